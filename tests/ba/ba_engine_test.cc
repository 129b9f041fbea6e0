// The bundle-adjustment engine (src/ba/): prior Jacobians against their autodiff twins, the Schur
// covariance against ceres::Covariance, gauge and rank messages, the error budget's additivity,
// analytic and autodiff solves reaching the same optimum, bad problems.
#include <gtest/gtest.h>

#include <algorithm>

#include <ceres/ceres.h>

#include <functional>
#include <memory>
#include <random>

#include "ba/bundle_adjuster.h"
#include "ba/priors.h"
#include "ba/quantities.h"
#include "ba/reprojection_error.h"
#include "camera/camera_model.h"
#include "geometry/rotation.h"
#include "synthetic/synthetic_joint.h"

namespace carmba {
namespace ba {
namespace {

// Analytic and autodiff derivatives of the same expression agree to rounding.
constexpr double kJacTol = 1e-10;
// ceres::Covariance (dense SVD of the whole Jacobian) and the Schur complement differ by the
// rounding of two different factorisations of a matrix with condition ~1e8.
constexpr double kCovTol = 1e-8;

// Every element within kCovTol of the reference, relative to sqrt(C_ii C_jj).
void ExpectCovarianceEqual(const Eigen::MatrixXd& schur, const Eigen::MatrixXd& ref) {
  ASSERT_EQ(schur.rows(), ref.rows());
  for (int i = 0; i < schur.rows(); ++i) {
    for (int j = 0; j < schur.cols(); ++j) {
      const double scale = std::sqrt(std::abs(ref(i, i) * ref(j, j)));
      ASSERT_NEAR(schur(i, j), ref(i, j), kCovTol * scale + 1e-300) << i << "," << j;
    }
  }
}

SyntheticJointSpec SmallSpec() {
  SyntheticJointSpec s;
  s.num_plate_views = 5;
  s.object_angles_deg = {0, 30, 90};
  return s;
}

TEST(BaPriors, IntrinsicsPriorAnalyticEqualsAutodiff) {
  const double mean[9] = {2000, 2010, 205, 200, 0.1, 0.01, 0.001, -0.002, 0.0};
  const std::vector<int> idx = {kFx, kCx, kK1};
  Eigen::MatrixXd C(3, 3);
  C << 25, 1, 0.01, 1, 4, 0.002, 0.01, 0.002, 1e-4;
  Eigen::MatrixXd S;
  ASSERT_TRUE(SqrtInformationN(C, &S));
  EXPECT_LT((S.transpose() * S - C.inverse()).norm(), 1e-9 * C.inverse().norm());
  IntrinsicsPriorError analytic(mean, idx, S);
  std::unique_ptr<ceres::CostFunction> autodiff(IntrinsicsPriorAutoDiff::Create(mean, idx, S));
  const double x[9] = {2003, 2009, 201, 199, 0.12, 0.0, 0.0, 0.0, 0.001};
  const double* params[1] = {x};
  double r1[3], r2[3], J1[27], J2[27];
  double* j1[1] = {J1};
  double* j2[1] = {J2};
  ASSERT_TRUE(analytic.Evaluate(params, r1, j1));
  ASSERT_TRUE(autodiff->Evaluate(params, r2, j2));
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(r1[i], r2[i], kJacTol) << i;
  for (int i = 0; i < 27; ++i) EXPECT_NEAR(J1[i], J2[i], kJacTol) << "index " << i;
  // |r|^2 is the Mahalanobis distance of the prior.
  Eigen::Vector3d d(3, -4, 0.02);
  EXPECT_NEAR(Eigen::Vector3d(r1[0], r1[1], r1[2]).squaredNorm(), d.dot(C.inverse() * d), 1e-9);
}

// The per-view plate block is the stacked per-point ReprojectionError (their residuals and
// Jacobians to the last bits), so the engine may use either.
TEST(BaPriors, PlateViewReprojectionIsStackedPointBlocks) {
  const double pose[6] = {0.2, -0.1, 0.05, 3, -4, 700};
  const double intr[9] = {2000, 2010, 205, 200, 0.08, -0.2, 1e-4, -2e-4, 0.1};
  std::vector<Eigen::Vector3d> p = {{0, 0, 0}, {20, 0, 0}, {0, 20, 0}, {40, 60, 0}};
  std::vector<Eigen::Vector2d> uv = {{200, 190}, {260, 201}, {207, 255}, {330, 370}};
  const double sigma = 0.07;
  PlateViewReprojection view(p, uv, sigma);
  const double* params[2] = {pose, intr};
  Eigen::Matrix<double, 8, 1> r;
  Eigen::Matrix<double, 8, 6, Eigen::RowMajor> Jp;
  Eigen::Matrix<double, 8, 9, Eigen::RowMajor> Ji;
  double* jac[2] = {Jp.data(), Ji.data()};
  ASSERT_TRUE(view.Evaluate(params, r.data(), jac));
  for (size_t i = 0; i < p.size(); ++i) {
    std::unique_ptr<ceres::CostFunction> one(
        ReprojectionError::Create(uv[i].x(), uv[i].y(), sigma));
    const double* pp[3] = {pose, p[i].data(), intr};
    double ri[2], jp[12], jpt[6], ji[18];
    double* jj[3] = {jp, jpt, ji};
    ASSERT_TRUE(one->Evaluate(pp, ri, jj));
    for (int k = 0; k < 2; ++k) {
      EXPECT_EQ(r(2 * i + k), ri[k]);
      for (int c = 0; c < 6; ++c) EXPECT_EQ(Jp(2 * i + k, c), jp[6 * k + c]);
      for (int c = 0; c < 9; ++c) EXPECT_EQ(Ji(2 * i + k, c), ji[9 * k + c]);
    }
  }
  // A point behind the source is refused, as the per-point block refuses it.
  const double behind[6] = {0, 0, 0, 0, 0, -700};
  const double* bad[2] = {behind, intr};
  EXPECT_FALSE(view.Evaluate(bad, r.data(), nullptr));
}

TEST(BaPriors, PointPriorRowsAnalyticEqualsAutodiff) {
  Eigen::Matrix<double, 2, 3> A;
  A << 2, 0.1, -0.3, 0, 4, 0.5;
  const Eigen::Vector3d p0(1, 2, 3);
  PointPriorRows analytic(p0, A);
  std::unique_ptr<ceres::CostFunction> autodiff(PointPriorRowsAutoDiff::Create(p0, A));
  const double x[3] = {1.5, 1.0, 3.2};
  const double* params[1] = {x};
  double r1[2], r2[2], J1[6], J2[6];
  double* j1[1] = {J1};
  double* j2[1] = {J2};
  ASSERT_TRUE(analytic.Evaluate(params, r1, j1));
  ASSERT_TRUE(autodiff->Evaluate(params, r2, j2));
  for (int i = 0; i < 2; ++i) EXPECT_NEAR(r1[i], r2[i], kJacTol);
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(J1[i], J2[i], kJacTol) << "index " << i;
}

TEST(BaLayout, NamesEveryParameter) {
  auto sj = MakeSyntheticJoint(SmallSpec(), NoiseSwitches(), 1);
  StateLayout L(sj.problem);
  // 6 free intrinsics + 8 poses + 9 markers (plate points held).
  EXPECT_EQ(L.num_free(), 6 + 6 * 8 + 3 * 9);
  EXPECT_EQ(L.FreeName(0), "fx");
  EXPECT_EQ(L.FreeName(5), "k2");
  EXPECT_EQ(L.FreeName(6), "plate p00 rx");
  EXPECT_EQ(L.FreeName(6 + 6 * 5 + 2), "view +000 rz");
  EXPECT_EQ(L.FreeName(L.num_free() - 1), "marker 9 z");
}

// Solves the small joint problem with everything that makes the covariance non-trivial: free
// plate points with their prior, an intrinsics prior, a Huber loss that is active.
struct Solved {
  SyntheticJoint sj;
  BaOptions options;
  BaResult result;
};

Solved SolveSmall(Loss loss, bool analytic) {
  SyntheticJointSpec spec = SmallSpec();
  spec.plate_free = true;
  spec.sigma_plate_mm = 0.02;
  spec.intrinsics_prior = true;
  Solved s{MakeSyntheticJoint(spec, NoiseSwitches(), 7), BaOptions(), BaResult()};
  s.options.loss = loss;
  s.options.loss_scale_px = 0.06;  // ~1 plate sigma: the loss is active on many points
  s.options.analytic_jacobians = analytic;
  auto r = SolveBundleAdjustment(s.sj.problem, s.options);
  EXPECT_TRUE(r.ok()) << r.status().message();
  if (r.ok()) s.result = *r;
  return s;
}

TEST(BaCovariance, SchurEqualsCeresCovariance) {
  for (const Loss loss : {Loss::kTrivial, Loss::kHuber, Loss::kCauchy}) {
    SCOPED_TRACE(NameOf(kLossNames, loss));
    Solved s = SolveSmall(loss, true);
    ASSERT_TRUE(s.result.covariance);
    const StateLayout& L = *s.result.layout;
    EXPECT_EQ(s.result.covariance->num_eliminated_blocks(), 9 + 25);  // markers, plate points
    // Intrinsics, two object poses, a plate pose, a marker, a plate point: blocks and cross-blocks.
    const std::vector<int> blocks = {L.group_block(0), L.view_block(5), L.view_block(7),
                                     L.view_block(0), L.marker_block(3), L.plate_point_block(12)};
    const Eigen::MatrixXd schur = s.result.Covariance(blocks);
    auto ceres_cov = CeresBlockCovariance(
        s.sj.problem, s.options, s.result, blocks, CovarianceAlgorithm::kDenseSvd);
    ASSERT_TRUE(ceres_cov.ok()) << ceres_cov.status().message();
    ASSERT_EQ(schur.rows(), ceres_cov->rows());
    for (int i = 0; i < schur.rows(); ++i) {
      for (int j = 0; j < schur.cols(); ++j) {
        const double ref = (*ceres_cov)(i, j);
        const double scale = std::sqrt(std::abs((*ceres_cov)(i, i) * (*ceres_cov)(j, j)));
        ASSERT_NEAR(schur(i, j), ref, kCovTol * scale + 1e-300)
            << "entry (" << i << ", " << j << ")";
      }
    }
  }
}

// The typed getters (BaResult::ViewPose, GroupIntrinsics, MarkerPosition and their covariances)
// read the blocks they name: each value lies within 5 sigma of the truth of that view, group or
// marker (a neighbour's block would be far off), and the joint covariance of two views equals
// ceres::Covariance of the two pose blocks, cross-covariance included.
TEST(BaResultAccess, TypedGettersReadTheBlocksTheyName) {
  Solved s = SolveSmall(Loss::kTrivial, true);
  ASSERT_TRUE(s.result.covariance);
  const BaResult& r = s.result;
  for (int v = 0; v < static_cast<int>(s.sj.true_poses.size()); ++v) {
    const Pose6 d = r.ViewPose(v) - s.sj.true_poses[v];
    EXPECT_LT(d.dot(r.ViewPoseCovariance(v).ldlt().solve(d)), 25.0 * 6) << "view " << v;
  }
  for (int m = 0; m < static_cast<int>(s.sj.true_markers.size()); ++m) {
    const Eigen::Vector3d d = r.MarkerPosition(m) - s.sj.true_markers[m];
    EXPECT_LT(d.dot(r.MarkerCovariance(m).ldlt().solve(d)), 25.0 * 3) << "marker " << m;
  }
  const std::array<double, kNumIntrinsics> K = r.GroupIntrinsics(0);
  const Eigen::MatrixXd CK = r.GroupIntrinsicsCovariance(0);
  for (int i : {kFx, kFy, kCx, kCy}) {
    EXPECT_LT(std::abs(K[i] - s.sj.true_intrinsics[i]), 5 * std::sqrt(CK(i, i))) << i;
  }
  const Eigen::MatrixXd C = r.ViewPosesCovariance({7, 5});
  auto ref = CeresBlockCovariance(
      s.sj.problem, s.options, r, r.ViewBlocks({7, 5}), CovarianceAlgorithm::kDenseSvd);
  ASSERT_TRUE(ref.ok()) << ref.status().message();
  ExpectCovarianceEqual(C, *ref);
  EXPECT_GT(C.topRightCorner(6, 6).norm(), 0);  // the cross-covariance is there
  // Typed access to the same blocks: Cross(a, b) is the joint covariance's off-diagonal block,
  // its transpose is Cross(b, a), and Cross(a, a) is the view's own.
  EXPECT_EQ((r.ViewPoseCross(7, 5) - C.topRightCorner(6, 6)).norm(), 0);
  EXPECT_LE((r.ViewPoseCross(5, 7) - C.topRightCorner(6, 6).transpose()).norm(), 1e-12 * C.norm());
  EXPECT_EQ((r.ViewPoseCross(5, 5) - r.ViewPoseCovariance(5)).norm(), 0);
  const int marker0 = r.layout->marker_block(0);
  EXPECT_EQ(r.Cross(marker0, r.layout->view_block(5)).rows(), 3);
  EXPECT_EQ(r.Cross(marker0, r.layout->view_block(5)).cols(), 6);
}

TEST(BaCovariance, CalibrationOnlyEliminatesPlatePoses) {
  SyntheticJointSpec spec = SmallSpec();
  spec.object_angles_deg.clear();
  auto sj = MakeSyntheticJoint(spec, NoiseSwitches(), 3);
  sj.problem.markers.clear();
  BaOptions o;
  auto r = SolveBundleAdjustment(sj.problem, o);
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_EQ(r->covariance->kept_size(), 6);  // the free intrinsics only
  const std::vector<int> blocks = {r->layout->group_block(0), r->layout->view_block(2)};
  const Eigen::MatrixXd schur = r->Covariance(blocks);
  auto ref = CeresBlockCovariance(sj.problem, o, *r, blocks, CovarianceAlgorithm::kDenseSvd);
  ASSERT_TRUE(ref.ok()) << ref.status().message();
  ExpectCovarianceEqual(schur, *ref);
}

// A fixed aspect ratio fy = r fx (IntrinsicsGroup::fy_over_fx): one free parameter for both, the
// ratio kept by the solve on both back ends, the covariance equal to ceres::Covariance through the
// affine manifold (fy's rows r times fx's), fy named in the budget.
TEST(BaCovariance, TiedAspectRatioEqualsCeresCovariance) {
  SyntheticJointSpec spec = SmallSpec();
  spec.object_angles_deg.clear();
  auto sj = MakeSyntheticJoint(spec, NoiseSwitches(), 4);
  sj.problem.markers.clear();
  IntrinsicsGroup& g = sj.problem.groups[0];
  const double ratio = 1.004;
  g.fy_over_fx = ratio;
  g.initial[kFx] *= 1.01;
  g.initial[kFy] = ratio * g.initial[kFx];
  const StateLayout layout(sj.problem);
  const BlockInfo& gi = layout.block(layout.group_block(0));
  EXPECT_FALSE(gi.selection);
  EXPECT_EQ(std::count(gi.free.begin(), gi.free.end(), kFy), 0);
  BaOptions o, lm;
  lm.backend = Backend::kCarmbaLm;
  auto r = SolveBundleAdjustment(sj.problem, o);
  auto rl = SolveBundleAdjustment(sj.problem, lm);
  ASSERT_TRUE(r.ok()) << r.status().message();
  ASSERT_TRUE(rl.ok()) << rl.status().message();
  EXPECT_NEAR(r->state[kFy], ratio * r->state[kFx], 1e-9 * r->state[kFy]);
  EXPECT_NEAR(rl->state[kFy], ratio * rl->state[kFx], 1e-9 * rl->state[kFy]);
  EXPECT_NEAR(r->chi2, rl->chi2, 1e-8 * r->chi2);
  const std::vector<int> blocks = {r->layout->group_block(0), r->layout->view_block(1)};
  const Eigen::MatrixXd schur = r->Covariance(blocks);
  auto ref = CeresBlockCovariance(sj.problem, o, *r, blocks, CovarianceAlgorithm::kDenseSvd);
  ASSERT_TRUE(ref.ok()) << ref.status().message();
  ExpectCovarianceEqual(schur, *ref);
  EXPECT_NEAR(schur(kFy, kFy), ratio * ratio * schur(kFx, kFx), 1e-9 * schur(kFy, kFy));
  EXPECT_NEAR(schur(kFx, kFy), ratio * schur(kFx, kFx), 1e-9 * schur(kFy, kFy));
  const auto budget = ComputeErrorBudget(sj.problem, *r, {});
  bool fy_listed = false;
  for (const auto& row : budget) {
    if (row.quantity.name == "fy") {
      fy_listed = true;
      EXPECT_NEAR(row.sigma, std::sqrt(schur(kFy, kFy)), 1e-9 * row.sigma);
    }
  }
  EXPECT_TRUE(fy_listed);
  // Initial values off the ratio are refused.
  g.initial[kFy] *= 1.001;
  auto bad = SolveBundleAdjustment(sj.problem, o);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("fy_over_fx"), std::string::npos) << bad.status().message();
}

TEST(BaSolve, AnalyticAndAutodiffReachTheSameOptimum) {
  Solved a = SolveSmall(Loss::kHuber, true);
  Solved b = SolveSmall(Loss::kHuber, false);
  ASSERT_EQ(a.result.state.size(), b.result.state.size());
  EXPECT_NEAR(a.result.chi2, b.result.chi2, 1e-9 * a.result.chi2);
  const Eigen::MatrixXd ca = a.result.Covariance({a.result.layout->group_block(0)});
  const Eigen::MatrixXd cb = b.result.Covariance({b.result.layout->group_block(0)});
  for (int i = 0; i < 9; ++i) {
    const double sigma = std::sqrt(std::max(ca(i, i), 1e-300));
    EXPECT_NEAR(a.result.state[i], b.result.state[i], 1e-6 * sigma + 1e-12) << i;
  }
  EXPECT_LT((ca - cb).norm(), 1e-6 * ca.norm());
}

// A solve started at the truth (a Monte Carlo trial) with a Gauss-Newton-sized first trust region
// reaches the optimum of the default start in fewer iterations; a radius that is not positive and
// finite is refused by name.
TEST(BaSolve, NearOptimumTrustRegionReachesTheSameOptimumInFewerIterations) {
  const SyntheticJoint sj = MakeSyntheticJoint(SmallSpec(), NoiseSwitches(), 3);
  BaOptions cold, near;
  near.initial_trust_region_radius = kNearOptimumTrustRegionRadius;
  auto a = SolveBundleAdjustment(sj.problem, cold);
  auto b = SolveBundleAdjustment(sj.problem, near);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_LT(b->iterations, a->iterations);
  EXPECT_NEAR(a->chi2, b->chi2, 1e-9 * a->chi2);
  const Eigen::MatrixXd C = a->Covariance({a->layout->group_block(0)});
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(a->state[i], b->state[i], 1e-4 * std::sqrt(C(i, i))) << i;
  }
  for (double bad : {0.0, -1.0, std::nan(""), HUGE_VAL}) {
    BaOptions o;
    o.initial_trust_region_radius = bad;
    auto r = SolveBundleAdjustment(sj.problem, o);
    ASSERT_FALSE(r.ok()) << bad;
    EXPECT_NE(r.status().message().find("initial_trust_region_radius"), std::string::npos)
        << r.status().message();
  }
}

TEST(BaBudget, SharesAddUpToTheTotal) {
  Solved s = SolveSmall(Loss::kTrivial, true);
  const auto rows = ComputeErrorBudget(s.sj.problem, s.result, s.sj.pairs);
  ASSERT_FALSE(rows.empty());
  const QuantitySet qs = DerivedQuantities(s.sj.problem, s.result, s.sj.pairs);
  ASSERT_EQ(rows.size(), qs.quantities.size());
  // 6 intrinsics + 2 centre projections + 3 views x 6 + 2 pairs x 2.
  EXPECT_EQ(rows.size(), 6u + 2u + 18u + 4u);
  const Eigen::MatrixXd cov_all = s.result.covariance->Solve(qs.G.transpose());
  for (size_t q = 0; q < rows.size(); ++q) {
    double sum = 0;
    for (double sh : rows[q].share) sum += sh;
    EXPECT_NEAR(sum, 1.0, 1e-9) << rows[q].quantity.name;
    // sigma is G H^-1 G^T.
    EXPECT_NEAR(rows[q].sigma * rows[q].sigma, (qs.G.row(q) * cov_all.col(q))(0),
                1e-9 * rows[q].sigma * rows[q].sigma) << rows[q].quantity.name;
    for (int src = 0; src < kNumSources; ++src) EXPECT_GE(rows[q].share[src], 0.0);
  }
  // Every residual source contributes to the relative rotations here (all five are present; no
  // considered calibration: the intrinsics are estimated).
  const BudgetRow& pair = rows[rows.size() - 4];
  EXPECT_NE(pair.quantity.name.find("relative rotation"), std::string::npos);
  for (int src = 0; src < kNumResidualSources; ++src) EXPECT_GT(pair.share[src], 0.0) << src;
  EXPECT_EQ(pair.share[static_cast<int>(Source::kCalibration)], 0.0);
  // An intrinsic's sigma is its covariance's diagonal.
  const Eigen::MatrixXd ci = s.result.Covariance({s.result.layout->group_block(0)});
  EXPECT_NEAR(rows[0].sigma, std::sqrt(ci(0, 0)), 1e-9 * rows[0].sigma);
}

TEST(BaGauge, MarkersFreeWithoutPriorsNameTheNullDirection) {
  SyntheticJointSpec spec = SmallSpec();
  auto sj = MakeSyntheticJoint(spec, NoiseSwitches(), 5);
  sj.problem.marker_priors = false;
  auto r = SolveBundleAdjustment(sj.problem, BaOptions());
  ASSERT_FALSE(r.ok());
  const std::string& m = r.status().message();
  EXPECT_NE(m.find("rank-deficient"), std::string::npos) << m;
  EXPECT_NE(m.find("gauge"), std::string::npos) << m;
  EXPECT_NE(m.find("marker"), std::string::npos) << m;
  EXPECT_NE(m.find("view"), std::string::npos) << m;
}

TEST(BaGauge, PlatePointsFreeWithoutPriorNameTheNullDirection) {
  auto sj = MakeSyntheticJoint(SmallSpec(), NoiseSwitches(), 5);
  sj.problem.plate.free = true;
  sj.problem.plate.sigma_mm = 0;  // no manufacturing prior
  auto r = SolveBundleAdjustment(sj.problem, BaOptions());
  ASSERT_FALSE(r.ok());
  const std::string& m = r.status().message();
  EXPECT_NE(m.find("rank-deficient"), std::string::npos) << m;
  EXPECT_NE(m.find("plate"), std::string::npos) << m;
}

TEST(BaGauge, MarkerInOneViewWithoutPriorIsNamed) {
  SyntheticJointSpec spec = SmallSpec();
  auto sj = MakeSyntheticJoint(spec, NoiseSwitches(), 5);
  sj.problem.marker_priors = false;
  // Marker 4 seen only in the first object view.
  for (auto& v : sj.problem.views) {
    if (v.kind != ViewKind::kObject || v.id == "+000") continue;
    for (size_t i = 0; i < v.point_ids.size(); ++i) {
      if (v.point_ids[i] == 4) {
        v.point_ids.erase(v.point_ids.begin() + i);
        v.uv_px.erase(v.uv_px.begin() + i);
        break;
      }
    }
  }
  auto r = SolveBundleAdjustment(sj.problem, BaOptions());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("marker 4 x, marker 4 y, marker 4 z not determined"),
            std::string::npos)
      << r.status().message();
}

