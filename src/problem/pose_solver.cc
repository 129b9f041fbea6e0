// The pose bundle adjustment (pose_problem.h).
#include <ceres/ceres.h>
#include <ceres/jet.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <opencv2/calib3d.hpp>
#include <limits>
#include <memory>
#include <set>

#include "ba/reprojection_error.h"
#include "geometry/rotation.h"
#include "pose/posit.h"
#include "problem/pose_covariance.h"
#include "problem/pose_problem.h"
#include "util/stats.h"

namespace carmba {

Eigen::Vector3d MarkerInProblemFrame(const PoseProblem& problem, const Marker& m) {
  Eigen::Vector3d p = m.p_in_object;
  if (problem.handedness == Handedness::kMirrored) p.y() = -p.y();
  return p;
}

namespace {

Eigen::Matrix3d MarkerCovarianceInProblemFrame(const PoseProblem& problem, const Marker& m) {
  if (problem.handedness == Handedness::kAsGiven) return m.covariance;
  const Eigen::Matrix3d F = Eigen::Vector3d(1, -1, 1).asDiagonal();
  return F * m.covariance * F;
}

}  // namespace

StatusOr<Pose6> InitialObjectPose(const Camera& cam,
                                  Initializer initializer,
                                  const std::vector<Eigen::Vector3d>& pts,
                                  const std::vector<Eigen::Vector2d>& uv) {
  switch (initializer) {
    case Initializer::kPosit:
      return PositPose(cam, pts, uv, PositOptions());
    case Initializer::kLegacyPosit: {
      // OpenCV 1.x cvPOSIT as the thesis used it, but in this problem's camera convention:
      // undistorted pixels relative to the principal point, one focal length (fx + fy) / 2,
      // float32, non-orthonormal rows; the result is projected to the nearest rotation.
      std::vector<Eigen::Vector2d> img(uv.size());
      for (size_t i = 0; i < uv.size(); ++i) {
        double xy[2];
        if (!UnprojectToNormalized(cam.params.data(), uv[i].data(), xy)) {
          return Status::Error("legacy POSIT: pixel " + std::to_string(i) +
                               " cannot be undistorted");
        }
        img[i] = Eigen::Vector2d(xy[0] * cam.params[kFx], xy[1] * cam.params[kFy]);
      }
      PositOptions o;
      o.mode = PositMode::kLegacy;
      auto r = Posit(pts, img, 0.5 * (cam.params[kFx] + cam.params[kFy]), o);
      if (!r.ok()) return r.status();
      const Eigen::Matrix3d R = NearestRotation(r->R);
      Pose6 pose;
      pose.head<3>() = RvecFromRotation(R);
      pose.tail<3>() = r->t - R * pts[0];
      return pose;
    }
    case Initializer::kEpnp:
    case Initializer::kSqpnp: {
      cv::Mat obj(static_cast<int>(pts.size()), 3, CV_64F), img(static_cast<int>(uv.size()), 2,
                                                                CV_64F);
      for (size_t i = 0; i < pts.size(); ++i) {
        for (int c = 0; c < 3; ++c) obj.at<double>(static_cast<int>(i), c) = pts[i][c];
        for (int c = 0; c < 2; ++c) img.at<double>(static_cast<int>(i), c) = uv[i][c];
      }
      const cv::Matx33d K(cam.params[kFx], 0, cam.params[kCx], 0, cam.params[kFy],
                          cam.params[kCy], 0, 0, 1);
      const cv::Matx<double, 1, 5> dist(cam.params[kK1], cam.params[kK2], cam.params[kP1],
                                        cam.params[kP2], cam.params[kK3]);
      cv::Mat rvec, tvec;
      bool ok = false;
      try {
        ok = cv::solvePnP(obj, img, K, dist, rvec, tvec, false,
                          initializer == Initializer::kEpnp ? cv::SOLVEPNP_EPNP
                                                                   : cv::SOLVEPNP_SQPNP);
      } catch (const cv::Exception& e) {
        return Status::Error(std::string(InitializerName(initializer)) + ": " + e.what());
      }
      if (!ok || rvec.empty()) {
        return Status::Error(std::string(InitializerName(initializer)) + " failed");
      }
      Pose6 pose;
      for (int c = 0; c < 3; ++c) pose[c] = rvec.at<double>(c), pose[3 + c] = tvec.at<double>(c);
      if (!pose.allFinite() || !(pose[5] > 0)) {
        return Status::Error(std::string(InitializerName(initializer)) +
                             " returned an invalid pose");
      }
      return pose;
    }
  }
  return Status::Error("unknown initializer");
}

namespace {

double ViewRms(const PoseProblem& problem,
               const PoseView& view,
               const Pose6& pose,
               const std::map<int, Eigen::Vector3d>& markers) {
  double ss = 0;
  int n = 0;
  for (const auto& o : view.observations) {
    Eigen::Vector2d q;
    if (!ProjectPoint(problem.camera.params.data(), pose.data(), markers.at(o.marker_id).data(),
                      q.data())) {
      return std::numeric_limits<double>::infinity();
    }
    ss += (q - o.uv_px).squaredNorm();
    n += 2;
  }
  return std::sqrt(ss / n);
}

// Sum of squared whitened residuals (reprojection and CT priors), without any robust loss.
// `information` holds each marker's CT information (problem frame), markers in id order.
double WhitenedChi2(const PoseProblem& problem,
                    const std::vector<Pose6>& poses,
                    const std::map<int, Eigen::Vector3d>& markers,
                    const std::map<int, const Marker*>& marker_by_id,
                    const std::vector<Eigen::Matrix3d>& information) {
  double chi2 = 0;
  const double w = 1.0 / (problem.sigma_px * problem.sigma_px);
  for (size_t v = 0; v < problem.views.size(); ++v) {
    for (const auto& o : problem.views[v].observations) {
      Eigen::Vector2d q;
      if (!ProjectPoint(problem.camera.params.data(), poses[v].data(),
                        markers.at(o.marker_id).data(), q.data())) {
        return std::numeric_limits<double>::infinity();
      }
      chi2 += (q - o.uv_px).squaredNorm() * w;
    }
  }
  size_t k = 0;
  for (const auto& [id, p] : markers) {
    const Eigen::Vector3d d = p - MarkerInProblemFrame(problem, *marker_by_id.at(id));
    chi2 += d.dot(information[k++] * d);
  }
  return chi2;
}

ceres::LossFunction* MakeLoss(const SolverConfig& c, double sigma_px) {
  const double s = c.loss_scale_px / sigma_px;  // residuals are whitened
  if (c.loss == "huber") return new ceres::HuberLoss(s);
  if (c.loss == "cauchy") return new ceres::CauchyLoss(s);
  if (c.loss == "soft_l1") return new ceres::SoftLOneLoss(s);
  return nullptr;
}

ceres::LinearSolverType LinearSolver(const std::string& name) {
  if (name == "dense_qr") return ceres::DENSE_QR;
  if (name == "dense_normal_cholesky") return ceres::DENSE_NORMAL_CHOLESKY;
  if (name == "sparse_schur") return ceres::SPARSE_SCHUR;
  if (name == "sparse_normal_cholesky") return ceres::SPARSE_NORMAL_CHOLESKY;
  if (name == "iterative_schur") return ceres::ITERATIVE_SCHUR;
  return ceres::DENSE_SCHUR;
}

// Value and gradient (w.r.t. the 12 parameters of two poses) of a pair metric.
template <typename F>
double PairMetric(const Pose6& a, const Pose6& b, F f, Eigen::Matrix<double, 12, 1>* grad) {
  using J = ceres::Jet<double, 12>;
  J pa[6], pb[6];
  for (int i = 0; i < 6; ++i) {
    pa[i] = J(a[i], i);
    pb[i] = J(b[i], 6 + i);
  }
  const J v = f(pa, pb);
  *grad = v.v;
  return v.a;
}

}  // namespace

StatusOr<PoseSolution> SolvePoseProblem(const PoseProblem& problem, const SolverConfig& config) {
  const auto t0 = std::chrono::steady_clock::now();
  std::string err;
  if (!config.Check(&err)) return Status::Error(config.path + ": " + err);
  CARMBA_RETURN_IF_ERROR(problem.Check());

  PoseSolution sol;
  sol.config_name = config.name;
  // Marker parameter blocks (only markers that some view observes).
  std::set<int> observed;
  for (const auto& v : problem.views) {
    for (const auto& o : v.observations) observed.insert(o.marker_id);
  }
  std::map<int, Eigen::Vector3d> markers;  // the parameter blocks, problem frame
  std::map<int, const Marker*> marker_by_id;
  for (const auto& m : problem.markers) {
    marker_by_id[m.id] = &m;
    if (observed.count(m.id)) markers[m.id] = MarkerInProblemFrame(problem, m);
  }

  // Initial poses.
  const size_t V = problem.views.size();
  std::vector<Pose6> poses(V);
  sol.views.resize(V);
  for (size_t v = 0; v < V; ++v) {
    std::vector<Eigen::Vector3d> pts;
    std::vector<Eigen::Vector2d> uv;
    for (const auto& o : problem.views[v].observations) {
      pts.push_back(markers.at(o.marker_id));
      uv.push_back(o.uv_px);
    }
    auto init = InitialObjectPose(problem.camera, config.initializer, pts, uv);
    if (!init.ok()) {
      return Status::Error(problem.path + ": view '" + problem.views[v].id + "': " +
                           init.status().message());
    }
    poses[v] = *init;
    sol.views[v].id = problem.views[v].id;
    sol.views[v].initial = *init;
    sol.views[v].initial_rms_px = ViewRms(problem, problem.views[v], *init, markers);
    sol.views[v].num_observations = static_cast<int>(problem.views[v].observations.size());
  }

  // The Ceres problem. All parameter blocks live in ONE buffer in a fixed order (poses, then
  // markers by id, then the intrinsics): Ceres orders blocks by address in places (the
  // covariance, elimination groups), so separately allocated blocks would make the results
  // depend on the heap layout in the last digits.
  const size_t M = markers.size();
  std::vector<double> buffer(6 * V + 3 * M + kNumIntrinsics);
  auto pose_ptr = [&](size_t v) { return buffer.data() + 6 * v; };
  std::map<int, double*> marker_ptr;
  {
    size_t k = 0;
    for (auto& [id, p] : markers) {
      marker_ptr[id] = buffer.data() + 6 * V + 3 * k++;
      std::copy(p.data(), p.data() + 3, marker_ptr[id]);
    }
  }
  for (size_t v = 0; v < V; ++v) std::copy(poses[v].data(), poses[v].data() + 6, pose_ptr(v));
  double* intrinsics = buffer.data() + 6 * V + 3 * M;
  std::copy(problem.camera.params.begin(), problem.camera.params.end(), intrinsics);
  // One Ceres context per thread, reused by every solve (Problem::Options::context): a study
  // solves thousands of small problems and need not build a context for each.
  static thread_local std::unique_ptr<ceres::Context> context(ceres::Context::Create());
  ceres::Problem::Options popts;
  popts.context = context.get();
  // The blocks below are built from validated input with sizes fixed at compile time; Ceres's
  // per-block checks (duplicate or aliasing parameter blocks) cannot fire here.
  popts.disable_all_safety_checks = true;
  ceres::Problem cp(popts);
  // The same blocks, as the Schur covariance needs them (owned by the Ceres problem).
  PoseCovarianceInput cov_in;
  std::map<int, int> marker_index;
  for (auto& [id, p] : marker_ptr) {
    marker_index[id] = static_cast<int>(cov_in.markers.size());
    cov_in.markers.push_back(p);
  }
  for (size_t v = 0; v < V; ++v) cov_in.poses.push_back(pose_ptr(v));
  cov_in.intrinsics = intrinsics;
  for (size_t v = 0; v < V; ++v) {
    for (const auto& o : problem.views[v].observations) {
      ceres::CostFunction* cost =
          config.analytic_jacobians
              ? ReprojectionError::Create(o.uv_px.x(), o.uv_px.y(), problem.sigma_px)
              : ReprojectionErrorAutoDiff::Create(o.uv_px.x(), o.uv_px.y(), problem.sigma_px);
      ceres::LossFunction* loss = MakeLoss(config, problem.sigma_px);
      cp.AddResidualBlock(cost, loss, pose_ptr(v), marker_ptr.at(o.marker_id), intrinsics);
      cov_in.blocks.push_back({cost, loss, static_cast<int>(v), marker_index.at(o.marker_id)});
    }
  }
  cp.SetParameterBlockConstant(intrinsics);
  for (auto& [id, p] : markers) {
    const Marker& m = *marker_by_id.at(id);
    const Eigen::Matrix3d cov = MarkerCovarianceInProblemFrame(problem, m);
    Eigen::Matrix3d S;
    if (!SqrtInformation(cov, &S)) {
      return Status::Error(problem.path + ": marker " + std::to_string(id) +
                           ": covariance is not symmetric positive definite");
    }
    // As two 2-row blocks (PointPriorRows): all marker rows then have 2 rows and Ceres uses its
    // fixed-size Schur eliminator.
    cov_in.marker_information.push_back(S.transpose() * S);
    const auto [rows01, row2] = PointPriorRows::Split(MarkerInProblemFrame(problem, m), S);
    cp.AddResidualBlock(rows01, nullptr, marker_ptr.at(id));
    cp.AddResidualBlock(row2, nullptr, marker_ptr.at(id));
  }
  // Initial cost, evaluated directly (Problem::Evaluate rebuilds Ceres's program each call).
  {
    const double chi2_0 = WhitenedChi2(problem, poses, markers, marker_by_id, cov_in.marker_information);
    if (!std::isfinite(chi2_0)) {
      return Status::Error(problem.path + ": the initial poses give a non-finite cost (a marker "
                                          "behind the source?)");
    }
    sol.initial_cost = 0.5 * chi2_0;
  }

  if (config.refine) {
    ceres::Solver::Options so;
    so.linear_solver_type = LinearSolver(config.linear_solver);
    so.max_num_iterations = config.max_iterations;
    so.function_tolerance = config.function_tolerance;
    so.gradient_tolerance = config.gradient_tolerance;
    so.parameter_tolerance = config.parameter_tolerance;
    so.num_threads = config.num_threads;
    so.logging_type = ceres::SILENT;
    if (so.linear_solver_type == ceres::DENSE_SCHUR || so.linear_solver_type == ceres::SPARSE_SCHUR ||
        so.linear_solver_type == ceres::ITERATIVE_SCHUR) {
      // Eliminate the markers first, then the poses: given explicitly, Ceres need not search
      // for an independent set.
      auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
      for (auto& [id, p] : marker_ptr) ordering->AddElementToGroup(p, 0);
      for (size_t v = 0; v < V; ++v) ordering->AddElementToGroup(pose_ptr(v), 1);
      so.linear_solver_ordering = ordering;
    }
    so.minimizer_progress_to_stdout = false;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &cp, &summary);
    sol.iterations = static_cast<int>(summary.iterations.size()) - 1;
    sol.termination = ceres::TerminationTypeToString(summary.termination_type);
    if (summary.termination_type == ceres::FAILURE ||
        summary.termination_type == ceres::USER_FAILURE) {
      return Status::Error(problem.path + ": bundle adjustment failed: " + summary.message);
    }
    sol.final_cost = summary.final_cost;
  } else {
    sol.termination = "NOT_REFINED";
    sol.final_cost = sol.initial_cost;
  }

