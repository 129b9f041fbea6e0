// Detection of calibration grids in X-ray images (and photographs).
//
// Pipeline per image (DetectGrid calls one function per step, in grid_detector.cc):
//   1. To a float grey image (8- or 16-bit, grey or colour), then an 8-bit working copy stretched
//      between the 1st and 99th percentile of the pixels inside the field of view.
//   2. Region of interest: an optional crop [x, y, w, h] and a circular mask. The image
//      intensifier's circular field of view is found automatically or given as [cx, cy, r]; blobs
//      touching its border are dropped. Found: the largest region above 15 % of the image's
//      range, its convex hull and the hull's enclosing circle shrunk by a margin; when dark
//      anatomy at the rim cuts that region (its hull covers < 97 % of its circle) and an
//      unexposed border exists, the region above 5 % of the range if it is > 3 % larger.
//   3. circles / acircles: cv::findCirclesGrid with a SimpleBlobDetector tuned for small dark
//      (metal on bright, X-ray) or bright blobs; polarity "auto" tries dark first, then bright.
//      When the dark search fails, it is repeated on a flat-fielded image (the image divided by
//      its morphological closing over ~2.4 blob diameters): the intensifier's fall-off, the heel
//      effect, glare and anatomy otherwise put spheres on bright parts of the field above every
//      threshold and merge spheres on dark parts with their surroundings. A grid OpenCV returns
//      is taken only when its points are distinct and lie on a lattice (else the next finder).
//      chessboard: cv::findChessboardCorners + cornerSubPix.
//   4. Sub-pixel centres of circles, on the float image, iterated from the blob centre: the blob's
//      size from its half-contrast area in a window of half the distance to the nearest grid
//      point (background level: the window's border band, between the blob and its neighbours);
//      a background plane fitted (robustly) to a 3 px ring just outside the blob, fitted into the
//      gap to the neighbours for large circles (any diameter up to nearly touching circles:
//      tests/detect/grid_detector_test.cc LargeCirclesSubPixel); the centroid of the FLAT-FIELD
//      contrast 1 - I / background over the disc inside the ring (dark polarity: X-ray
//      attenuation, independent of vignetting and other brightness gradients; bright:
//      I - background). Only the fully exposed field of view is used: the intensifier's rim
//      fall-off (found from the median radial profile) is excluded, and a blob whose ring reaches
//      it is dropped; so is a centre the refinement moved by more than half the blob's radius
//      (at least 1.5 px: a strong anatomical edge in the ring). Next to sharp background
//      structure (a bone edge across the sphere) the centre moves to the centroid of the blob's
//      core (contrast above 25 % of its peak), which that structure hardly pulls, when the two
//      differ by 0.03-0.06 px and more; a point whose core and whole-blob centroids are more than
//      0.15 px apart is dropped as unreliable (listed with kUnreliableCentre). Against the
//      simulator's truth: ~0.004 px RMS systematic error (tests/detect/simulated_scene_test.cc),
//      ~0.012 px over a real anatomical background (tests/detect/recall_test.cc), < 0.02 px and
//      no point beyond ~0.1 px next to sharp anatomy (tests/detect/edge_accuracy_test.cc, where
//      the plain centroid was 0.027 px RMS with points up to 1.8 px off). The points kept must
//      lie on a grid (a homography from the plate within 30 % of the pitch).
//   5. Ids: row-major in the grid (detect/observations.h). For symmetric grids and chessboards,
//      whose ordering is only defined up to the grid's symmetry, the ordering is made right-handed
//      in the image (row direction x column direction > 0): an X-ray sees the plate from either
//      side, and a consistent handedness is what lets all views share one rigid plate.
//   6. A plate larger than the requested pattern (the blob lattice continues beyond the found
//      rows / columns: at least 2 blobs and half a line on the next lattice nodes) is rejected as
//      ambiguous: OpenCV would pick a different sub-window in different views.
// A not-found result carries why: too few blobs (with the count), no grid ordering among the
// blobs (ambiguous, or grid partly outside the field of view), points on the mask border, more
// grid points than the pattern (with the plate's size seen).
#pragma once

#include <opencv2/core.hpp>

#include <optional>
#include <string>
#include <vector>

