// The pose bundle adjustment (pose_solver.h).
#include "problem/pose_solver.h"

#include <ceres/ceres.h>
#include <ceres/jet.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <numeric>
#include <set>

#include "ba/bundle_adjuster.h"
#include "geometry/rotation.h"
#include "problem/ba_assembly.h"
#include "util/stats.h"

namespace carmba {

StatusOr<std::pair<std::vector<int>, Eigen::MatrixXd>> ConsideredCalibration(const Camera& camera) {
  std::pair<std::vector<int>, Eigen::MatrixXd> out;
  const size_t n = camera.covariance_names.size();
  if (n == 0) return out;
  out.second.resize(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(n));
  for (size_t i = 0; i < n; ++i) {
    const auto* it =
        std::find(kIntrinsicNames, kIntrinsicNames + kNumIntrinsics, camera.covariance_names[i]);
    if (it == kIntrinsicNames + kNumIntrinsics || camera.covariance.size() != n ||
        camera.covariance[i].size() != n) {
      return Status::Error("covariance: expected a square matrix over intrinsic names");
    }
    out.first.push_back(static_cast<int>(it - kIntrinsicNames));
    for (size_t j = 0; j < n; ++j) out.second(i, j) = camera.covariance[i][j];
  }
  out.second = (0.5 * (out.second + out.second.transpose())).eval();
  return out;
}

std::vector<std::string> PoseWarnings(const PoseSolution& solution) {
  if (!solution.ba_result) return {};
  return ba::SolveWarnings(*solution.ba_result);
}

namespace {

// One intrinsics group held at the camera's values, with camera.json's covariance considered
// when the config asks.
StatusOr<ba::IntrinsicsGroup> HeldIntrinsics(const Problem& problem, const SolverConfig& config) {
  ba::IntrinsicsGroup g;
  std::copy(problem.camera->params.begin(), problem.camera->params.end(), g.initial.begin());
  g.free.fill(false);
  g.width = problem.camera->width;
  g.height = problem.camera->height;
  if (config.consider_calibration) {
    auto considered = ConsideredCalibration(*problem.camera);
    if (!considered.ok())
      return Status::Error(problem.path + ": camera: " + considered.status().message());
    g.consider_indices = considered->first;
    g.consider_covariance = considered->second;
  }
  return g;
}

// The engine's problem (problem/ba_assembly.h) with its one group held at the camera's values.
// Fills each view's initial pose into `sol`, and the validation pairs.
StatusOr<ba::BaProblem> PoseBaProblem(const Problem& problem,
                                      const SolverConfig& config,
                                      const ProgressFn& progress,
                                      PoseSolution* sol) {
  auto group = HeldIntrinsics(problem, config);
  if (!group.ok()) return group.status();
  BaAssemblyInput input;
  input.groups.push_back(*group);
  auto assembled = ToBaProblem(problem, config, std::move(input), progress);
  if (!assembled.ok()) return assembled.status();
  const ba::BaProblem& bp = assembled->problem;
  sol->views.resize(bp.views.size());
  for (size_t v = 0; v < bp.views.size(); ++v) {
    ViewSolution& vs = sol->views[v];
    vs.id = bp.views[v].id;
    vs.initial = bp.views[v].initial;
    vs.num_observations = static_cast<int>(bp.views[v].point_ids.size());
  }
  sol->validation_pairs = assembled->validation_pairs;
  return std::move(assembled->problem);
}

// The engine's failures with the pose problem's advice.
Status PoseSolveError(const Problem& problem, const Status& s) {
  switch (s.kind()) {
    case ErrorKind::kNotDetermined:
      return Status::Error(problem.path + ": " + s.message() +
                           " (degenerate geometry: too few or (near-)coplanar markers in a view?)");
    case ErrorKind::kNonFiniteInitialState:
      return Status::Error(problem.path + ": the initial poses give a non-finite cost (a marker "
                                          "behind the source?)");
    case ErrorKind::kOther:
      break;
  }
  return Status::Error(problem.path + ": " + s.message());
}

// The solution's poses and markers from the engine's result, and how the front end states its
// termination (NOT_REFINED when the config does not refine).
std::vector<Pose6> TakePoseSolution(const Problem& problem,
                                    const SolverConfig& config,
                                    PoseSolution* sol) {
  const ba::BaResult& r = *sol->ba_result;
  sol->termination = config.refine ? r.TerminationText() : "NOT_REFINED";
  sol->converged = !config.refine || r.converged();
  sol->final_cost = config.refine ? r.final_cost : r.initial_cost;
  const size_t V = problem.object_views.size();
  std::vector<Pose6> poses(V);
  for (size_t v = 0; v < V; ++v) poses[v] = r.ViewPose(static_cast<int>(v));
  std::map<int, Eigen::Vector3d> markers;
  for (size_t k = 0; k < sol->ba_problem->markers.size(); ++k) {
    markers[sol->ba_problem->markers[k].id] = r.MarkerPosition(static_cast<int>(k));
  }
  for (size_t v = 0; v < V; ++v) {  // the engine's reprojection statistics
    ViewSolution& vs = sol->views[v];
    vs.cam_from_object = poses[v];
    vs.rms_px = r.views[v].rms_px;
    vs.initial_rms_px = r.initial_view_rms_px.at(v);
  }
  sol->markers = std::move(markers);
  return poses;
}

// The joint covariance of all poses -- the engine's Schur covariance, or ceres::Covariance over
// the same problem (the configs' reference algorithms) -- and each view's sigmas (NaN unrefined).
Status PoseCovariance(const Problem& problem,
                      const SolverConfig& config,
                      const ba::BaOptions& options,
                      const std::vector<Pose6>& poses,
                      PoseSolution* sol) {
  const ba::BaResult& r = *sol->ba_result;
  if (!config.refine) {
    for (auto& vs : sol->views) {
      vs.covariance.setConstant(std::nan(""));
      vs.sigma_rotation_deg.setConstant(std::nan(""));
      vs.sigma_translation_mm.setConstant(std::nan(""));
    }
    return Status::Ok();
  }
  std::vector<int> views(poses.size());
  std::iota(views.begin(), views.end(), 0);
  const std::vector<int> pose_blocks = r.ViewBlocks(views);
  if (config.covariance_algorithm == ba::CovarianceAlgorithm::kSchur) {
    sol->joint_covariance = r.ViewPosesCovariance(views);
  } else {
    auto cov = ba::CeresBlockCovariance(
        *sol->ba_problem, options, r, pose_blocks, config.covariance_algorithm);
    if (!cov.ok()) {
      return Status::Error(problem.path +
                           ": the covariance is rank-deficient (degenerate geometry: too few or "
                           "(near-)coplanar markers in a view?)");
    }
    sol->joint_covariance = *cov;  // scaled as the engine's (BaResult::covariance_scale)
    if (r.covariance) sol->joint_covariance += r.CalibrationCovariance(pose_blocks);
  }
  sol->has_covariance = sol->joint_covariance.allFinite();
  for (size_t v = 0; v < poses.size(); ++v) {
    ViewSolution& vs = sol->views[v];
    vs.covariance = sol->ViewPoseCross(v, v);
    Eigen::Matrix3d Jl;
    SO3LeftJacobian(poses[v].data(), Jl.data());  // row-major into column-major storage
    Jl.transposeInPlace();
    const Eigen::Matrix3d local = Jl * vs.covariance.topLeftCorner<3, 3>() * Jl.transpose();
    vs.sigma_rotation_deg = local.diagonal().cwiseSqrt() * kRadToDeg;
    vs.sigma_translation_mm = vs.covariance.bottomRightCorner<3, 3>().diagonal().cwiseSqrt();
  }
  return Status::Ok();
}

// The angle between the viewing directions and the relative rotation of a validation pair, with
// their sigmas from the joint covariance.
PairSolution ValidationPairSolution(const ValidationPair& pair,
                                    size_t ia,
                                    size_t ib,
                                    const std::vector<Pose6>& poses,
                                    const PoseSolution& sol) {
  PairSolution ps;
  ps.a = pair.a, ps.b = pair.b, ps.expected_deg = pair.expected_deg;
  Eigen::Matrix<double, 12, 12> C;
  if (sol.has_covariance) {
    C << sol.ViewPoseCross(ia, ia), sol.ViewPoseCross(ia, ib), sol.ViewPoseCross(ib, ia),
        sol.ViewPoseCross(ib, ib);
  }
  Eigen::Matrix<double, 12, 1> g;
  const double vd = PairMetricWithGradient(
      poses[ia].data(), poses[ib].data(),
      [](auto* a, auto* b) { return ViewDirectionAngle(a, b); }, g.data());
  ps.angle_view_dirs_deg = vd * kRadToDeg;
  ps.sigma_view_dirs_deg = sol.has_covariance ? std::sqrt(g.dot(C * g)) * kRadToDeg : std::nan("");
  const double rr = PairMetricWithGradient(
      poses[ia].data(), poses[ib].data(),
      [](auto* a, auto* b) { return RelativeRotationAngle(a, b); }, g.data());
  ps.relative_rotation_deg = rr * kRadToDeg;
  ps.sigma_relative_rotation_deg =
      sol.has_covariance ? std::sqrt(g.dot(C * g)) * kRadToDeg : std::nan("");
  return ps;
}

}  // namespace

StatusOr<PoseSolution> SolvePoseProblem(const Problem& problem,
                                        const SolverConfig& config,
                                        const ProgressFn& progress) {
  const auto t0 = std::chrono::steady_clock::now();
  std::string err;
  if (!config.Check(&err)) return Status::Error(config.path + ": " + err);
  if (!problem.IsPoseProblem() || !problem.camera) {
    return Status::Error(problem.path +
                         ": not a pose problem (it needs object views only and the "
                         "camera, without an intrinsics prior): solve it as a joint problem");
  }
  CARMBA_RETURN_IF_ERROR(problem.Check());
  PoseSolution sol;
  sol.config_name = config.name;
  auto bp = PoseBaProblem(problem, config, progress, &sol);
  if (!bp.ok()) return bp.status();
  const ba::BaOptions options = config.ToBaOptions();
  auto solved = ba::SolveBundleAdjustment(*bp, options);
  if (!solved.ok()) return PoseSolveError(problem, solved.status());
  sol.ba_problem = std::make_shared<const ba::BaProblem>(std::move(*bp));
  sol.ba_result = std::make_shared<const ba::BaResult>(std::move(*solved));
  const std::vector<Pose6> poses = TakePoseSolution(problem, config, &sol);
  CARMBA_RETURN_IF_ERROR(PoseCovariance(problem, config, options, poses, &sol));

  for (size_t k = 0; k < problem.validation.size(); ++k) {
    const auto [ia, ib] = sol.validation_pairs[k];
    sol.validation.push_back(ValidationPairSolution(problem.validation[k], ia, ib, poses, sol));
  }
  // Relative poses (every pair of few views, else the validation pairs) and, when asked, the
  // leave-one-marker-out TRE: both from the engine's covariance.
  const ba::BaResult& r = *sol.ba_result;
  const bool engine_covariance = config.refine &&
                                 config.covariance_algorithm == ba::CovarianceAlgorithm::kSchur &&
                                 r.covariance;
  if (engine_covariance) {
    sol.relative_poses = analysis::EstimateRelativePoses(
        r, analysis::RelativePosePairs(*sol.ba_problem, sol.validation_pairs));
  }
  sol.time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (config.tre) {
    if (!engine_covariance) {
      return Status::Error(config.path +
                           ": tre: true needs the refined solve with the engine's "
                           "covariance (refine: true, covariance: {algorithm: schur})");
    }
    auto tre = analysis::LeaveOneMarkerOut(*sol.ba_problem, r, options);
    if (!tre.ok()) return Status::Error(problem.path + ": " + tre.status().message());
    sol.tre = *tre;
  }
  return sol;
}

}  // namespace carmba