  for (size_t v = 0; v < V; ++v) std::copy(pose_ptr(v), pose_ptr(v) + 6, poses[v].data());
  for (auto& [id, p] : markers) std::copy(marker_ptr.at(id), marker_ptr.at(id) + 3, p.data());

  // Statistics from the raw (loss-free) whitened residuals.
  sol.chi2 = WhitenedChi2(problem, poses, markers, marker_by_id, cov_in.marker_information);
  sol.num_residuals = 0;
  for (const auto& v : problem.views) sol.num_residuals += 2 * static_cast<int>(v.observations.size());
  sol.num_residuals += 3 * static_cast<int>(markers.size());
  double ss = 0;
  int n = 0;
  for (size_t v = 0; v < V; ++v) {
    sol.views[v].cam_from_object = poses[v];
    sol.views[v].rms_px = ViewRms(problem, problem.views[v], poses[v], markers);
    ss += sol.views[v].rms_px * sol.views[v].rms_px * 2 * sol.views[v].num_observations;
    n += 2 * sol.views[v].num_observations;
  }
  sol.rms_px = std::sqrt(ss / n);
  sol.markers = markers;
  sol.num_parameters = static_cast<int>(6 * V + 3 * markers.size());
  sol.dof = sol.num_residuals - sol.num_parameters;
  sol.sigma0 = sol.dof > 0 ? std::sqrt(sol.chi2 / sol.dof) : std::nan("");
  sol.sigma_aposteriori_px = sol.sigma0 * problem.sigma_px;
  sol.chi2_p_value = ChiSquareUpperTail(sol.chi2, sol.dof);

