#include "camera/camera_model.h"

#include <ceres/gradient_checker.h>
#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <opencv2/calib3d.hpp>
#include <memory>
#include <random>

#include "ba/reprojection_error.h"

extern "C" {
#include <mrcal/mrcal.h>
}

namespace carmba {
namespace {

// Analytic vs ceres::Jet: the same derivative evaluated by two formulas in double precision;
// they agree to rounding (~1e-13 relative), so 1e-10 relative to max(1, |J|) catches any
// algebra error while allowing rounding.
constexpr double kJacTol = 1e-10;
// GradientChecker uses central finite differences (truncation and rounding error ~1e-7 relative
// at its default step, and ~1e-13 absolute on entries as small as 1e-11, like d/dk3 near the
// image centre), hence the looser tolerance, relative to max(1, |J|), on the whole cost function.
constexpr double kFiniteDiffTol = 1e-6;
// Projection agreement with OpenCV and mrcal: both evaluate the same OPENCV5 polynomial.
constexpr double kProjTolPx = 1e-9;

struct Case {
  std::array<double, 9> intrinsics;
  std::array<double, 6> pose;
  std::array<double, 3> point;
};

// A grid of parameter sets (barrel, pincushion, tangential, none) x poses x points.
std::vector<Case> Grid() {
  const std::vector<std::array<double, 9>> intr = {
      {2061.389, 2254.646, 203.655, 205.117, 0, 0, 0, 0, 0},
      {2061.389, 2254.646, 203.655, 205.117, -0.25, 0.12, 1e-3, -2e-3, -0.03},
      {1500.0, 1480.0, 320.0, 240.0, 0.3, -0.2, -4e-3, 3e-3, 0.5},
      {800.0, 820.0, 100.5, 90.25, -0.05, 0.01, 0.02, -0.01, 0.001}};
  const std::vector<std::array<double, 6>> poses = {
      {0, 0, 0, 0, 0, 700},
      {0.3, -0.4, 0.2, 10, -20, 800},
      {2.8, 0.1, -0.3, -5, 3, 650},       // near 180 degrees, like the thesis's 0-degree view
      // Small rotation: exercises our Taylor branch of J_l (|r| < 1e-4) against Ceres's exact
      // formula. (Below |r| ~ 1.5e-8 Ceres itself switches to p + r x p, whose derivative is only
      // first-order accurate, so it cannot serve as the reference there.)
      {1e-5, 2e-5, -1e-5, 1, 2, 900}};
  const std::vector<std::array<double, 3>> points = {
      {0, 0, 0}, {-58.85, 1, 14}, {13.35, -20, 49}, {40, 40, -30}};
  std::vector<Case> out;
  for (const auto& i : intr)
    for (const auto& p : poses)
      for (const auto& x : points) out.push_back({i, p, x});
  return out;
}

TEST(CameraModel, AnalyticJacobiansMatchJets) {
  using J = ceres::Jet<double, 18>;
  int index = 0;
  for (const Case& c : Grid()) {
    J in[9], pose[6], pt[3], uv[2];
    for (int i = 0; i < 9; ++i) in[i] = J(c.intrinsics[i], i);
    for (int i = 0; i < 6; ++i) pose[i] = J(c.pose[i], 9 + i);
    for (int i = 0; i < 3; ++i) pt[i] = J(c.point[i], 15 + i);
    ASSERT_TRUE(ProjectPoint(in, pose, pt, uv)) << "case " << index;
    double q[2], Ji[18], Jp[12], Jx[6];
    ASSERT_TRUE(ProjectPointWithJac(c.intrinsics.data(), c.pose.data(), c.point.data(), q, Ji, Jp,
                                    Jx));
    for (int r = 0; r < 2; ++r) {
      EXPECT_NEAR(q[r], uv[r].a, kJacTol * std::max(1.0, std::fabs(q[r]))) << "case " << index;
      for (int k = 0; k < 9; ++k) {
        const double jet = uv[r].v[k];
        EXPECT_NEAR(Ji[9 * r + k], jet, kJacTol * std::max(1.0, std::fabs(jet)))
            << "case " << index << " d uv[" << r << "]/d intrinsics[" << k << "]";
      }
      for (int k = 0; k < 6; ++k) {
        const double jet = uv[r].v[9 + k];
        EXPECT_NEAR(Jp[6 * r + k], jet, kJacTol * std::max(1.0, std::fabs(jet)))
            << "case " << index << " d uv[" << r << "]/d pose[" << k << "]";
      }
      for (int k = 0; k < 3; ++k) {
        const double jet = uv[r].v[15 + k];
        EXPECT_NEAR(Jx[3 * r + k], jet, kJacTol * std::max(1.0, std::fabs(jet)))
            << "case " << index << " d uv[" << r << "]/d point[" << k << "]";
      }
    }
    ++index;
  }
}

TEST(CameraModel, CameraPointJacobianMatchesJets) {
  using J = ceres::Jet<double, 3>;
  for (const Case& c : Grid()) {
    const double p[3] = {c.point[0] + 5, c.point[1] - 3, c.point[2] + 700};
    J pj[3] = {J(p[0], 0), J(p[1], 1), J(p[2], 2)}, in[9], uv[2];
    for (int i = 0; i < 9; ++i) in[i] = J(c.intrinsics[i]);
    ASSERT_TRUE(ProjectCamPoint(in, pj, uv));
    double q[2], Jpc[6];
    ASSERT_TRUE(ProjectCamPointWithJac(c.intrinsics.data(), p, q, nullptr, Jpc));
    for (int r = 0; r < 2; ++r)
      for (int k = 0; k < 3; ++k)
        EXPECT_NEAR(Jpc[3 * r + k], uv[r].v[k], kJacTol * std::max(1.0, std::fabs(uv[r].v[k])));
  }
}

TEST(CameraModel, GradientCheckerOnReprojectionResidual) {
  for (const Case& c : Grid()) {
    ReprojectionError cost(200.0, 210.0, 0.7);
    ceres::NumericDiffOptions nd;
    const std::vector<const ceres::Manifold*>* no_manifolds = nullptr;
    ceres::GradientChecker checker(&cost, no_manifolds, nd);
    const double* params[3] = {c.pose.data(), c.point.data(), c.intrinsics.data()};
    ceres::GradientChecker::ProbeResults results;
    checker.Probe(params, kFiniteDiffTol, &results);  // fills both Jacobians
    ASSERT_TRUE(results.return_value);
    ASSERT_EQ(results.jacobians.size(), 3u);
    for (int b = 0; b < 3; ++b) {
      const auto& Ja = results.jacobians[b];
      const auto& Jn = results.numeric_jacobians[b];
      for (int i = 0; i < Ja.rows(); ++i) {
        for (int k = 0; k < Ja.cols(); ++k) {
          EXPECT_NEAR(Ja(i, k), Jn(i, k), kFiniteDiffTol * std::max(1.0, std::fabs(Jn(i, k))))
              << "block " << b << " row " << i << " col " << k;
        }
      }
    }
  }
}

TEST(CameraModel, RejectsPointsBehindTheSource) {
  const double in[9] = {1000, 1000, 200, 200, 0, 0, 0, 0, 0};
  const double p[3] = {0, 0, -5};
  double uv[2];
  EXPECT_FALSE(ProjectCamPoint(in, p, uv));
  EXPECT_FALSE(ProjectCamPointWithJac(in, p, uv, nullptr, nullptr));
  ReprojectionError cost(0, 0, 1);
  const double pose[6] = {0, 0, 0, 0, 0, -10};
  const double pt[3] = {0, 0, 0};
  const double* params[3] = {pose, pt, in};
  double r[2];
  EXPECT_FALSE(cost.Evaluate(params, r, nullptr));
}

TEST(CameraModel, ProjectionMatchesOpenCvAndMrcal) {
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> u(-1, 1);
  mrcal_lensmodel_t model;
  model.type = MRCAL_LENSMODEL_OPENCV5;
  for (const Case& c : Grid()) {
    std::vector<cv::Point3d> obj;
    std::vector<mrcal_point3_t> cam_pts;
    std::vector<Eigen::Vector2d> ours;
    for (int i = 0; i < 50; ++i) {
      const double x[3] = {60 * u(rng), 60 * u(rng), 60 * u(rng)};
      obj.emplace_back(x[0], x[1], x[2]);
      double pc[3];
      ceres::AngleAxisRotatePoint(c.pose.data(), x, pc);
      mrcal_point3_t m;
      m.x = pc[0] + c.pose[3], m.y = pc[1] + c.pose[4], m.z = pc[2] + c.pose[5];
      cam_pts.push_back(m);
      Eigen::Vector2d q;
      ASSERT_TRUE(ProjectPoint(c.intrinsics.data(), c.pose.data(), x, q.data()));
      ours.push_back(q);
    }
    const cv::Matx33d K(c.intrinsics[0], 0, c.intrinsics[2], 0, c.intrinsics[1], c.intrinsics[3],
                        0, 0, 1);
    const cv::Vec<double, 5> dist(c.intrinsics[4], c.intrinsics[5], c.intrinsics[6],
                                  c.intrinsics[7], c.intrinsics[8]);
    std::vector<cv::Point2d> cvq;
    cv::projectPoints(obj, cv::Vec3d(c.pose[0], c.pose[1], c.pose[2]),
                      cv::Vec3d(c.pose[3], c.pose[4], c.pose[5]), K, dist, cvq);
    std::vector<mrcal_point2_t> mq(cam_pts.size());
    ASSERT_TRUE(mrcal_project(mq.data(), nullptr, nullptr, cam_pts.data(),
                              static_cast<int>(cam_pts.size()), &model, c.intrinsics.data()));
    for (size_t i = 0; i < ours.size(); ++i) {
      EXPECT_NEAR(ours[i].x(), cvq[i].x, kProjTolPx);
      EXPECT_NEAR(ours[i].y(), cvq[i].y, kProjTolPx);
      EXPECT_NEAR(ours[i].x(), mq[i].x, kProjTolPx);
      EXPECT_NEAR(ours[i].y(), mq[i].y, kProjTolPx);
    }
  }
}

TEST(CameraModel, UnprojectInvertsProjection) {
  const double in[9] = {2061.389, 2254.646, 203.655, 205.117, -0.25, 0.12, 1e-3, -2e-3, -0.03};
  for (double x = -0.1; x <= 0.1; x += 0.02) {
    for (double y = -0.1; y <= 0.1; y += 0.02) {
      const double p[3] = {x, y, 1};
      double uv[2], xy[2];
      ASSERT_TRUE(ProjectCamPoint(in, p, uv));
      ASSERT_TRUE(UnprojectToNormalized(in, uv, xy));
      EXPECT_NEAR(xy[0], x, 1e-12);
      EXPECT_NEAR(xy[1], y, 1e-12);
    }
  }
}

// The CT prior, as the two 2-row blocks the pose problem hands to Ceres: whitened by the CT
// covariance (squared norm = Mahalanobis distance), information J^T J = C^-1, gradient C^-1 d.
TEST(PointPrior, SplitIntoTwoRowBlocksIsTheSamePrior) {
  Eigen::Matrix3d C;
  C << 0.09, 0.01, 0, 0.01, 0.04, 0.005, 0, 0.005, 0.25;
  const Eigen::Vector3d m(1, 2, 3), p(1.3, 1.9, 3.5);
  Eigen::Matrix3d S;
  EXPECT_FALSE(SqrtInformation(-C, &S));
  ASSERT_TRUE(SqrtInformation(C, &S));
  const auto [a, b] = PointPriorRows::Split(m, S);
  std::unique_ptr<PointPriorRows> ua(a), ub(b);
  const double* params[1] = {p.data()};
  double chi2 = 0;
  Eigen::Matrix3d info = Eigen::Matrix3d::Zero();
  Eigen::Vector3d grad = Eigen::Vector3d::Zero();
  for (const PointPriorRows* block : {a, b}) {
    Eigen::Vector2d r;
    Eigen::Matrix<double, 2, 3, Eigen::RowMajor> J;
    double* jac[1] = {J.data()};
    ASSERT_TRUE(block->Evaluate(params, r.data(), jac));
    chi2 += r.squaredNorm();
    info += J.transpose() * J;
    grad += J.transpose() * r;
  }
  const Eigen::Vector3d d = p - m;
  EXPECT_NEAR(chi2, d.dot(C.inverse() * d), 1e-12);
  EXPECT_LT((info - C.inverse()).norm(), 1e-9);
  EXPECT_LT((grad - C.inverse() * d).norm(), 1e-9);
}

}  // namespace
}  // namespace carmba