#include "detect/observations.h"
#include "io/dicom_xray.h"
#include "util/progress.h"
#include "util/status.h"

namespace carmba {

struct DetectionOptions {
  // "dark" (metal on bright background, X-ray), "bright", or "auto" (dark, then bright).
  std::string polarity = "auto";
  // Crop [x, y, w, h] in px; empty = whole image.
  std::vector<int> roi_px;
  // Circular mask [cx, cy, r] in px (full-image coordinates); empty = auto_fov_mask decides.
  std::vector<double> fov_circle_px;
  // Find the image intensifier's circular field of view and mask outside it.
  bool auto_fov_mask = true;
  // Shrink the field-of-view circle by this many px (its rim is blurred).
  double fov_margin_px = 2;
  // Blob area limits (px^2) for circle grids.
  double min_blob_area_px = 6;
  double max_blob_area_px = 20000;
  // Sub-pixel refinement of circle centres.
  bool refine = true;

  bool Check(std::string* error) const;
};

// Reads detection options from a YAML map (keys = field names): a problem's
// `plate_views.detection`, or a detection file.
class YamlMap;
void ReadDetectionOptions(YamlMap& map, DetectionOptions* options);
// A detection file (`carmba calibrate --detection`, `carmba detect --detection`): the keys of
// ReadDetectionOptions at its top level. Errors name the file and the key.
Status LoadDetectionOptions(const std::string& path, DetectionOptions* options);
// Only the region-of-interest / field-of-view keys (roi_px, fov_circle_px, auto_fov_mask,
// fov_margin_px), e.g. for the marker blob detector.
void ReadFieldOfViewOptions(YamlMap& map, DetectionOptions* options);

// A candidate blob or grid point that is not among the detected points, and why (full-image
// pixel coordinates): "not on the grid" (a blob of the search that found the grid but is no grid
// point), "on the field-of-view border", kUnreliableCentre with the distance of the core's and the
// whole blob's centroids, "no blob / refinement failed" (OpenCV's grid point
// where the refinement found no blob or was pulled off it), or, when no grid was found, the
// reason for the blobs of the search with the most blobs.
// The reason given for a grid point dropped because its centre is unreliable: the centroid of
// the sphere's core and that of the whole blob differ by more than 0.15 px (background structure
// across the sphere, e.g. an anatomical edge; step 4).
inline constexpr const char* kUnreliableCentre = "centre unreliable: background edge";
struct RejectedBlob {
  cv::Point2d uv_px;
  double diameter_px = 0;  // the blob finder's size (0 for a grid point without a blob)
  std::string why;
};

struct GridDetection {
  bool found = false;
  std::string reason;   // why not found (empty when found)
  int num_blobs = -1;   // candidate blobs seen (circle grids)
  std::string polarity; // the polarity that worked
  ViewObservations view;
  std::vector<RejectedBlob> rejected;  // circle grids: what was not used, and why
  // Circle grids, per point of `view`: how far the centroid of the blob's core (contrast above
  // 25 % of its peak) lies from the centroid of the whole blob (RefineCentroid's shift_px): ~0.01
  // px on a smooth background, larger where background structure the ring's plane does not
  // follow (an anatomical edge) pulls the whole blob's centroid. 0 without refinement.
  std::vector<double> background_shift_px;
};


// Detects `grid` in an image of any depth (CV_8U/CV_16U/CV_32F, 1 or 3 channels).
GridDetection DetectGrid(const cv::Mat& image,
                         const GridSpec& grid,
                         const DetectionOptions& options);

// Detects the grid in every view of every file (ReadImageViews: a multi-frame DICOM file gives
// one view per frame, named `file#frameN`). Views where it is found go into the set; the others
// are listed as "view: reason" in `skipped`. Errors: unreadable image, images of different sizes.
// `detections` (optional): every view's detection in order, view.image set to the view's name.
// `progress` (optional) is called once per file, after its views are done.
StatusOr<ObservationSet> DetectGridInFiles(const std::vector<std::string>& files,
                                           const GridSpec& grid,
                                           const DetectionOptions& options,
                                           std::vector<std::string>* skipped,
                                           double* seconds_per_image = nullptr,
                                           std::vector<GridDetection>* detections = nullptr,
                                           const ProgressFn& progress = nullptr);

}  // namespace carmba
