#include "analysis/triangulation.h"

#include <cmath>
#include <cstdio>
#include <set>

#include "ba/quantities.h"
#include "camera/camera_model.h"
#include "geometry/rotation.h"
#include "util/format.h"
#include "util/stats.h"

namespace carmba {
namespace analysis {

bool TriangulationOptions::Check(std::string* error) const {
  if (!(min_ray_angle_deg >= 0 && min_ray_angle_deg < 90)) {
    *error = "min_ray_angle_deg must be in [0, 90) deg";
    return false;
  }
  if (max_iterations < 1) {
    *error = "max_iterations must be >= 1";
    return false;
  }
  return true;
}

namespace {

// X projected into view `view` at the solution: the pixel and, when `Jp` is given, d uv / d X
// (2 x 3, row-major). False when X lies behind the view's source.
bool ProjectIntoView(const ba::BaProblem& problem,
                     const ba::BaResult& result,
                     int view,
                     const Eigen::Vector3d& X,
                     double* uv,
                     double* Jp = nullptr) {
  return ProjectPointWithJac(result.GroupIntrinsics(problem.views[view].group).data(),
                             result.ViewPose(view).data(),
                             X.data(),
                             uv,
                             nullptr,
                             nullptr,
                             Jp);
}

// Each observation's ray in the object frame: origin = the source -R^T t, direction
// R^T (x, y, 1) normalised. Errors name the view that cannot give one.
Status ObjectRays(const ba::BaProblem& problem,
                  const ba::BaResult& result,
                  const std::vector<PixelObservation>& obs,
                  std::vector<Eigen::Vector3d>* origin,
                  std::vector<Eigen::Vector3d>* dir) {
  std::set<int> seen;
  for (const auto& o : obs) {
    if (o.view < 0 || o.view >= static_cast<int>(problem.views.size())) {
      return Status::Error("view index " + std::to_string(o.view) + " is not in the problem");
    }
    const ba::BaView& v = problem.views[o.view];
    if (v.kind != ba::ViewKind::kObject) {
      return Status::Error("view '" + v.id +
                           "' is a plate view: points are triangulated in object views");
    }
    if (!seen.insert(o.view).second) return Status::Error("view '" + v.id + "' is given twice");
    if (!o.uv_px.allFinite() || !o.covariance_px2.allFinite()) {
      return Status::Error("view '" + v.id + "': non-finite pixel or pixel covariance");
    }
    if (Eigen::LLT<Eigen::Matrix2d>(o.covariance_px2).info() != Eigen::Success ||
        !(o.covariance_px2.determinant() > 0)) {
      return Status::Error("view '" + v.id + "': the pixel covariance is not positive definite");
    }
    if (problem.groups[v.group].smooth) {
      return Status::Error("view '" + v.id + "': triangulation with angle-dependent (smooth) "
                           "intrinsics is not supported");
    }
    const std::array<double, kNumIntrinsics> intrinsics = result.GroupIntrinsics(v.group);
    const Pose6 view_pose = result.ViewPose(o.view);
    const double* K = intrinsics.data();
    const double* pose = view_pose.data();
    double xy[2];
    if (!UnprojectToNormalized(K, o.uv_px.data(), xy)) {
      return Status::Error("view '" + v.id + "': pixel (" + Fmt("%g", o.uv_px[0]) + ", " +
                           Fmt("%g", o.uv_px[1]) +
                           ") cannot be undistorted with the calibrated model");
    }
    const Eigen::Matrix3d R = RotationOf(Eigen::Vector3d(pose[0], pose[1], pose[2]));
    const Eigen::Vector3d t(pose[3], pose[4], pose[5]);
    origin->push_back(-R.transpose() * t);
    dir->push_back((R.transpose() * Eigen::Vector3d(xy[0], xy[1], 1.0)).normalized());
  }
  return Status::Ok();
}

// The widest angle between two rays (deg) and their indices.
double WidestRayPair(const std::vector<Eigen::Vector3d>& dir, int* wa, int* wb) {
  double widest = 0;
  *wa = 0, *wb = 1;
  for (size_t i = 0; i < dir.size(); ++i) {
    for (size_t j = i + 1; j < dir.size(); ++j) {
      const double a = std::atan2(dir[i].cross(dir[j]).norm(), dir[i].dot(dir[j]));
      if (a * kRadToDeg > widest) {
        widest = a * kRadToDeg;
        *wa = static_cast<int>(i), *wb = static_cast<int>(j);
      }
    }
  }
  return widest;
}

// The least-squares midpoint of the rays.
Eigen::Vector3d RayMidpoint(const std::vector<Eigen::Vector3d>& origin,
                            const std::vector<Eigen::Vector3d>& dir) {
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < dir.size(); ++i) {
    const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - dir[i] * dir[i].transpose();
    A += P;
    b += P * origin[i];
  }
  return A.ldlt().solve(b);
}

// The normal equations of the point's pixel residuals at p (whitened by each pixel covariance):
// N = sum J^T W J, g = sum J^T W r and the cost r^T W r.
Status PointNormalEquations(const ba::BaProblem& problem,
                            const ba::BaResult& result,
                            const std::vector<PixelObservation>& obs,
                            const Eigen::Vector3d& p,
                            Eigen::Matrix3d* N,
                            Eigen::Vector3d* g,
                            double* cost) {
  N->setZero();
  g->setZero();
  *cost = 0;
  for (const auto& o : obs) {
    const ba::BaView& v = problem.views[o.view];
    double uv[2], Jp[6];
    if (!ProjectIntoView(problem, result, o.view, p, uv, Jp)) {
      return Status::Error("the rays meet behind the source of view '" + v.id + "'");
    }
    const Eigen::Matrix<double, 2, 3> J =
        Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>>(Jp);
    const Eigen::Matrix2d W = o.covariance_px2.inverse();
    const Eigen::Vector2d r = Eigen::Vector2d(uv[0], uv[1]) - o.uv_px;
    *N += J.transpose() * W * J;
    *g += J.transpose() * W * r;
    *cost += r.dot(W * r);
  }
  return Status::Ok();
}

// Gauss-Newton in pixels from X, halving a step while it does not lower the cost (far from the
// optimum only); N: the normal matrix at the result.
Status RefineInPixels(const ba::BaProblem& problem,
                      const ba::BaResult& result,
                      const std::vector<PixelObservation>& obs,
                      int max_iterations,
                      Eigen::Vector3d* X,
                      Eigen::Matrix3d* N) {
  Eigen::Vector3d g;
  double cost = 0;
  for (int it = 0; it < max_iterations; ++it) {
    CARMBA_RETURN_IF_ERROR(PointNormalEquations(problem, result, obs, *X, N, &g, &cost));
    const Eigen::Vector3d step = -N->ldlt().solve(g);
    if (!step.allFinite()) break;
    double a = 1.0, new_cost = cost;
    Eigen::Matrix3d N2;
    Eigen::Vector3d g2;
    for (int k = 0; k < 30; ++k, a *= 0.5) {
      if (PointNormalEquations(problem, result, obs, *X + a * step, &N2, &g2, &new_cost).ok() &&
          new_cost <= cost) {
        break;
      }
    }
    if (!(new_cost <= cost)) break;
    *X += a * step;
    if ((a * step).norm() < 1e-10 * (1.0 + X->norm())) break;
  }
  return PointNormalEquations(problem, result, obs, *X, N, &g, &cost);
}

// The point's pixel Jacobians stacked over its observations: over the point (Js), over the
// solve's free state (Bs) and considered intrinsics (Bcs); the residuals and their covariance;
// and K, Kc = sum_i J_i^T W_i B_i over the free state and the considered intrinsics.
struct StackedPointJacobians {
  Eigen::MatrixXd K, Kc, Js, Bs, Bcs, Sigma;
  Eigen::VectorXd rs;
};

StackedPointJacobians StackPointJacobians(const ba::BaProblem& problem,
                                          const ba::BaResult& result,
                                          const std::vector<PixelObservation>& obs,
                                          const Eigen::Vector3d& X,
                                          TriangulatedPoint* out) {
  const ba::StateLayout& L = *result.layout;
  StackedPointJacobians s;
  s.K = Eigen::MatrixXd::Zero(3, L.num_free());
  s.Kc = Eigen::MatrixXd::Zero(3, L.num_consider());
  const Eigen::Index n2 = 2 * static_cast<Eigen::Index>(obs.size());
  s.Js.resize(n2, 3);
  s.Bs = Eigen::MatrixXd::Zero(n2, L.num_free());
  s.Bcs = Eigen::MatrixXd::Zero(n2, L.num_consider());
  s.rs.resize(n2);
  s.Sigma = Eigen::MatrixXd::Zero(n2, n2);
  int oi = 0;
  double ss = 0;
  for (const auto& o : obs) {
    const ba::BaView& v = problem.views[o.view];
    const int gb = L.group_block(v.group), vb = L.view_block(o.view);
    double uv[2], Ji[2 * kNumIntrinsics], Jpose[12], Jp[6];
    ProjectPointWithJac(result.GroupIntrinsics(v.group).data(),
                        result.ViewPose(o.view).data(),
                        X.data(),
                        uv,
                        Ji,
                        Jpose,
                        Jp);
    const Eigen::Matrix<double, 2, 3> J =
        Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>>(Jp);
    const Eigen::Matrix<double, 3, 2> JW = J.transpose() * o.covariance_px2.inverse();
    const Eigen::MatrixXd Bi =
        Eigen::Map<Eigen::Matrix<double, 2, kNumIntrinsics, Eigen::RowMajor>>(Ji);
    const Eigen::MatrixXd Bp = Eigen::Map<Eigen::Matrix<double, 2, 6, Eigen::RowMajor>>(Jpose);
    // Rows of J_i^T W_i B_i over the free state (tied parameters through the block's basis).
    const Eigen::Matrix<double, 3, kNumIntrinsics, Eigen::RowMajor> Ki = JW * Bi;
    const Eigen::Matrix<double, 3, 6, Eigen::RowMajor> Kp = JW * Bp;
    for (int row = 0; row < 3; ++row) {
      ba::AddGradientRow(L, gb, Ki.row(row).data(), row, &s.K);
      ba::AddGradientRow(L, vb, Kp.row(row).data(), row, &s.K);
      ba::AddConsiderGradientRow(L, gb, Ki.row(row).data(), row, &s.Kc);
    }
    const Eigen::Vector2d r = Eigen::Vector2d(uv[0], uv[1]) - o.uv_px;
    out->residual_px.push_back(r);
    ss += r.squaredNorm();
    for (int row = 0; row < 2; ++row) {
      ba::AddGradientRow(L, gb, Ji + row * kNumIntrinsics, 2 * oi + row, &s.Bs);
      ba::AddGradientRow(L, vb, Jpose + row * 6, 2 * oi + row, &s.Bs);
      ba::AddConsiderGradientRow(L, gb, Ji + row * kNumIntrinsics, 2 * oi + row, &s.Bcs);
    }
    s.Js.middleRows<2>(2 * oi) = J;
    s.rs.segment<2>(2 * oi) = r;
    s.Sigma.block<2, 2>(2 * oi, 2 * oi) = o.covariance_px2;
    ++oi;
  }
  out->rms_px = std::sqrt(ss / (2.0 * obs.size()));
  return s;
}

// The solve's and the considered calibration's shares of the point's covariance, with G = -N^-1 K
// (and the budget's traces by source), into out; out->covariance the total.
void PointSolveShares(const ba::BaResult& result,
                      const StackedPointJacobians& s,
                      TriangulatedPoint* out) {
  const Eigen::MatrixXd G = -out->covariance_pixels * s.K;
  const Eigen::MatrixXd Gc = -out->covariance_pixels * s.Kc;
  out->covariance_solve = G * result.covariance->Solve(G.transpose()) * result.covariance_scale;
  out->covariance_solve = 0.5 * (out->covariance_solve + out->covariance_solve.transpose()).eval();
  if (result.covariance->num_consider() > 0) {
    const Eigen::MatrixXd T = result.covariance->ConsiderGradient(G, Gc);  // 3 x nc
    out->covariance_calibration = T * result.covariance->consider_covariance() * T.transpose();
    out->covariance_calibration =
        0.5 * (out->covariance_calibration + out->covariance_calibration.transpose()).eval();
  }
  if (result.linearization) {
    const ba::ErrorBudget eb =
        result.covariance->Budget(G, *result.linearization, result.covariance_scale, Gc);
    for (int k = 0; k < ba::kNumSources; ++k)
      out->solve_trace_by_source[k] = eb.by_source.col(k).sum();
  }
  out->covariance = out->covariance_pixels + out->covariance_solve + out->covariance_calibration;
}

// Self-check: the residuals against their covariance M = the pixels' + the solve's projected
// (B C B^T, correlated between views through the shared intrinsics and markers), with the
// point's 3 directions taken out: chi2 = min_dX (r + J dX)^T M^-1 (r + J dX).
void TriangulationSelfCheck(const ba::BaResult& result,
                            const StackedPointJacobians& s,
                            int num_obs,
                            TriangulatedPoint* out) {
  Eigen::MatrixXd M =
      s.Sigma + s.Bs * result.covariance->Solve(s.Bs.transpose()) * result.covariance_scale;
  if (result.covariance->num_consider() > 0) {
    const Eigen::MatrixXd T = result.covariance->ConsiderGradient(s.Bs, s.Bcs);
    M += T * result.covariance->consider_covariance() * T.transpose();
  }
  const Eigen::LDLT<Eigen::MatrixXd> Mi(0.5 * (M + M.transpose()));
  const Eigen::VectorXd Mr = Mi.solve(s.rs);
  const Eigen::MatrixXd MJ = Mi.solve(s.Js);
  const Eigen::Vector3d gJ = s.Js.transpose() * Mr;
  out->chi2 = s.rs.dot(Mr) - gJ.dot((s.Js.transpose() * MJ).ldlt().solve(gJ));
  out->dof = 2 * num_obs - 3;
  out->chi2_p_value = ChiSquareUpperTail(out->chi2, out->dof);
}

// The point from all of `obs`, with its covariance and residuals.
StatusOr<TriangulatedPoint> TriangulateAll(const ba::BaProblem& problem,
                                           const ba::BaResult& result,
                                           const std::vector<PixelObservation>& obs,
                                           const TriangulationOptions& options) {
  if (obs.size() < 2) {
    return Status::Error(obs.empty() ? std::string("no observations")
                                     : "seen in one view only ('" + problem.views[obs[0].view].id +
                                           "'): at least two views are needed");
  }
  std::vector<Eigen::Vector3d> origin, dir;
  CARMBA_RETURN_IF_ERROR(ObjectRays(problem, result, obs, &origin, &dir));
  TriangulatedPoint out;
  int wa = 0, wb = 1;
  out.max_ray_angle_deg = WidestRayPair(dir, &wa, &wb);
  constexpr double kParallelDeg = 1e-6;  // below: the depth is not determined at all
  if (out.max_ray_angle_deg < kParallelDeg) {
    return Status::Error("the rays are parallel (" + Fmt("%.2g", out.max_ray_angle_deg) +
                         " deg apart): the depth along them is not determined");
  }
  Eigen::Vector3d X = RayMidpoint(origin, dir);
  Eigen::Matrix3d N;
  CARMBA_RETURN_IF_ERROR(RefineInPixels(problem, result, obs, options.max_iterations, &X, &N));
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(N);
  if (!(eig.eigenvalues()[0] > 1e-14 * eig.eigenvalues()[2])) {
    return Status::Error("the rays are too close to parallel (" +
                         Fmt("%.2g", out.max_ray_angle_deg) +
                         " deg apart): the depth along them is not determined");
  }
  out.p_in_object = X;
  out.covariance_pixels = N.inverse();
  const StackedPointJacobians stacked = StackPointJacobians(problem, result, obs, X, &out);
  PointSolveShares(result, stacked, &out);
  if (out.max_ray_angle_deg < options.min_ray_angle_deg) {
    const Eigen::Vector3d along = (dir[wa] + dir[wb]).normalized();
    out.warnings.push_back("the rays are nearly parallel: the widest pair (views '" +
                  problem.views[obs[wa].view].id + "' and '" + problem.views[obs[wb].view].id +
                  "') is " + Fmt("%.2f", out.max_ray_angle_deg) + " deg apart (below " +
                  Fmt("%g", options.min_ray_angle_deg) + "); sigma along the rays " +
                  Fmt("%.3g", std::sqrt(along.dot(out.covariance * along))) + " mm");
  }
  TriangulationSelfCheck(result, stacked, static_cast<int>(obs.size()), &out);
  return out;
}

// The pixel of `o` against the projection of X: residual (px) and its whitened norm.
std::pair<Eigen::Vector2d, double> PixelResidual(const ba::BaProblem& problem,
                                                  const ba::BaResult& result,
                                                  const PixelObservation& o,
                                                  const Eigen::Vector3d& X) {
  double uv[2];
  if (!ProjectIntoView(problem, result, o.view, X, uv)) {
    return {Eigen::Vector2d::Constant(std::nan("")), std::nan("")};
  }
  const Eigen::Vector2d r = Eigen::Vector2d(uv[0], uv[1]) - o.uv_px;
  return {r, std::sqrt(r.dot(o.covariance_px2.ldlt().solve(r)))};
}

}  // namespace

StatusOr<TriangulatedPoint> TriangulatePoint(const ba::BaProblem& problem,
                                             const ba::BaResult& result,
                                             const std::vector<PixelObservation>& obs,
                                             const TriangulationOptions& options) {
  std::string err;
  if (!options.Check(&err)) return Status::Error(err);
  if (!result.covariance) return Status::Error("the solve has no covariance");
  if (!problem.rigs.empty()) {
    return Status::Error(
        "triangulation through a solve with rigs is not supported (its views' poses are "
        "composed; carmba track triangulates its own beads)");
  }
  auto point = TriangulateAll(problem, result, obs, options);
  if (!point.ok()) return point;
  std::vector<size_t> used(obs.size());
  for (size_t i = 0; i < obs.size(); ++i) used[i] = i;
  std::vector<std::string> rejections;
  // Reject the most inconsistent ray while the rays do not meet and three or more remain.
  while (point->chi2_p_value < options.outlier_p && used.size() >= 3) {
    int best = -1;
    StatusOr<TriangulatedPoint> best_point = Status::Error("");
    for (size_t k = 0; k < used.size(); ++k) {
      std::vector<PixelObservation> rest;
      for (size_t m = 0; m < used.size(); ++m) {
        if (m != k) rest.push_back(obs[used[m]]);
      }
      auto t = TriangulateAll(problem, result, rest, options);
      if (t.ok() && (best < 0 || t->chi2 < best_point->chi2))
        best = static_cast<int>(k), best_point = t;
    }
    if (best < 0) break;
    const PixelObservation& out_obs = obs[used[best]];
    const auto [r, n_sigma] = PixelResidual(problem, result, out_obs, best_point->p_in_object);
    rejections.push_back("the ray of view '" + problem.views[out_obs.view].id +
                         "' was rejected as an outlier: its pixel (" +
                         Fmt("%.2f", out_obs.uv_px[0]) + ", " + Fmt("%.2f", out_obs.uv_px[1]) +
                         ") lies " + Fmt("%.3g", r.norm()) + " px (" + Fmt("%.3g", n_sigma) +
                         " sigma) from the point the other " + std::to_string(used.size() - 1) +
                         " rays give (chi-square of all rays " + Fmt("%.3g", point->chi2) + " on " +
                         std::to_string(point->dof) +
                         " dof, P = " + Fmt("%.2g", point->chi2_p_value) + ")");
    used.erase(used.begin() + best);
    point = best_point;
  }
  TriangulatedPoint out = std::move(*point);
  // Residuals and flags per observation as given.
  out.residual_px.assign(obs.size(), Eigen::Vector2d::Zero());
  out.rejected.assign(obs.size(), 1);
  for (size_t i = 0; i < obs.size(); ++i) {
    out.residual_px[i] = PixelResidual(problem, result, obs[i], out.p_in_object).first;
  }
  for (size_t i : used) out.rejected[i] = 0;
  out.warnings.insert(out.warnings.end(), rejections.begin(), rejections.end());
  if (!problem.markers.empty()) {
    // Far outside the markers (the points the poses were estimated from).
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (const auto& m : problem.markers) c += m.p_ct;
    c /= static_cast<double>(problem.markers.size());
    double extent = 0;
    for (const auto& m : problem.markers) extent = std::max(extent, (m.p_ct - c).norm());
    const double d = (out.p_in_object - c).norm();
    if (extent > 0 && d > kOutsideMarkersFactor * extent) {
      out.warnings.push_back("the point is " + Fmt("%.0f", d) + " mm from the markers' centroid, " +
                             "more than " + Fmt("%g", kOutsideMarkersFactor) +
                             " x their extent (" + Fmt("%.0f", extent) +
                             " mm): far outside the markers the poses were estimated from");
    }
  }
  if (out.chi2_p_value < options.outlier_p) {
    double worst = 0;
    for (size_t i : used) worst = std::max(worst, out.residual_px[i].norm());
    out.warnings.push_back(
        "the rays do not meet within their pixel covariances: chi-square " + Fmt("%.3g", out.chi2) +
        " on " + std::to_string(out.dof) + " dof (P = " + Fmt("%.2g", out.chi2_p_value) +
        "), a residual of " + Fmt("%.3g", worst) + " px" +
        (used.size() < 3 ? "; with two rays the wrong one cannot be told: check the pixels"
                         : "") +
        "; the covariance assumes they do");
  }
  return out;
}

}  // namespace analysis
}  // namespace carmba
