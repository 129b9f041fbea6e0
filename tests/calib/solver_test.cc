// `carmba calibrate`'s solve (the engine's carmba_lm / Ceres back ends, ba/bundle_adjuster.h) and
// its covariance (the engine's Schur covariance) against a plain dense reference: the normal
// equations of all parameters (plate poses and free intrinsics) assembled point by point from
// camera/camera_model.h's ProjectPointWithJac (not the solver's per-view kernel) and inverted
// densely. Checked: the marginal covariance of the intrinsics, the projection uncertainty (mrcal's
// definition) and that the returned solution is the minimum (a further Gauss-Newton step is
// negligible against the reported sigmas), for the plain problem, the thesis's constraints and a
// robust loss.
#include <ceres/loss_function.h>
#include <ceres/rotation.h>
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>

#include "calib/calibrate.h"
#include "calib/projection_uncertainty.h"
#include "synthetic/synthetic_views.h"

namespace carmba {
namespace {

const std::array<double, kNumIntrinsics> kSolverTruth = {2061.4, 2254.6, 203.7, 205.1, -0.3,
                                                   2.0,    0.0005, -0.0003, 0.0};

ObservationSet Views(int n, uint64_t seed) {
  SyntheticViewsOptions so;
  so.num_views = n;
  so.seed = seed;
  so.noise_sigma_px = 0.3;
  return MakeSyntheticViews(kSolverTruth, 408, 408, GridSpec(), so);
}

// H = sum w J^T J and g = sum w J^T e over [poses (6 per view) | free intrinsics (A)], unwhitened
// px, with w = rho'(|e|^2 / sigma_solve^2) under the result's robust loss (1 without).
struct DenseSystem {
  Eigen::MatrixXd H;
  Eigen::VectorXd g;
};

DenseSystem Assemble(const ObservationSet& obs, const CalibrationResult& r, double sigma_solve) {
  const int nv = static_cast<int>(obs.views.size());
  const Eigen::MatrixXd& A = r.intrinsics_from_free;
  const int k = static_cast<int>(A.cols());
  const int n = 6 * nv + k;
  DenseSystem s{Eigen::MatrixXd::Zero(n, n), Eigen::VectorXd::Zero(n)};
  std::unique_ptr<ceres::LossFunction> loss;
  const double a = r.loss_scale_px / sigma_solve;
  if (r.loss == ba::Loss::kHuber) loss.reset(new ceres::HuberLoss(a));
  if (r.loss == ba::Loss::kCauchy) loss.reset(new ceres::CauchyLoss(a));
  for (int v = 0; v < nv; ++v) {
    for (size_t j = 0; j < obs.views[v].uv_px.size(); ++j) {
      const Eigen::Vector3d P = obs.grid.PointInPlate(obs.views[v].point_ids[j]);
      double uv[2];
      Eigen::Matrix<double, 2, 9, Eigen::RowMajor> Ji;
      Eigen::Matrix<double, 2, 6, Eigen::RowMajor> Jp;
      EXPECT_TRUE(ProjectPointWithJac(r.camera.params.data(), r.cam_from_plate[v].data(), P.data(),
                                      uv, Ji.data(), Jp.data(), nullptr));
      const Eigen::Vector2d e(uv[0] - obs.views[v].uv_px[j].x(),
                              uv[1] - obs.views[v].uv_px[j].y());
      double w = 1;
      if (loss) {
        double rho[3];
        loss->Evaluate(e.squaredNorm() / (sigma_solve * sigma_solve), rho);
        w = rho[1];
      }
      Eigen::MatrixXd J = Eigen::MatrixXd::Zero(2, n);
      J.block<2, 6>(0, 6 * v) = Jp;
      J.rightCols(k) = Ji * A;
      s.H.noalias() += w * J.transpose() * J;
      s.g.noalias() += w * J.transpose() * e;
    }
  }
  return s;
}

// Inverse with a unit-diagonal scaling (the focal lengths are ~1e3 px, the rotations ~1e-2 rad).
Eigen::MatrixXd ScaledInverse(const Eigen::MatrixXd& H) {
  const Eigen::VectorXd d = H.diagonal().cwiseSqrt().cwiseInverse();
  const Eigen::MatrixXd Hn = d.asDiagonal() * H * d.asDiagonal();
  const Eigen::MatrixXd I = Eigen::MatrixXd::Identity(H.rows(), H.cols());
  return d.asDiagonal() * Hn.ldlt().solve(I) * d.asDiagonal();
}

struct Case {
  const char* name;
  CalibrationOptions options;
  int num_views;
  uint64_t seed;
};

std::vector<Case> Cases() {
  std::vector<Case> cases;
  cases.push_back({"all nine free", CalibrationOptions(), 16, 116});
  Case thesis{"thesis constraints", CalibrationOptions(), 16, 11};
  thesis.options.fix_aspect_ratio = true;
  thesis.options.zero_tangential = true;
  thesis.options.fix_principal_point = true;
  thesis.options.fix_k3 = true;
  cases.push_back(thesis);
  Case given_sigma{"given pixel sigma, 40 views", CalibrationOptions(), 40, 7};
  given_sigma.options.pixel_sigma_px = 0.3;
  cases.push_back(given_sigma);
  Case robust{"cauchy loss (Ceres path, same covariance code)", CalibrationOptions(), 16, 5};
  robust.options.solve.loss = ba::Loss::kCauchy;
  cases.push_back(robust);
  return cases;
}

TEST(SolverTest, CovarianceAndProjectionUncertaintyMatchDenseReference) {
  // Same quantities by different algebra (Schur blocks with the rotation Jacobian mapped per view
  // vs dense inverse of all parameters); the dense inverse of this ill-conditioned matrix (k2, k3
  // nearly collinear at an 11 degree field of view) loses digits, hence 1e-6, not 1e-12.
  constexpr double kCovRelTol = 1e-6;
  constexpr double kProjRelTol = 1e-6;
  for (const Case& c : Cases()) {
    SCOPED_TRACE(c.name);
    const ObservationSet obs = Views(c.num_views, c.seed);
    auto r = Calibrate(obs, c.options);
    ASSERT_TRUE(r.ok()) << r.status().message();
    const double sigma_solve = c.options.pixel_sigma_px > 0 ? c.options.pixel_sigma_px : 1.0;
    const DenseSystem s = Assemble(obs, *r, sigma_solve);
    const Eigen::MatrixXd H_inv = ScaledInverse(s.H);
    const int nv = static_cast<int>(obs.views.size());
    const int k = r->num_free_intrinsics;
    const Eigen::MatrixXd& A = r->intrinsics_from_free;
    const Eigen::MatrixXd cov =
        A * H_inv.bottomRightCorner(k, k) * A.transpose() * (r->sigma_px * r->sigma_px);
    for (int i = 0; i < kNumIntrinsics; ++i) {
      for (int j = 0; j < kNumIntrinsics; ++j) {
        const double scale = std::sqrt(cov(i, i) * cov(j, j));
        if (scale == 0) {
          EXPECT_EQ(r->covariance(i, j), 0.0) << i << "," << j;
          continue;
        }
        EXPECT_NEAR(r->covariance(i, j) / scale, cov(i, j) / scale, kCovRelTol)
            << kIntrinsicNames[i] << "," << kIntrinsicNames[j];
      }
    }
    // Projection uncertainty: q(theta) = project(intrinsics, mean_i T_i(theta) T_i0^-1 p_cam),
    // Cov(q) = J_q H^-1 J_q^T sigma^2 with J_q taken through ProjectPointWithJac per view.
    ASSERT_EQ(r->projection_sigma.size(), 5u);
    for (const ProjectionSigma& ps : r->projection_sigma) {
      SCOPED_TRACE(ps.where);
      const double q[2] = {ps.u_px, ps.v_px};
      double xy[2];
      ASSERT_TRUE(UnprojectToNormalized(r->camera.params.data(), q, xy));
      Eigen::Vector3d p_cam(xy[0], xy[1], 1.0);
      p_cam *= r->uncertainty_distance_mm / p_cam.norm();
      Eigen::MatrixXd Jq = Eigen::MatrixXd::Zero(2, 6 * nv + k);
      const double identity_pose[6] = {0, 0, 0, 0, 0, 0};
      double uv[2];
      Eigen::Matrix<double, 2, 9, Eigen::RowMajor> Ji;
      ASSERT_TRUE(ProjectPointWithJac(r->camera.params.data(), identity_pose, p_cam.data(), uv,
                                      Ji.data(), nullptr, nullptr));
      Jq.rightCols(k) = Ji * A;
      for (int v = 0; v < nv; ++v) {
        const auto& pose = r->cam_from_plate[v];
        double R[9];
        ceres::AngleAxisToRotationMatrix(pose.data(), ceres::RowMajorAdapter3x3(R));
        const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> Rm(R);
        const Eigen::Vector3d p_frame =
            Rm.transpose() * (p_cam - Eigen::Vector3d(pose[3], pose[4], pose[5]));
        Eigen::Matrix<double, 2, 6, Eigen::RowMajor> Jp;
        ASSERT_TRUE(ProjectPointWithJac(r->camera.params.data(), pose.data(), p_frame.data(), uv,
                                        nullptr, Jp.data(), nullptr));
        Jq.block<2, 6>(0, 6 * v) = Jp / nv;
      }
      const Eigen::Matrix2d cov_q = Jq * H_inv * Jq.transpose() * (r->sigma_px * r->sigma_px);
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(cov_q);
      EXPECT_NEAR(ps.sigma_u_px / std::sqrt(cov_q(0, 0)), 1.0, kProjRelTol);
      EXPECT_NEAR(ps.sigma_v_px / std::sqrt(cov_q(1, 1)), 1.0, kProjRelTol);
      EXPECT_NEAR(ps.worst_px / std::sqrt(es.eigenvalues()(1)), 1.0, kProjRelTol);
    }
  }
}

// Largest move of an intrinsic, in reported sigmas, by one more full Gauss-Newton step from the
// returned solution.
double FurtherStepInSigmas(const ObservationSet& obs, const CalibrationResult& r) {
  const DenseSystem s = Assemble(obs, r, 1.0);
  const Eigen::VectorXd step = -ScaledInverse(s.H) * s.g;
  const int k = r.num_free_intrinsics;
  const Eigen::VectorXd dx = r.intrinsics_from_free * step.tail(k);
  double worst = 0;
  for (int i = 0; i < kNumIntrinsics; ++i) {
    if (r.sigma[i] > 0) worst = std::max(worst, std::abs(dx(i)) / r.sigma[i]);
  }
  return worst;
}

TEST(SolverTest, SolutionIsTheMinimum) {
  // The LM stops at a relative cost change of 1e-10; a further Gauss-Newton step must not move any
  // intrinsic by more than 1e-3 of its sigma (measured: 5e-5, 8e-6 and 3.4e-4 for the three
  // cases). Gauss-Newton converges only linearly along the weakly determined distortion
  // directions (the residual curvature is not small against them), so one step understates the
  // remaining distance there; this checks the stopping point, it does not bound that distance.
  // The negative control (two iterations per stage: 1.2, 0.06 and 0.35 sigma) shows the measure
  // sees an unconverged solution.
  constexpr double kMaxStepSigma = 1e-3;
  for (const Case& c : Cases()) {
    SCOPED_TRACE(c.name);
    const ObservationSet obs = Views(c.num_views, c.seed);
    auto r = Calibrate(obs, c.options);
    ASSERT_TRUE(r.ok()) << r.status().message();
    if (c.options.solve.loss != ba::Loss::kTrivial)
      continue;  // a weighted problem: GN step differs
    EXPECT_LT(FurtherStepInSigmas(obs, *r), kMaxStepSigma);
    CalibrationOptions early = c.options;
    early.solve.max_iterations = 2;
    auto r2 = Calibrate(obs, early);
    ASSERT_TRUE(r2.ok()) << r2.status().message();
    EXPECT_GT(FurtherStepInSigmas(obs, *r2), 10 * kMaxStepSigma);
  }
}

}  // namespace
}  // namespace carmba