  // Joint covariance of all poses.
  if (config.refine && config.covariance_algorithm == "schur") {
    auto cov = PoseCovarianceBySchur(cov_in);
    if (!cov.ok()) {
      return Status::Error(problem.path + ": " + cov.status().message() +
                           " (degenerate geometry: too few or (near-)coplanar markers in a view?)");
    }
    sol.joint_covariance = std::move(*cov);
  } else if (config.refine) {
    ceres::Covariance::Options co;
    co.algorithm_type =
        config.covariance_algorithm == "dense_svd" ? ceres::DENSE_SVD : ceres::SPARSE_QR;
    if (config.covariance_algorithm == "eigen_sparse_qr") {
      co.sparse_linear_algebra_library_type = ceres::EIGEN_SPARSE;
    }
    co.num_threads = config.num_threads;
    co.null_space_rank = 0;
    co.min_reciprocal_condition_number = 1e-14;
    ceres::Covariance covariance(co);
    std::vector<std::pair<const double*, const double*>> pairs;
    std::vector<const double*> blocks;
    for (size_t i = 0; i < V; ++i) {
      blocks.push_back(pose_ptr(i));
      for (size_t j = i; j < V; ++j) pairs.emplace_back(pose_ptr(i), pose_ptr(j));
    }
    if (!covariance.Compute(pairs, &cp)) {
      return Status::Error(problem.path +
                           ": the covariance is rank-deficient (degenerate geometry: too few or "
                           "(near-)coplanar markers in a view?)");
    }
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> jc(6 * V, 6 * V);
    covariance.GetCovarianceMatrix(blocks, jc.data());
    sol.joint_covariance = jc;
  }
  if (config.refine) {
    if (config.covariance_aposteriori && std::isfinite(sol.sigma0)) {
      sol.joint_covariance *= sol.sigma0 * sol.sigma0;
    }
    sol.has_covariance = sol.joint_covariance.allFinite();
    for (size_t v = 0; v < V; ++v) {
      ViewSolution& vs = sol.views[v];
      vs.covariance = sol.joint_covariance.block<6, 6>(6 * v, 6 * v);
      Eigen::Matrix3d Jl;
      SO3LeftJacobian(poses[v].data(), Jl.data());  // row-major into column-major storage
      Jl.transposeInPlace();
      const Eigen::Matrix3d local = Jl * vs.covariance.topLeftCorner<3, 3>() * Jl.transpose();
      vs.sigma_rotation_deg = local.diagonal().cwiseSqrt() * kRadToDeg;
      vs.sigma_translation_mm = vs.covariance.bottomRightCorner<3, 3>().diagonal().cwiseSqrt();
    }
  } else {
    for (auto& vs : sol.views) {
      vs.covariance.setConstant(std::nan(""));
      vs.sigma_rotation_deg.setConstant(std::nan(""));
      vs.sigma_translation_mm.setConstant(std::nan(""));
    }
  }