TEST(BaProblemCheck, BadProblemsAreOneLineErrors) {
  auto base = MakeSyntheticJoint(SmallSpec(), NoiseSwitches(), 5).problem;
  struct Case {
    std::string expect;
    std::function<void(BaProblem*)> corrupt;
  };
  const std::vector<Case> cases = {
      {"marker 42 is not among the fiducials",
       [](BaProblem* p) { p->views.back().point_ids[0] = 42; }},
      {"1 observation(s), at least 4 needed",
       [](BaProblem* p) {
         p->views.back().point_ids.resize(1);
         p->views.back().uv_px.resize(1);
       }},
      {"has no plate views and no prior",
       [](BaProblem* p) {
         IntrinsicsGroup g = p->groups[0];
         g.name = "lao90";
         p->groups.push_back(g);
         p->views.back().group = 1;
       }},
      {"is given twice", [](BaProblem* p) { p->views[1].id = p->views[0].id; }},
      {"plate point 99 is not on the plate",
       [](BaProblem* p) { p->views[0].point_ids[0] = 99; }},
      {"sigma_px must be > 0", [](BaProblem* p) { p->views[0].sigma_px = 0; }},
      {"non-finite pixel", [](BaProblem* p) { p->views[0].uv_px[2].x() = std::nan(""); }},
  };
  for (const auto& c : cases) {
    BaProblem p = base;
    c.corrupt(&p);
    auto r = SolveBundleAdjustment(p, BaOptions());
    ASSERT_FALSE(r.ok()) << c.expect;
    EXPECT_NE(r.status().message().find(c.expect), std::string::npos) << r.status().message();
    EXPECT_EQ(r.status().message().find('\n'), std::string::npos);
  }
}

