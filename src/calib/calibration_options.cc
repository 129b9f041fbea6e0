#include "calib/calibration_options.h"

#include <cmath>

#include "camera/camera.h"
#include "util/plausible.h"
#include "util/yaml_reader.h"

namespace carmba {

SolverConfig CalibrationOptions::DefaultCalibrationSolve() {
  SolverConfig c;
  c.name = "calibration";
  c.backend = ba::Backend::kCarmbaLm;
  return c;
}

bool CalibrationOptions::Check(std::string* error) const {
  if (!solve.Check(error)) return false;
  if (solve.reject_sigma != 0) {
    *error =
        "outliers.reject_sigma: expected 0 (a calibration lists its outliers, "
        "outliers.list_sigma, and does not drop them)";
    return false;
  }
  if (!(aspect_ratio_fy_over_fx >= 0) || !std::isfinite(aspect_ratio_fy_over_fx)) {
    *error = "aspect_ratio_fy_over_fx: expected >= 0 (0 = from the initial estimate)";
    return false;
  }
  if (!principal_point_px.empty() && principal_point_px.size() != 2) {
    *error = "principal_point_px: expected [cx, cy] or []";
    return false;
  }
  namespace pl = plausible;
  for (size_t i = 0; i < principal_point_px.size(); ++i) {
    if (!CheckRange("principal_point_px: element " + std::to_string(i), principal_point_px[i],
                    pl::kPixelCoordinatePx, error)) {
      return false;
    }
  }
  // (distortion terms in `fix` beside distortion: auto: SolverConfig::Check)
  if (solve.distortion_auto) {
    const char* conflict = zero_tangential ? "zero_tangential" : fix_k3 ? "fix_k3" : nullptr;
    if (conflict) {
      *error = std::string("distortion: auto chooses the distortion terms itself; remove ") +
               conflict + " (or set distortion: given)";
      return false;
    }
  }
  if (!initial_intrinsics.empty() && initial_intrinsics.size() != kNumIntrinsics) {
    *error = "initial_intrinsics: expected 9 values [fx, fy, cx, cy, k1, k2, p1, p2, k3]";
    return false;
  }
  for (size_t i = 0; i < initial_intrinsics.size(); ++i) {
    const PlausibleRange& r = i < 2   ? pl::kFocalPx
                              : i < 4 ? pl::kPixelCoordinatePx
                                      : pl::kDistortion;
    if (!CheckRange(std::string("initial_intrinsics: ") + kIntrinsicNames[i],
                    initial_intrinsics[i], r, error)) {
      return false;
    }
  }
  if (pixel_sigma_px != 0 && !InRange(pixel_sigma_px, pl::kPixelSigmaPx)) {
    *error = "pixel_sigma_px: expected 0 (estimate) or " + FormatRange(pl::kPixelSigmaPx) +
             ", got " + FormatCompact(pixel_sigma_px);
    return false;
  }
  if (min_views < 1) {
    *error = "min_views: expected >= 1";
    return false;
  }
  if (solve.max_iterations < 1) {
    *error = "max_iterations: expected >= 1";
    return false;
  }
  if (uncertainty_distance_mm != 0 && !InRange(uncertainty_distance_mm, pl::kDistanceMm)) {
    *error = "uncertainty_distance_mm: expected 0 (the median plate distance) or " +
             FormatRange(pl::kDistanceMm) + ", got " + FormatCompact(uncertainty_distance_mm);
    return false;
  }
  return true;
}

namespace {

// The loss, the outlier listing and the back end in the solver config's vocabulary
// (problem/solver_config.h LoadSolverConfig: loss: {type, scale_px}, outliers: {list_sigma},
// backend), or in the calibration config's older spelling (robust_loss, robust_loss_scale_px,
// outlier_threshold_sigma, solver), which keeps working; both spellings of one thing are an
// error naming the two.
Status ReadCalibrationSolveKeys(const std::string& path, YamlMap* map, CalibrationOptions* o) {
  YamlMap& m = *map;
  const std::pair<const char*, std::vector<const char*>> spellings[] = {
      {"loss", {"robust_loss", "robust_loss_scale_px"}},
      {"outliers", {"outlier_threshold_sigma"}},
      {"backend", {"solver"}}};
  for (const auto& [key, old_keys] : spellings) {
    for (const char* old_key : old_keys) {
      if (m.Has(key) && m.Has(old_key)) {
        return Status::Error(path + ": give '" + key + "' or its older spelling '" + old_key +
                             "', not both");
      }
    }
  }
  SolverConfig& c = o->solve;
  // The older spelling, translated (at most one of the two spellings is there).
  // Every key is asked for whether or not it is there: the readers' key lists are checked
  // against formats.md (DocsFormats).
  constexpr EnumName<ba::Loss> kOlderLossNames[] = {
      {ba::Loss::kTrivial, "none"}, {ba::Loss::kHuber, "huber"}, {ba::Loss::kCauchy, "cauchy"}};
  constexpr EnumName<ba::Backend> kOlderSolverNames[] = {{ba::Backend::kCarmbaLm, "lm"},
                                                         {ba::Backend::kCeres, "ceres"}};
  m.GetEnum("robust_loss", kOlderLossNames, &c.loss);
  m.GetInRange("robust_loss_scale_px", &c.loss_scale_px, plausible::kLossScalePx);
  m.GetInRange("outlier_threshold_sigma", &c.outlier_sigma, plausible::kSigmaMultiple);
  m.GetEnum("solver", kOlderSolverNames, &c.backend);
  // The solver config's spelling, read by the solver config's reader.
  ReadSolveKeys(m, &c);
  return Status::Ok();
}

// What a calibration config held before it said only how to solve, and where it went.
struct MovedKey {
  const char* key;
  const char* now;
};
constexpr MovedKey kMovedCalibrationKeys[] = {
    {"detection",
     "the plate's detection options belong to the data: the problem's plate_views.detection, or "
     "calibrate --detection FILE with these keys at its top level"},
    {"crosscheck",
     "the cross-checks are calibrate's flags: --no-mrcal, --no-opencv, --opencv-max-views N, "
     "--mrcal-python PATH"}};

}  // namespace

SolverConfig CalibrationOptions::ToSolverConfig() const {
  SolverConfig c = solve;
  c.backend = solve.backend == ba::Backend::kCarmbaLm && solve.loss == ba::Loss::kTrivial
                  ? ba::Backend::kCarmbaLm
                  : ba::Backend::kCeres;
  c.linear_solver = "dense_schur";
  // The pixel sigma given (pixel_sigma_px), or estimated: the engine's a-posteriori factor.
  c.covariance_scale =
      pixel_sigma_px > 0 ? ba::CovarianceScale::kApriori : ba::CovarianceScale::kGlobal;
  return c;
}

Status LoadCalibrationOptions(const std::string& path, CalibrationOptions* o) {
  YamlMap m = YamlMap::Load(path);
  CARMBA_RETURN_IF_ERROR(m.status());
  for (const char* k : {"initializer", "linear_solver", "covariance", "jacobians", "refine"}) {
    if (m.Has(k)) {
      return Status::Error(path + ": this is a solver config (key '" + k +
                           "'), for `carmba solve`; `carmba calibrate` needs a calibration config "
                           "(fix, loss, pixel_sigma_px; configs/calib_*.yaml)");
    }
  }
  for (const MovedKey& k : kMovedCalibrationKeys) {
    if (m.Has(k.key)) return Status::Error(path + ": key '" + k.key + "': " + k.now);
  }
  m.Get("fix_aspect_ratio", &o->fix_aspect_ratio);
  m.Get("aspect_ratio_fy_over_fx", &o->aspect_ratio_fy_over_fx);
  m.Get("zero_tangential", &o->zero_tangential);
  m.Get("fix_principal_point", &o->fix_principal_point);
  m.Get("principal_point_px", &o->principal_point_px);
  m.Get("fix_k3", &o->fix_k3);
  m.Get("initial_intrinsics", &o->initial_intrinsics);
  CARMBA_RETURN_IF_ERROR(ReadCalibrationSolveKeys(path, &m, o));
  m.GetNonNegative("pixel_sigma_px", &o->pixel_sigma_px);
  m.Get("min_views", &o->min_views);
  m.GetNonNegative("uncertainty_distance_mm", &o->uncertainty_distance_mm);
  CARMBA_RETURN_IF_ERROR(m.Finish());
  std::string err;
  if (!o->Check(&err)) return Status::Error(path + ": " + err);
  return Status::Ok();
}

}  // namespace carmba