  // Validation pairs.
  std::map<std::string, size_t> index;
  for (size_t v = 0; v < V; ++v) index[problem.views[v].id] = v;
  for (const auto& pr : problem.validation) {
    PairSolution ps;
    ps.a = pr.a, ps.b = pr.b, ps.expected_deg = pr.expected_deg;
    const size_t ia = index.at(pr.a), ib = index.at(pr.b);
    Eigen::Matrix<double, 12, 12> C;
    if (sol.has_covariance) {
      C.topLeftCorner<6, 6>() = sol.joint_covariance.block<6, 6>(6 * ia, 6 * ia);
      C.topRightCorner<6, 6>() = sol.joint_covariance.block<6, 6>(6 * ia, 6 * ib);
      C.bottomLeftCorner<6, 6>() = sol.joint_covariance.block<6, 6>(6 * ib, 6 * ia);
      C.bottomRightCorner<6, 6>() = sol.joint_covariance.block<6, 6>(6 * ib, 6 * ib);
    }
    Eigen::Matrix<double, 12, 1> g;
    const double vd = PairMetric(poses[ia], poses[ib],
                                 [](auto* a, auto* b) { return ViewDirectionAngle(a, b); }, &g);
    ps.angle_view_dirs_deg = vd * kRadToDeg;
    ps.sigma_view_dirs_deg =
        sol.has_covariance ? std::sqrt(g.dot(C * g)) * kRadToDeg : std::nan("");
    const double rr = PairMetric(poses[ia], poses[ib],
                                 [](auto* a, auto* b) { return RelativeRotationAngle(a, b); }, &g);
    ps.relative_rotation_deg = rr * kRadToDeg;
    ps.sigma_relative_rotation_deg =
        sol.has_covariance ? std::sqrt(g.dot(C * g)) * kRadToDeg : std::nan("");
    sol.validation.push_back(ps);
  }
  sol.time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return sol;
}

}  // namespace carmba