TEST(BaOutliers, ListedAndRejected) {
  // 7 object views: a wrong pixel cannot hide in one marker's CT prior and one view's pose.
  auto sj = MakeSyntheticJoint(SyntheticJointSpec(), NoiseSwitches(), 11);
  // A gross error on marker 5 in the last object view.
  BaView& v = sj.problem.views.back();
  v.uv_px[4] += Eigen::Vector2d(8.0, -6.0);  // 50 sigma at 0.2 px
  BaOptions o;
  auto r = SolveBundleAdjustment(sj.problem, o);
  ASSERT_TRUE(r.ok()) << r.status().message();
  ASSERT_FALSE(r->outliers.empty());
  EXPECT_EQ(r->outliers[0].view, v.id);
  EXPECT_EQ(r->outliers[0].id, 5);
  EXPECT_GT(r->outliers[0].residual_sigma, 8.0);
  o.reject_sigma = 5.0;
  auto rr = SolveBundleAdjustment(sj.problem, o);
  ASSERT_TRUE(rr.ok()) << rr.status().message();
  ASSERT_EQ(rr->rejected.size(), 1u);
  EXPECT_EQ(rr->rejected[0].id, 5);
  EXPECT_TRUE(rr->outliers.empty());
  EXPECT_LT(rr->sigma0, 1.5);
}

