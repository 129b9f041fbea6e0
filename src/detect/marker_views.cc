#include "detect/marker_views.h"

#include <Eigen/Eigenvalues>
#include <cctype>
#include <cmath>
#include <map>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "camera/camera_model.h"
#include "detect/detect_steps.h"
#include "geometry/rotation.h"
#include "io/dicom_view.h"
#include "io/image_files.h"
#include "util/format.h"
#include "util/plausible.h"
#include "util/yaml_reader.h"

namespace carmba {

bool ObjectViewsOptions::Check(std::string* error) const {
  if (source_to_object_mm != 0 && !InRange(source_to_object_mm, plausible::kSourceToObjectMm)) {
    *error = "source_to_object_mm: expected 0 (unknown) or " +
             FormatRange(plausible::kSourceToObjectMm) + ", got " +
             FormatCompact(source_to_object_mm) + " (a distance in metres?)";
    return false;
  }
  if (!(sigma_floor_px >= 0 && sigma_floor_px < 100)) {
    *error = "sigma_floor_px: expected 0 .. 100 px";
    return false;
  }
  if (blobs.diameter_px.empty() && !(blobs.diameter_mm > 0)) {
    *error = "marker diameter: expected diameter_px [min, max] or diameter_mm";
    return false;
  }
  if (blobs.diameter_px.empty() && !InRange(blobs.diameter_mm, plausible::kMarkerDiameterMm)) {
    *error = "diameter_mm: expected " + FormatRange(plausible::kMarkerDiameterMm) + ", got " +
             FormatCompact(blobs.diameter_mm) + " (a diameter in metres?)";
    return false;
  }
  return correspondence.Check(error);
}

void ReadObjectViewsOptions(YamlMap& m, ObjectViewsOptions* o) {
  ReadMarkerBlobOptions(m, &o->blobs);
  m.GetNonNegative("source_to_object_mm", &o->source_to_object_mm);
  m.GetNonNegative("sigma_floor_px", &o->sigma_floor_px);
  m.Get("use_nominal_geometry", &o->use_nominal_geometry);
  if (m.Has("correspondence")) {
    YamlMap& c = m.Map("correspondence");
    c.GetPositive("gate_px", &o->correspondence.gate_px);
    c.GetPositive("predict_gate_px", &o->correspondence.predict_gate_px);
    c.GetPositive("accept_rms_px", &o->correspondence.accept_rms_px);
    c.Get("min_markers", &o->correspondence.min_markers);
    c.GetNonNegative("min_fraction", &o->correspondence.min_fraction);
    c.GetNonNegative("px_per_mm", &o->correspondence.px_per_mm);
    c.GetNonNegative("scale_tolerance", &o->correspondence.scale_tolerance);
    c.GetNonNegative("ambiguity_margin_px", &o->correspondence.ambiguity_margin_px);
    c.Get("max_blobs", &o->correspondence.max_blobs);
  }
}

double IsotropicSigmaPx(const Eigen::Matrix2d& C, double floor_px) {
  const double lmax =
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(C, Eigen::EigenvaluesOnly).eigenvalues()(1);
  return std::sqrt(std::max(0.0, lmax) + floor_px * floor_px);
}

std::vector<Observation> LabelledObservations(const ObjectView& view, double floor_px) {
  std::vector<Observation> out;
  if (!view.labelled) return out;
  for (size_t i = 0; i < view.detection.blobs.size(); ++i) {
    if (view.marker_id_of_blob[i] < 0) continue;
    const MarkerBlob& b = view.detection.blobs[i];
    Observation o;
    o.marker_id = view.marker_id_of_blob[i];
    o.uv_px = Eigen::Vector2d(b.uv_px.x, b.uv_px.y);
    o.covariance_px2 << b.covariance_px2(0, 0), b.covariance_px2(0, 1), b.covariance_px2(1, 0),
        b.covariance_px2(1, 1);
    o.sigma_px = IsotropicSigmaPx(o.covariance_px2, floor_px);
    o.covariance_px2 += floor_px * floor_px * Eigen::Matrix2d::Identity();
    out.push_back(o);
  }
  std::sort(out.begin(), out.end(), [](const Observation& a, const Observation& b) {
    return a.marker_id < b.marker_id;
  });
  return out;
}

std::vector<PoseView> ToPoseViews(const std::vector<ObjectView>& views, double floor_px) {
  std::vector<PoseView> out;
  for (const ObjectView& v : views) {
    if (!v.labelled) continue;
    out.push_back({v.id, LabelledObservations(v, floor_px)});
  }
  return out;
}

namespace {

// Two markers whose shadows overlap can form one blob that the blob finder does not flag (two
// discs half a diameter apart look like one slightly large, slightly elongated disc), and the
// correspondence then gives it one of them: its centre is off by a quarter of the offset. The
// labelled pose predicts where every marker projects: a labelled marker with another marker's
// predicted centre within `merge_distance` blob diameters of its own is left out (listed as a
// rejected blob with the reason), whether or not the blob looked merged.
void LeaveOutPredictedOverlaps(const Camera& camera, const std::vector<Eigen::Vector3d>& P,
                               double merge_distance, ObjectView* v) {
  std::vector<double> diameters;
  for (size_t i = 0; i < v->marker_id_of_blob.size(); ++i) {
    if (v->labelling.marker_of_blob[i] >= 0) diameters.push_back(v->detection.blobs[i].diameter_px);
  }
  if (diameters.empty()) return;
  std::nth_element(diameters.begin(), diameters.begin() + diameters.size() / 2, diameters.end());
  const double limit = merge_distance * diameters[diameters.size() / 2];
  std::vector<Eigen::Vector2d> proj(P.size());
  std::vector<bool> ok(P.size());
  for (size_t m = 0; m < P.size(); ++m) {
    ok[m] = ProjectPoint(
        camera.params.data(), v->labelling.cam_from_object.data(), P[m].data(), proj[m].data());
  }
  for (size_t i = 0; i < v->marker_id_of_blob.size(); ++i) {
    const int m = v->labelling.marker_of_blob[i];
    if (m < 0 || !ok[m]) continue;
    int other = -1;
    for (size_t k = 0; k < P.size() && other < 0; ++k) {
      if (static_cast<int>(k) != m && ok[k] && (proj[k] - proj[m]).norm() < limit)
        other = static_cast<int>(k);
    }
    if (other < 0) continue;
    const MarkerBlob& b = v->detection.blobs[i];
    v->detection.rejected.push_back({b.uv_px,
                                     b.diameter_px,
                                     "overlaps another marker (predicted " +
                                         Fixed((proj[other] - proj[m]).norm(), 1) + " px apart)"});
    v->labelling.marker_of_blob[i] = -1;
    v->marker_id_of_blob[i] = -1;
    --v->labelling.num_labelled;
  }
}

// What hides a marker in this view (pose/marker_correspondence.h ViewContext): outside the
// detector's circular field, or on a candidate it rejected as metal (two shadows merged, a bead or
// a wire across: "merged", "elongated", "too large", "field-of-view border", "refinement
// failed"). A blob-sized shadow too faint to measure ("low contrast") is a faint blob: anatomy
// and noise make them everywhere, but a marker behind dense anatomy is one of them (0.1-0.3 px
// from its true centre in the randomised real-CT scenes). Not "too small" (noise).
ViewContext CorrespondenceContext(const MarkerBlobDetection& d) {
  ViewContext c;
  c.fov_centre = Eigen::Vector2d(d.fov_centre.x, d.fov_centre.y);
  c.fov_radius = d.fov_radius;
  for (const RejectedBlob& r : d.rejected) {
    if (r.why == "too small") continue;
    auto& list = r.why == "low contrast" ? c.faint_blobs : c.obstructions;
    list.emplace_back(r.uv_px.x, r.uv_px.y);
  }
  for (const MarkerBlob& b : d.blobs) {
    const cv::Matx22d& C = b.covariance_px2;
    const Eigen::Matrix2d cov =
        (Eigen::Matrix2d() << C(0, 0), C(0, 1), C(1, 0), C(1, 1)).finished();
    c.blob_sigma_px.push_back(IsotropicSigmaPx(cov, 0));
  }
  return c;
}

}  // namespace

namespace {

// The pose of the object in view `v` that the labelled view `ref` and the two views' nominal
// geometry predict (both have nominal_cam_from_patient).
Pose6 PredictedPose(const ObjectView& ref, const ObjectView& v) {
  const Rigid3 patient_from_object =
      ref.nominal_cam_from_patient->Inverse() * Rigid3::FromPose(ref.labelling.cam_from_object);
  return (*v.nominal_cam_from_patient * patient_from_object).ToPose();
}

// The correspondence options for a detected view: separation_px from its median blob, px_per_mm
// from the blob options (or fx / SOD when the diameter was given in px).
CorrespondenceOptions ViewCorrespondenceOptions(const ObjectView& v,
                                                const MarkerBlobOptions& bo,
                                                const Camera& camera,
                                                std::optional<double> sod,
                                                CorrespondenceOptions co) {
  if (co.separation_px == 0 && !v.detection.blobs.empty()) {
    // Markers closer than the detector's merge distance make one rejected blob: the median
    // blob's diameter times merge_distance (detect/marker_blobs.h).
    std::vector<double> d;
    for (const MarkerBlob& b : v.detection.blobs) d.push_back(b.diameter_px);
    std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
    co.separation_px = bo.merge_distance * d[d.size() / 2];
  }
  if (co.px_per_mm == 0) {
    // The nominal magnification: the blob options', else fx / SOD when the file has it.
    co.px_per_mm = bo.diameter_px.empty() ? bo.px_per_mm : sod ? camera.params[kFx] / *sod : 0.0;
  }
  return co;
}

// Labels the detected blobs of `v` with the markers (at `predicted` first when given). An
// ambiguous view (a layout nearly symmetric as this view sees it) is not guessed: it is left
// unlabelled with the reason, like any view that cannot be labelled.
void LabelView(const Camera& camera,
               const std::vector<Marker>& markers,
               const std::vector<Eigen::Vector3d>& P,
               const CorrespondenceOptions& co,
               double merge_distance,
               const std::optional<Pose6>& predicted,
               ObjectView* view) {
  ObjectView& v = *view;
  std::vector<Eigen::Vector2d> uv;
  for (const MarkerBlob& b : v.detection.blobs) uv.emplace_back(b.uv_px.x, b.uv_px.y);
  auto lab = LabelMarkerBlobs(camera, P, uv, co, predicted, CorrespondenceContext(v.detection));
  if (!lab.ok()) {
    v.skipped = lab.status().message();
    return;
  }
  v.labelled = true;
  v.labelling = *lab;
  v.marker_id_of_blob.assign(uv.size(), -1);
  for (size_t i = 0; i < uv.size(); ++i) {
    if (lab->marker_of_blob[i] >= 0) v.marker_id_of_blob[i] = markers[lab->marker_of_blob[i]].id;
  }
  for (const OffPoseBlob& off : lab->off_pose) {
    const MarkerBlob& b = v.detection.blobs[off.blob];
    v.detection.rejected.push_back({b.uv_px,
                                    b.diameter_px,
                                    "off the pose: " + Fixed(off.distance_px, 2) +
                                        " px from where the other markers put marker " +
                                        std::to_string(markers[off.marker].id) +
                                        " (two shadows in line, or an edge across it)"});
  }
  LeaveOutPredictedOverlaps(camera, P, merge_distance, &v);
  if (v.labelling.num_labelled < co.min_markers) {
    v.labelled = false;
    v.skipped = "only " + std::to_string(v.labelling.num_labelled) +
                " markers left once the overlapping ones are left out (" +
                std::to_string(co.min_markers) + " needed)";
  }
}

// A view as read and detected, before its labelling.
struct DetectedView {
  ObjectView view;
  CorrespondenceOptions correspondence;
};

// Reads the views of one file and detects their blobs (a view whose detection fails is kept with
// the reason).
Status DetectViews(const std::string& file,
                   const Camera& camera,
                   const ObjectViewsOptions& o,
                   std::vector<DetectedView>* out) {
  auto named = ReadImageViews(file);
  if (!named.ok()) return named.status();
  for (const NamedImage& ni : *named) {
    DetectedView dv;
    ObjectView& v = dv.view;
    v.name = ni.name;
    v.image = ni.image;
    if (v.image.cols != camera.width || v.image.rows != camera.height) {
      return Status::Error(v.name + ": image size " + std::to_string(v.image.cols) + "x" +
                           std::to_string(v.image.rows) + " differs from the camera's " +
                           std::to_string(camera.width) + "x" + std::to_string(camera.height));
    }
    std::optional<double> sod;
    if (ni.geometry) {
      auto nominal = NominalViewFromDicom(*ni.geometry, v.image.cols, v.image.rows, v.name);
      if (!nominal.ok()) return nominal.status();
      if (o.use_nominal_geometry) v.nominal_cam_from_patient = nominal->cam_from_patient;
      if (ni.geometry->sod_mm) {
        sod = *ni.geometry->sod_mm;
      } else if (ni.geometry->sid_mm && ni.geometry->magnification) {
        sod = *ni.geometry->sid_mm / *ni.geometry->magnification;
      }
    }
    MarkerBlobOptions bo = o.blobs;
    if (bo.diameter_px.empty() && !(bo.px_per_mm > 0)) {
      const double z = sod ? *sod : o.source_to_object_mm;
      if (!(z > 0)) {
        return Status::Error(v.name +
                             ": diameter_mm needs the magnification: give px_per_mm or "
                             "source_to_object_mm (no Distance Source to Patient (0018,1111) in "
                             "the image)");
      }
      bo.px_per_mm = camera.params[kFx] / z;
    }
    v.px_per_mm = bo.px_per_mm;
    v.detection = DetectMarkerBlobs(v.image, bo);
    if (!v.detection.ok) v.skipped = v.detection.reason;
    dv.correspondence = ViewCorrespondenceOptions(v, bo, camera, sod, o.correspondence);
    out->push_back(std::move(dv));
  }
  return Status::Ok();
}

}  // namespace

StatusOr<std::vector<ObjectView>> DetectAndLabelObjectViews(const std::vector<std::string>& files,
                                                            const Camera& camera,
                                                            const std::vector<Marker>& markers,
                                                            const ObjectViewsOptions& o) {
  std::string err;
  if (!o.Check(&err)) return Status::Error("object views: " + err);
  std::vector<Eigen::Vector3d> P;
  for (const Marker& m : markers) P.push_back(m.p_in_object);
  std::vector<DetectedView> detected;
  for (const std::string& file : files) {
    const Status st = DetectViews(file, camera, o, &detected);
    if (!st.ok()) return st;
  }
  // In order: each view after the first labelled one with a nominal pose (`ref`) is labelled at
  // the pose that view and the nominal geometry predict first.
  std::vector<ObjectView> views;
  int ref = -1;
  for (const DetectedView& dv : detected) {
    ObjectView v = dv.view;
    if (v.detection.ok) {
      std::optional<Pose6> predicted;
      if (ref >= 0 && v.nominal_cam_from_patient) predicted = PredictedPose(views[ref], v);
      LabelView(camera, markers, P, dv.correspondence, o.blobs.merge_distance, predicted, &v);
    }
    views.push_back(std::move(v));
    if (ref < 0 && views.back().labelled && views.back().nominal_cam_from_patient)
      ref = static_cast<int>(views.size()) - 1;
  }
  // The views before `ref` had no prediction: one refused on its own (ambiguous, or too few
  // markers for a labelling found by search) is labelled again at the predicted pose.
  for (int i = 0; i < ref; ++i) {
    if (views[i].labelled || !detected[i].view.detection.ok ||
        !detected[i].view.nominal_cam_from_patient)
      continue;
    ObjectView retry = detected[i].view;
    LabelView(camera,
              markers,
              P,
              detected[i].correspondence,
              o.blobs.merge_distance,
              PredictedPose(views[ref], retry),
              &retry);
    if (retry.labelled) views[i] = std::move(retry);
  }
  int labelled = 0;
  std::ostringstream why;
  for (const ObjectView& v : views) {
    labelled += v.labelled;
    if (!v.labelled) why << (why.tellp() > 0 ? "; " : "") << v.name << ": " << v.skipped;
  }
  if (views.empty()) return Status::Error("no object views in the images");
  if (labelled == 0) return Status::Error("no view could be labelled (" + why.str() + ")");
  std::vector<std::string> names;
  for (const ObjectView& v : views) names.push_back(v.name);
  const std::vector<std::string> ids = ShortViewIds(names);
  for (size_t i = 0; i < views.size(); ++i) views[i].id = ids[i];
  return views;
}

}  // namespace carmba
