// Object views from X-ray images: marker blobs (detect/marker_blobs.h) labelled with the CT
// markers (pose/marker_correspondence.h) in every view of a set of image files, one rigid object.
//
// Every file read and its blobs detected first; then per view, in file order (a multi-frame
// DICOM file gives one view per frame):
//   1. Blobs. With `diameter_mm` and no px range, the magnification is px_per_mm if given, else
//      fx / SOD with the DICOM frame's Distance Source to Patient (0018,1111) (or SID /
//      Estimated Radiographic Magnification Factor), else fx / source_to_object_mm; none of these
//      is an error naming the view.
//   2. Labels. When this view and an already labelled view both have a nominal cam_from_patient
//      (DICOM positioner angles and distances, io/dicom_view.h), the object's pose is predicted
//      from it: cam_from_object_v = cam_from_patient_v * patient_from_cam_r * cam_from_object_r
//      (the nominal geometry's relative C-arm motion applied to the labelled view r; the
//      isocentre offset cancels). Else, or when the prediction is not accepted, the full
//      hypothesise-and-verify search runs. One set of CT markers for all views: the labels are
//      consistent across views by construction (one rigid object).
//   3. A view with fewer than min_markers blobs, whose blobs no labelling explains, or whose
//      labelling is ambiguous (the layout nearly symmetric as that view sees it: refusing to
//      guess) is skipped with the reason; the others go on. A view refused before the first
//      labelled view with a nominal pose had no prediction: it is labelled again at the pose that
//      view predicts, and kept when that labelling is accepted (in the randomised real-CT scenes
//      a view with 4 markers as blobs of their own and two 4-marker labellings about equally
//      good, tests/detect/marker_recall_test.cc).
//   4. A labelled marker that the pose predicts within merge_distance blob diameters of another
//      marker is left out (a merged blob the blob finder did not flag), listed as rejected.
// Errors (the whole set, one line naming the view or file): an unreadable / corrupt image or a
// missing file; images of a size other than the camera's; no view labelled (with each view's
// reason: an ambiguous layout, the fiducials of another object, a wrong camera, or too few
// markers).
//
// Pixel covariance for the bundle adjustment: each blob's 2x2 covariance C plus the floor,
// C + sigma_floor_px^2 I, which the engine whitens in full (ba/reprojection_error.h); the isotropic
// sigma = sqrt(lambda_max(C) + sigma_floor_px^2) (a conservative bound) is kept beside it for the
// robust loss's scale and the reports.
#pragma once

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "camera/camera.h"
#include "camera/carm_geometry.h"
#include "detect/marker_blobs.h"
#include "io/object_views.h"
#include "pose/marker_correspondence.h"
#include "util/status.h"

namespace carmba {

struct ObjectViewsOptions {
  MarkerBlobOptions blobs;
  double source_to_object_mm = 0;  // for diameter_mm when px_per_mm and DICOM SOD are absent
  CorrespondenceOptions correspondence;
  double sigma_floor_px = 0;       // added in quadrature to each blob's sigma (model error)
  bool use_nominal_geometry = true;

  bool Check(std::string* error) const;
};
class YamlMap;
// Reads the blob keys, source_to_object_mm, sigma_floor_px, use_nominal_geometry and a
// `correspondence:` map (gate_px, predict_gate_px, accept_rms_px, min_markers, min_fraction,
// ambiguity_margin_px, max_blobs).
void ReadObjectViewsOptions(YamlMap& map, ObjectViewsOptions* options);

struct ObjectView {
  std::string name;   // file, or file#frameN (in error messages, and result.json's "image")
  std::string id;     // short id (io/image_files.h ShortViewIds): in tables, CSVs, result.json
  cv::Mat image;      // as read (for overlays)
  MarkerBlobDetection detection;
  bool labelled = false;
  std::string skipped;  // why not labelled
  MarkerLabelling labelling;
  std::vector<int> marker_id_of_blob;  // CT marker id per blob, -1 = none
  std::optional<Rigid3> nominal_cam_from_patient;
  double px_per_mm = 0;  // the magnification used
};

// The observations of a labelled view in the one form every reader hands on (io/object_views.h),
// sorted by marker id: per labelled blob its marker id, pixel, covariance plus floor^2 I and the
// isotropic sigma of that (IsotropicSigmaPx).
std::vector<Observation> LabelledObservations(const ObjectView& view, double sigma_floor_px = 0);
// sqrt(lambda_max(C) + floor^2).
double IsotropicSigmaPx(const Eigen::Matrix2d& covariance_px2, double sigma_floor_px);

StatusOr<std::vector<ObjectView>> DetectAndLabelObjectViews(const std::vector<std::string>& files,
                                                            const Camera& camera,
                                                            const std::vector<Marker>& markers,
                                                            const ObjectViewsOptions& options);

// The labelled views as pose-problem views (observations with their per-blob sigma).
std::vector<PoseView> ToPoseViews(const std::vector<ObjectView>& views, double sigma_floor_px);

}  // namespace carmba