// Every observation's residual at the solution is the engine's (BaResult::residuals): projection
// minus observation, as an independent re-projection of the solved state gives; the view RMS and
// the outlier listing agree with it; a rejected observation is NaN.
TEST(BaResiduals, PerObservationResidualsAreTheSolutionsReprojection) {
  auto sj = MakeSyntheticJoint(SyntheticJointSpec(), NoiseSwitches(), 11);
  const int last = static_cast<int>(sj.problem.views.size()) - 1;
  sj.problem.views[last].uv_px[4] += Eigen::Vector2d(8.0, -6.0);
  BaOptions o;
  auto r = SolveBundleAdjustment(sj.problem, o);
  ASSERT_TRUE(r.ok()) << r.status().message();
  ASSERT_EQ(r->residuals.size(), sj.problem.views.size());
  const BaObservationResidual& gross = r->residuals[last][4];
  EXPECT_DOUBLE_EQ(gross.du_px, r->outliers[0].du_px);
  EXPECT_DOUBLE_EQ(gross.sigma_norm, r->outliers[0].residual_sigma);
  const StateLayout& L = *r->layout;
  int plate_checked = 0;
  for (size_t v = 0; v < sj.problem.views.size(); ++v) {
    const BaView& view = sj.problem.views[v];
    ASSERT_EQ(r->residuals[v].size(), view.uv_px.size());
    double ss = 0;
    for (size_t j = 0; j < view.uv_px.size(); ++j) {
      const BaObservationResidual& e = r->residuals[v][j];
      ASSERT_TRUE(e.used());
      ss += e.du_px * e.du_px + e.dv_px * e.dv_px;
      if (view.kind != ViewKind::kPlate) continue;
      const Pose6 pose = r->ViewPose(static_cast<int>(v));
      const double* point = r->block(L.plate_point_block(view.point_ids[j]));
      const Eigen::Vector3d pc =
          RotationOf(pose.data()) * Eigen::Map<const Eigen::Vector3d>(point) + pose.tail<3>();
      double uv[2];
      ASSERT_TRUE(ProjectCamPoint(r->block(L.group_block(view.group)), pc.data(), uv));
      EXPECT_NEAR(e.du_px, uv[0] - view.uv_px[j].x(), 1e-9);
      EXPECT_NEAR(e.dv_px, uv[1] - view.uv_px[j].y(), 1e-9);
      ++plate_checked;
    }
    EXPECT_NEAR(r->views[v].rms_px, std::sqrt(ss / (2.0 * view.uv_px.size())), 1e-12);
  }
  EXPECT_GT(plate_checked, 100);
  o.reject_sigma = 5.0;
  auto rr = SolveBundleAdjustment(sj.problem, o);
  ASSERT_TRUE(rr.ok()) << rr.status().message();
  EXPECT_FALSE(rr->residuals[last][4].used());
  EXPECT_TRUE(rr->residuals[last][3].used());
}

