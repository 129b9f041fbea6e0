#include "calib/calibrate.h"

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <set>

#include "ba/bundle_adjuster.h"
#include "ba/quantities.h"
#include "ba/schur_lm.h"
#include "calib/projection_uncertainty.h"
#include "calib/zhang_init.h"
#include "util/plausible.h"

namespace carmba {

namespace {

double Seconds(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

// The calibration as a problem of the bundle-adjustment engine, its plate part alone
// (ToBaPlateProblem, detect/observations.h): one intrinsics group, one plate pose per view, the
// plate's points held at the nominal grid. Views are named by their images (by number when those
// are not unique).
ba::BaProblem CalibrationProblem(const ObservationSet& obs,
                                 const std::array<double, kNumIntrinsics>& x,
                                 const std::array<bool, kNumIntrinsics>& free,
                                 double fy_over_fx,
                                 double sigma_px,
                                 const std::vector<Pose6>& poses) {
  ba::IntrinsicsGroup g;
  g.width = obs.width;
  g.height = obs.height;
  g.initial = x;
  g.free = free;
  g.fy_over_fx = fy_over_fx;
  std::set<std::string> names;
  for (const auto& v : obs.views) names.insert(v.image);
  const bool by_image = names.size() == obs.views.size() && !names.count("");
  std::vector<ba::BaView> views;
  for (size_t v = 0; v < obs.views.size(); ++v) {
    views.push_back(ToBaPlateView(
        obs.views[v], by_image ? obs.views[v].image : std::to_string(v), 0, poses[v], sigma_px));
  }
  ba::BaProblem p = ToBaPlateProblem("calibration", obs, {g}, std::move(views));
  p.markers_free = false;
  return p;
}

Status CheckCalibrationInput(const ObservationSet& obs, const CalibrationOptions& opt) {
  std::string err;
  if (!opt.Check(&err)) return Status::Error("calibration options: " + err);
  if (!obs.grid.Check(&err)) return Status::Error(err);
  if (obs.width <= 0 || obs.height <= 0) return Status::Error("image size unknown (expected > 0)");
  const int num_views = static_cast<int>(obs.views.size());
  if (num_views < opt.min_views) {
    return Status::Error("only " + std::to_string(num_views) + " usable view(s), min_views is " +
                         std::to_string(opt.min_views));
  }
  for (int v = 0; v < num_views; ++v) {
    const auto& view = obs.views[v];
    if (view.uv_px.size() < 4 || view.uv_px.size() != view.point_ids.size()) {
      return Status::Error("view " + std::to_string(v) + " (" + view.image +
                           "): expected at least 4 points, got " +
                           std::to_string(view.uv_px.size()));
    }
    for (size_t j = 0; j < view.uv_px.size(); ++j) {
      if (!view.uv_px[j].allFinite()) {
        return Status::Error("view " + std::to_string(v) + " (" + view.image + "): point " +
                             std::to_string(view.point_ids[j]) + " is not finite");
      }
    }
  }
  return Status::Ok();
}

// Per intrinsic: estimated (not held) under the options' constraints; fy follows fx when the
// aspect ratio is held.
std::vector<bool> FreeIntrinsics(const CalibrationOptions& opt) {
  std::vector<bool> free(kNumIntrinsics, true);
  for (const auto& n : opt.solve.fix) free[IntrinsicIndexOf(n)] = false;
  if (opt.fix_principal_point) free[kCx] = free[kCy] = false;
  if (opt.zero_tangential) free[kP1] = free[kP2] = false;
  if (opt.fix_k3) free[kK3] = false;
  if (opt.fix_aspect_ratio) free[kFy] = free[kFx];
  return free;
}

// The calibration solved through the engine in stages, each seeded by the one before: the
// pinhole core with the distortion held at its initial value (mrcal seeds the same way), the
// distortion terms chosen by the data (distortion: auto), then everything. Back end: carmba's
// Schur LM (solver: lm, no robust loss) or Ceres.
class StagedCalibration {
 public:
  StagedCalibration(const ObservationSet& obs,
                    const CalibrationOptions& opt,
                    const CalibrationStart& start,
                    double sigma_solve)
      : obs_(obs), opt_(opt), fy_over_fx_(start.fy_over_fx), sigma_solve_(sigma_solve),
        x_(start.intrinsics), poses_(start.cam_from_plate) {
    options_ = opt.ToSolverConfig().ToBaOptions();
  }

  bool own_lm() const { return options_.backend == ba::Backend::kCarmbaLm; }
  const std::array<double, kNumIntrinsics>& intrinsics() const { return x_; }
  const std::vector<Pose6>& poses() const { return poses_; }

  // The pinhole core alone, when any distortion term is free: only a seed, loose tolerances.
  Status SolveCore(const std::array<bool, kNumIntrinsics>& free) {
    std::array<bool, kNumIntrinsics> core = free;
    bool any_distortion = false;
    for (int i = kK1; i < kNumIntrinsics; ++i) any_distortion |= core[i], core[i] = false;
    return any_distortion ? Solve(core, true).status() : Status::Ok();
  }

  // distortion: auto -- the distortion terms chosen by the data (analysis/lens_models.h), seeded by
  // the pinhole stage; with an unknown pixel sigma the comparison estimates it from the full model.
  // Sets the distortion part of `free`; the terms left out are held at 0.
  StatusOr<analysis::DistortionSelection> SelectDistortion(std::array<bool, kNumIntrinsics>* free) {
    std::array<bool, kNumIntrinsics> all = *free;
    for (int i = kK1; i < kNumIntrinsics; ++i) all[i] = true;
    ba::BaProblem p = CalibrationProblem(obs_, x_, all, fy_over_fx_, sigma_solve_, poses_);
    ba::BaOptions so = options_;
    so.function_tolerance = 1e-10, so.gradient_tolerance = 1e-14, so.parameter_tolerance = 1e-10;
    so.compute_covariance = so.evaluate_solution = true;
    auto sel = analysis::SelectDistortionModel(
        p, so, analysis::kDistortionFolds, opt_.pixel_sigma_px == 0);
    if (!sel.ok()) return Status::Error("distortion: auto: " + sel.status().message());
    analysis::ApplyDistortionModel(sel->recommended, &p);
    for (int i = kK1; i < kNumIntrinsics; ++i) {
      (*free)[i] = p.groups[0].free[i];
      if (!(*free)[i]) x_[i] = 0;
    }
    return sel;
  }

  // One stage from the current state; a coarse one returns the solved state only. The engine's
  // typed failures get the calibration's advice.
  StatusOr<ba::BaResult> Solve(const std::array<bool, kNumIntrinsics>& free, bool coarse) {
    options_.function_tolerance = coarse ? 1e-6 : 1e-10;
    options_.gradient_tolerance = coarse ? 1e-10 : 1e-14;
    options_.parameter_tolerance = coarse ? 1e-6 : 1e-10;
    options_.compute_covariance = !coarse;
    options_.evaluate_solution = !coarse;
    const ba::BaProblem p = CalibrationProblem(obs_, x_, free, fy_over_fx_, sigma_solve_, poses_);
    auto res = ba::SolveBundleAdjustment(p, options_);
    if (!res.ok()) {
      const std::string& m = res.status().message();
      switch (res.status().kind()) {
        case ErrorKind::kNotDetermined:
          return Status::Error("the views do not determine the intrinsics (" + m +
                               "); degenerate views, e.g. all fronto-parallel or too few tilts");
        case ErrorKind::kNonFiniteInitialState:
          return Status::Error(
              "initialisation puts grid points behind the source (bad detections?)");
        case ErrorKind::kOther:
          break;
      }
      return res.status();
    }
    x_ = res->GroupIntrinsics(0);
    for (size_t v = 0; v < poses_.size(); ++v) poses_[v] = res->ViewPose(static_cast<int>(v));
    return res;
  }

 private:
  const ObservationSet& obs_;
  const CalibrationOptions& opt_;
  const double fy_over_fx_;
  const double sigma_solve_;
  ba::BaOptions options_;
  std::array<double, kNumIntrinsics> x_;
  std::vector<Pose6> poses_;
};

// Every point's residual at the solution, as the engine evaluated it (BaResult::residuals), into
// the view and point statistics; returns them all.
std::vector<PointResidual> Residuals(const ObservationSet& obs, CalibrationResult* r) {
  std::vector<PointResidual> all;
  r->points.resize(obs.grid.NumPoints());
  std::vector<double> point_ssr(obs.grid.NumPoints(), 0.0);
  const auto& residuals = r->engine->residuals;
  for (size_t v = 0; v < obs.views.size(); ++v) {
    const auto& view = obs.views[v];
    const Pose6& pose = r->cam_from_plate[v];
    ViewStats vs;
    vs.image = view.image;
    vs.num_points = static_cast<int>(view.uv_px.size());
    double vssr = 0;
    for (size_t j = 0; j < view.uv_px.size(); ++j) {
      const ba::BaObservationResidual& res = residuals[v][j];
      PointResidual pr;
      pr.view = static_cast<int>(v);
      pr.point_id = view.point_ids[j];
      pr.du_px = res.du_px;
      pr.dv_px = res.dv_px;
      const double e2 = pr.du_px * pr.du_px + pr.dv_px * pr.dv_px;
      pr.norm_px = std::sqrt(e2);
      vssr += e2;
      vs.max_px = std::max(vs.max_px, pr.norm_px);
      point_ssr[pr.point_id] += e2;
      r->points[pr.point_id].num_views++;
      all.push_back(pr);
    }
    vs.rms_px = std::sqrt(vssr / (2.0 * vs.num_points));
    vs.tilt_deg = std::acos(std::min(1.0, std::abs(RotationOf(pose.data())(2, 2)))) * 180.0 / M_PI;
    vs.distance_mm = Eigen::Vector3d(pose[3], pose[4], pose[5]).norm();
    r->views.push_back(vs);
  }
  for (int id = 0; id < obs.grid.NumPoints(); ++id) {
    r->points[id].point_id = id;
    if (r->points[id].num_views > 0) {
      r->points[id].rms_px = std::sqrt(point_ssr[id] / (2.0 * r->points[id].num_views));
    }
  }
  return all;
}

// The residual statistics: RMS, degrees of freedom and the pixel sigma (given, or the engine's
// a-posteriori one, by the robust loss's weights when there is one) from the engine; the
// outliers at that sigma and the 10 worst from its residuals.
Status ResidualStatistics(const ObservationSet& obs,
                          const CalibrationOptions& opt,
                          double sigma_solve,
                          CalibrationResult* r) {
  std::vector<PointResidual> all = Residuals(obs, r);
  const ba::BaResult& engine = *r->engine;
  r->num_points = static_cast<int>(all.size());
  r->dof = engine.dof;
  r->rms_px = engine.rms_plate_px;
  r->rms_opencv_px = std::sqrt(2.0) * engine.rms_plate_px;
  if (opt.pixel_sigma_px > 0) {
    r->sigma_px = opt.pixel_sigma_px;
  } else {
    if (r->dof <= 0) {
      return Status::Error(
          "cannot estimate the pixel sigma: " + std::to_string(engine.num_residuals) +
          " residuals for " + std::to_string(engine.num_free) +
          " parameters (give pixel_sigma_px or more points)");
    }
    // The engine's a-posteriori variance factor (covariance.scale: global), robust with a loss.
    r->sigma_px = sigma_solve * std::sqrt(engine.covariance_scale);
    r->sigma_estimated = true;
  }
  // Outliers and the 10 worst, largest first (only those are sorted).
  const auto larger = [](const PointResidual& a, const PointResidual& b) {
    return a.norm_px > b.norm_px;
  };
  for (const auto& pr : all) {
    if (pr.norm_px > opt.solve.outlier_sigma * r->sigma_px) r->outliers.push_back(pr);
  }
  std::sort(r->outliers.begin(), r->outliers.end(), larger);
  const size_t num_worst = std::min<size_t>(all.size(), 10);
  std::partial_sort(all.begin(), all.begin() + num_worst, all.end(), larger);
  all.resize(num_worst);
  r->worst = all;
  return Status::Ok();
}

// The covariance of the intrinsics, marginal over the poses (the engine's Schur covariance, at the
// pixel sigma used: given, or the engine's a-posteriori one), into r and its camera. A focal length
// known to worse than 10 % means the views do not constrain it (a fronto-parallel set is exactly
// singular without noise, nearly singular with it).
Status IntrinsicsCovariance(CalibrationResult* r) {
  const ba::BaResult& engine = *r->engine;
  r->covariance_scale = engine.covariance_scale;
  r->covariance = engine.GroupIntrinsicsCovariance(0);
  for (int i = 0; i < kNumIntrinsics; ++i)
    r->sigma[i] = std::sqrt(std::max(0.0, r->covariance(i, i)));
  constexpr double kMaxRelativeFocalSigma = 0.1;
  for (int i : {kFx, kFy}) {
    if (r->free[i] && !(r->sigma[i] < kMaxRelativeFocalSigma * r->camera.params[i])) {
      return Status::Error(std::string("the views do not determine ") + kIntrinsicNames[i] +
                           " (sigma " + std::to_string(r->sigma[i]) + " px for " +
                           std::to_string(r->camera.params[i]) +
                           " px); degenerate views, e.g. all fronto-parallel");
    }
  }
  r->camera.covariance_names.assign(kIntrinsicNames, kIntrinsicNames + kNumIntrinsics);
  r->camera.covariance.assign(kNumIntrinsics, std::vector<double>(kNumIntrinsics));
  for (int i = 0; i < kNumIntrinsics; ++i) {
    for (int j = 0; j < kNumIntrinsics; ++j) r->camera.covariance[i][j] = r->covariance(i, j);
  }
  return Status::Ok();
}

// The solution of the final stage into r: the intrinsics and poses, the engine's termination,
// the basis of the free intrinsics.
void TakeSolution(const StagedCalibration& solve,
                  std::shared_ptr<const ba::BaResult> engine,
                  int width,
                  int height,
                  CalibrationResult* r) {
  const ba::BlockInfo& gi = engine->layout->block(engine->layout->group_block(0));
  r->intrinsics_from_free = gi.constant ? Eigen::MatrixXd::Zero(kNumIntrinsics, 0) : gi.basis;
  r->num_free_intrinsics = static_cast<int>(r->intrinsics_from_free.cols());
  const auto& x = solve.intrinsics();
  std::copy(x.begin(), x.end(), r->camera.params.begin());
  r->camera.width = width;
  r->camera.height = height;
  r->cam_from_plate = solve.poses();
  r->engine = std::move(engine);
}

}  // namespace

StatusOr<CalibrationResult> Calibrate(const ObservationSet& obs, const CalibrationOptions& opt) {
  CARMBA_RETURN_IF_ERROR(CheckCalibrationInput(obs, opt));
  const auto t0 = std::chrono::steady_clock::now();
  auto start = InitialiseCalibration(obs, opt);
  if (!start.ok()) return start.status();
  CalibrationResult r;
  r.initial_intrinsics = start->intrinsics;
  r.initial_cam_from_plate = start->cam_from_plate;
  r.free = FreeIntrinsics(opt);
  r.loss = opt.solve.loss;
  r.loss_scale_px = opt.solve.loss_scale_px;
  std::array<bool, kNumIntrinsics> free{};
  for (int i = 0; i < kNumIntrinsics; ++i) free[i] = r.free[i];

  const double sigma_solve = opt.pixel_sigma_px > 0 ? opt.pixel_sigma_px : 1.0;
  StagedCalibration solve(obs, opt, *start, sigma_solve);
  CARMBA_RETURN_IF_ERROR(solve.SolveCore(free));
  if (opt.solve.distortion_auto) {
    auto selection = solve.SelectDistortion(&free);
    if (!selection.ok()) return selection.status();
    for (int i = kK1; i < kNumIntrinsics; ++i) r.free[i] = free[i];
    r.distortion = *selection;
  }
  auto solved = solve.Solve(free, false);
  if (!solved.ok()) return solved.status();
  TakeSolution(
      solve, std::make_shared<ba::BaResult>(std::move(*solved)), obs.width, obs.height, &r);
  const auto t1 = std::chrono::steady_clock::now();
  r.solve_seconds = Seconds(t0, t1);

  CARMBA_RETURN_IF_ERROR(ResidualStatistics(obs, opt, sigma_solve, &r));
  CARMBA_RETURN_IF_ERROR(IntrinsicsCovariance(&r));
  ProjectionSigmaAtCentreAndCorners(obs.width, obs.height, opt.uncertainty_distance_mm, &r);
  r.covariance_seconds = Seconds(t1, std::chrono::steady_clock::now());
  Status s = r.camera.Check();
  if (!s.ok()) return s.WithContext("calibrated camera");
  return r;
}

Status CheckPlateDistance(const CalibrationResult& result,
                          double spacing_mm,
                          const std::string& pitch_source) {
  std::vector<double> d;
  for (const ViewStats& v : result.views) d.push_back(v.distance_mm);
  if (d.empty()) return Status::Ok();
  std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
  const double median = d[d.size() / 2];
  if (InRange(median, plausible::kPlateDistanceMm)) return Status::Ok();
  return Status::Error(
      "the plate sits " + FormatCompact(median) + " mm from the source (median of " +
      std::to_string(result.views.size()) + " views), expected " +
      FormatRange(plausible::kPlateDistanceMm) + ": check the grid pitch, " + pitch_source + " " +
      FormatCompact(spacing_mm) +
      (median < plausible::kPlateDistanceMm.lo ? " (a unit slip? cm for mm)" : " (a unit slip?)"));
}

ObservationSet SolvedObservations(const ObservationSet& obs, const CalibrationResult& result) {
  ObservationSet out = obs;
  if (!result.engine || result.engine->shadow_offsets.empty()) return out;
  const auto& offsets = result.engine->shadow_offsets;  // the calibration's views, in obs order
  for (size_t v = 0; v < out.views.size() && v < offsets.size(); ++v) {
    for (size_t i = 0; i < out.views[v].uv_px.size() && i < offsets[v].size(); ++i) {
      out.views[v].uv_px[i] -= offsets[v][i];
    }
  }
  return out;
}

}  // namespace carmba