// Each view's RMS at the initial values: started from a solution, it is that solution's RMS;
// started from the synthetic problem's perturbed initial values, it is larger.
TEST(BaResiduals, InitialViewRmsIsTheRmsAtTheInitialValues) {
  auto sj = MakeSyntheticJoint(SyntheticJointSpec(), NoiseSwitches(), 12);
  BaOptions o;
  o.shadow_correction = false;
  auto first = SolveBundleAdjustment(sj.problem, o);
  ASSERT_TRUE(first.ok()) << first.status().message();
  ASSERT_EQ(first->initial_view_rms_px.size(), sj.problem.views.size());
  BaProblem at_solution = sj.problem;
  const StateLayout& L = *first->layout;
  for (size_t g = 0; g < at_solution.groups.size(); ++g) {
    std::copy_n(first->block(L.group_block(static_cast<int>(g))), kNumIntrinsics,
                at_solution.groups[g].initial.begin());
  }
  for (size_t v = 0; v < at_solution.views.size(); ++v) {
    at_solution.views[v].initial = first->ViewPose(static_cast<int>(v));
  }
  for (size_t m = 0; m < at_solution.markers.size(); ++m) {
    at_solution.markers[m].p_ct =
        Eigen::Map<const Eigen::Vector3d>(first->block(L.marker_block(static_cast<int>(m))));
  }
  for (size_t p = 0; p < at_solution.plate.points.size(); ++p) {
    at_solution.plate.points[p] =
        Eigen::Map<const Eigen::Vector3d>(first->block(L.plate_point_block(static_cast<int>(p))));
  }
  auto second = SolveBundleAdjustment(at_solution, o);
  ASSERT_TRUE(second.ok()) << second.status().message();
  int larger = 0;
  for (size_t v = 0; v < sj.problem.views.size(); ++v) {
    EXPECT_NEAR(
        second->initial_view_rms_px[v], first->views[v].rms_px, 1e-6 * first->views[v].rms_px)
        << sj.problem.views[v].id;
    larger += first->initial_view_rms_px[v] > 1.01 * first->views[v].rms_px;
  }
  EXPECT_GT(larger, static_cast<int>(sj.problem.views.size()) / 2);
}

}  // namespace
}  // namespace ba
}  // namespace carmba

namespace carmba {
namespace ba {
namespace {

// carmba's own Levenberg-Marquardt as the engine's back end reaches Ceres's optimum on a
// calibration problem (plate views only), and refuses problems outside its structure.
TEST(BaBackend, CarmbaLmReachesTheCeresOptimum) {
  SyntheticJointSpec spec;
  spec.num_plate_views = 12;
  spec.object_angles_deg.clear();
  SyntheticJoint sj = MakeSyntheticJoint(spec, NoiseSwitches(), 21);
  sj.problem.markers.clear();
  // Start away from the optimum.
  sj.problem.groups[0].initial[kFx] *= 1.02;
  sj.problem.groups[0].initial[kCx] += 3;
  for (auto& v : sj.problem.views) v.initial[5] += 5;
  BaOptions ceres_options, lm_options;
  lm_options.backend = Backend::kCarmbaLm;
  auto a = SolveBundleAdjustment(sj.problem, ceres_options);
  auto b = SolveBundleAdjustment(sj.problem, lm_options);
  ASSERT_TRUE(a.ok()) << a.status().message();
  ASSERT_TRUE(b.ok()) << b.status().message();
  EXPECT_TRUE(b->converged()) << b->TerminationText();
  EXPECT_NEAR(a->chi2, b->chi2, 1e-8 * a->chi2);
  const Eigen::MatrixXd C = a->Covariance({a->layout->group_block(0)});
  for (int i = 0; i < kNumIntrinsics; ++i) {
    const double sigma = std::sqrt(std::max(C(i, i), 0.0));
    if (sigma == 0) continue;
    EXPECT_NEAR(a->state[i], b->state[i], 1e-4 * sigma) << "intrinsic " << i;
  }
  // Outside its structure: an object view.
  SyntheticJoint joint = MakeSyntheticJoint(SyntheticJointSpec(), NoiseSwitches(), 1);
  auto c = SolveBundleAdjustment(joint.problem, lm_options);
  ASSERT_FALSE(c.ok());
  EXPECT_NE(
      c.status().message().find("backend carmba_lm (calibration problems) needs plate views only"),
      std::string::npos)
      << c.status().message();
}

}  // namespace
}  // namespace ba
}  // namespace carmba
