// Considered calibration (Schmidt "consider" covariance of held intrinsics, ba/covariance.h) and
// full 2x2 whitening of pixel observations (ba/reprojection_error.h), on the engine:
//   * the 2x2-whitened reprojection's analytic Jacobians against ceres::Jet (1e-10) and central
//     differences (GradientChecker), |r|^2 = e^T Sigma^-1 e, isotropic sigma the special case;
//   * the consider sensitivity D = d x_f / d c against re-solves with the held intrinsics moved
//     (central differences), analytic and autodiff Jacobians alike;
//   * seeded Monte Carlo of pose problems whose held intrinsics come from a calibration with error
//     (drawn from that calibration's covariance) plus pixel and CT noise: NEES per dof of the
//     poses, a relative pose and a triangulated point with the consider term (the band
//     [0.8, 1.25]) and without it (too large: printed and required above the band);
//   * anisotropic blob covariances: pose NEES with the full 2x2 whitening against the isotropic
//     larger-eigenvalue bound.
// NEES of dimension d averaged over T trials and V views has a relative standard error of about
// sqrt(2 / (d T V)) at best (the views of one trial are correlated through the CT and the
// calibration, so the effective count is nearer T): 300 trials of a 6-dof pose give ~3.3 %.
#include <ceres/ceres.h>
#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <random>

#include "analysis/relative_pose.h"
#include "analysis/tre.h"
#include "analysis/triangulation.h"
#include "ba/bundle_adjuster.h"
#include "ba/quantities.h"
#include "ba/reprojection_error.h"
#include "figures.h"
#include "synthetic/synthetic_joint.h"
#include "synthetic_pixels.h"

namespace carmba {
namespace ba {
namespace {

constexpr double kConsiderJacTol = 1e-10;       // analytic vs ceres::Jet: the same arithmetic
constexpr double kFiniteDiffTol = 1e-6; // central differences: truncation + rounding ~1e-7 rel.
constexpr double kNeesLow = 0.8, kNeesHigh = 1.25;  // the band


TEST(PixelWhitening, FullCovarianceAnalyticEqualsJetsAndFiniteDifferences) {
  const double pose[6] = {0.2, -0.1, 0.05, 3, -4, 700};
  const double point[3] = {12, -30, 25};
  const double intr[9] = {2000, 2010, 205, 200, 0.08, -0.2, 1e-4, -2e-4, 0.1};
  const double* params[3] = {pose, point, intr};
  for (const Eigen::Matrix2d& C :
       {Eigen::Matrix2d((Eigen::Matrix2d() << 0.09, 0.05, 0.05, 0.04).finished()),
        Eigen::Matrix2d((Eigen::Matrix2d() << 0.5, -0.3, -0.3, 0.25).finished()),
        Eigen::Matrix2d((Eigen::Matrix2d() << 0.16, 0.0, 0.0, 0.16).finished())}) {
    PixelWhitening w;
    ASSERT_TRUE(PixelWhitening::FromCovariance(C, &w));
    ReprojectionError analytic(200, 190, w);
    std::unique_ptr<ceres::CostFunction> autodiff(ReprojectionErrorAutoDiff::Create(200, 190, w));
    double r1[2], r2[2], a[3][18], b[3][18];
    double* ja[3] = {a[0], a[1], a[2]};
    double* jb[3] = {b[0], b[1], b[2]};
    ASSERT_TRUE(analytic.Evaluate(params, r1, ja));
    ASSERT_TRUE(autodiff->Evaluate(params, r2, jb));
    const int sizes[3] = {6, 3, 9};
    for (int k = 0; k < 2; ++k) EXPECT_NEAR(r1[k], r2[k], kConsiderJacTol);
    for (int blk = 0; blk < 3; ++blk) {
      for (int i = 0; i < 2 * sizes[blk]; ++i) {
        EXPECT_NEAR(a[blk][i], b[blk][i], kConsiderJacTol * std::max(1.0, std::abs(b[blk][i])))
            << "block " << blk << " index " << i;
      }
    }
    // |r|^2 is the Mahalanobis distance of the pixel error; L^-1 undone gives the pixel error.
    double uv[2];
    ASSERT_TRUE(ProjectPoint(intr, pose, point, uv));
    const Eigen::Vector2d e(uv[0] - 200, uv[1] - 190), r(r1[0], r1[1]);
    EXPECT_NEAR(r.squaredNorm(), e.dot(C.inverse() * e), 1e-9 * e.dot(C.inverse() * e));
    EXPECT_LT((w.Unwhiten(r) - e).norm(), 1e-9 * e.norm());
    // Central differences over the whole cost (a looser tolerance: finite differences).
    ceres::NumericDiffOptions nd;
    const std::vector<const ceres::Manifold*>* no_manifolds = nullptr;
    ceres::GradientChecker checker(&analytic, no_manifolds, nd);
    ceres::GradientChecker::ProbeResults res;
    checker.Probe(params, kFiniteDiffTol, &res);
    ASSERT_TRUE(res.return_value);
    for (int blk = 0; blk < 3; ++blk) {
      const auto& Ja = res.jacobians[blk];
      const auto& Jn = res.numeric_jacobians[blk];
      for (int i = 0; i < Ja.rows(); ++i) {
        for (int k = 0; k < Ja.cols(); ++k) {
          EXPECT_NEAR(Ja(i, k), Jn(i, k), kFiniteDiffTol * std::max(1.0, std::abs(Jn(i, k))))
              << "block " << blk << " row " << i << " col " << k;
        }
      }
    }
  }
  // Isotropic sigma is the special case, to the last bit.
  PixelWhitening iso;
  ASSERT_TRUE(PixelWhitening::FromCovariance(0.49 * Eigen::Matrix2d::Identity(), &iso));
  ReprojectionError by_sigma(200, 190, 0.7), by_cov(200, 190, iso);
  double r1[2], r2[2], a[3][18], b[3][18];
  double* ja[3] = {a[0], a[1], a[2]};
  double* jb[3] = {b[0], b[1], b[2]};
  ASSERT_TRUE(by_sigma.Evaluate(params, r1, ja));
  ASSERT_TRUE(by_cov.Evaluate(params, r2, jb));
  for (int k = 0; k < 2; ++k) EXPECT_NEAR(r1[k], r2[k], 1e-15 * std::abs(r1[k]));
  for (int i = 0; i < 18; ++i) EXPECT_NEAR(a[2][i], b[2][i], 1e-15 * std::abs(a[2][i]));
  // Not positive definite: refused.
  EXPECT_FALSE(PixelWhitening::FromCovariance((Eigen::Matrix2d() << 1, 2, 2, 1).finished(), &iso));
}

// A calibration's covariance of (fx, fy, cx, cy, k1, k2): the synthetic joint problem's plate
// part (`plate_views` plate views, 0.05 px), solved at the truth.
Eigen::MatrixXd CalibrationCovariance(int plate_views, std::vector<int>* indices) {
  SyntheticJointSpec cal;
  cal.num_plate_views = plate_views;
  NoiseSwitches none{false, false, false, false, false, false};
  const SyntheticJoint sj = MakeSyntheticJoint(cal, none, 1);
  auto r = SolveBundleAdjustment(sj.problem, BaOptions());
  EXPECT_TRUE(r.ok()) << r.status().message();
  const Eigen::MatrixXd C9 = r->Covariance({r->layout->group_block(0)});
  *indices = {kFx, kFy, kCx, kCy, kK1, kK2};
  Eigen::MatrixXd C(6, 6);
  for (int i = 0; i < 6; ++i) {
    for (int j = 0; j < 6; ++j) C(i, j) = C9((*indices)[i], (*indices)[j]);
  }
  return C;
}

// The pose problem: the synthetic object views only, the intrinsics held at a calibration's values
// and considered with its covariance.
SyntheticJointSpec PoseSpec(int plate_views) {
  SyntheticJointSpec s;
  s.num_plate_views = 0;
  s.free.fill(false);
  s.consider_covariance = CalibrationCovariance(plate_views, &s.consider_indices);
  return s;
}

TEST(Consider, SensitivityMatchesResolvesWithTheHeldIntrinsicsMoved) {
  const SyntheticJointSpec spec = PoseSpec(5);
  for (const bool analytic : {true, false}) {
    BaOptions o;
    o.analytic_jacobians = analytic;
    // Noise-free data: the Gauss-Newton H is then the exact Hessian (with residuals the
    // curvature term sum r d2r differs by ~1e-3 relative here), so D is exact to first order.
    const SyntheticJoint sj =
        MakeSyntheticJoint(spec, NoiseSwitches{false, false, false, false, false, false}, 3);
    auto r0 = SolveBundleAdjustment(sj.problem, o);
    ASSERT_TRUE(r0.ok()) << r0.status().message();
    const Eigen::MatrixXd& D = r0->covariance->consider_sensitivity();
    ASSERT_EQ(D.cols(), 6);
    ASSERT_EQ(D.rows(), r0->layout->num_free());
    double worst = 0;
    for (int k = 0; k < 6; ++k) {
      // A step of 1e-3 sigma: the response is linear to ~1e-6 relative there.
      const double h = 1e-3 * std::sqrt(spec.consider_covariance(k, k));
      Eigen::VectorXd x[2];
      for (int s = 0; s < 2; ++s) {
        BaProblem p = sj.problem;
        p.groups[0].initial[spec.consider_indices[k]] += (s ? -h : h);
        for (size_t v = 0; v < p.views.size(); ++v) {
          p.views[v].initial =
              Eigen::Map<const Pose6>(r0->block(r0->layout->view_block(static_cast<int>(v))));
        }
        BaOptions q = o;
        q.compute_covariance = false;
        auto r = SolveBundleAdjustment(p, q);
        ASSERT_TRUE(r.ok()) << r.status().message();
        x[s].resize(r->layout->num_free());
        for (int f = 0; f < r->layout->num_free(); ++f) {
          const auto [b, i] = r->layout->FreeIndex(f);
          x[s][f] = r->block(b)[i];
        }
      }
      const Eigen::VectorXd num = (x[0] - x[1]) / (2 * h);
      worst = std::max(worst, (num - D.col(k)).norm() / D.col(k).norm());
    }
    std::printf("consider sensitivity D (%s Jacobians) vs re-solves: worst column relative "
                "difference %.2e\n", analytic ? "analytic" : "autodiff", worst);
    EXPECT_LT(worst, 1e-4);  // measured 1.5e-5: the re-solves' own nonlinearity
  }
}

TEST(Consider, BudgetSplitsTheCalibrationShare) {
  const SyntheticJointSpec spec = PoseSpec(5);
  const SyntheticJoint sj = MakeSyntheticJoint(spec, NoiseSwitches(), 4);
  auto r = SolveBundleAdjustment(sj.problem, BaOptions());
  ASSERT_TRUE(r.ok()) << r.status().message();
  const auto rows = ComputeErrorBudget(sj.problem, *r, sj.pairs);
  const QuantitySet qs = DerivedQuantities(sj.problem, *r, sj.pairs);
  int checked = 0;
  for (size_t q = 0; q < rows.size(); ++q) {
    double sum = 0;
    for (double sh : rows[q].share) sum += sh;
    if (rows[q].sigma > 0) {
      EXPECT_NEAR(sum, 1.0, 1e-9) << rows[q].quantity.name;
    }
    // A pose's variance is the diagonal of Covariance (both parts), its calibration share the
    // diagonal of CalibrationCovariance.
    const std::string& n = rows[q].quantity.name;
    for (size_t v = 0; v < sj.problem.views.size(); ++v) {
      if (n != "view " + sj.problem.views[v].id + " tz") continue;
      const int b = r->layout->view_block(static_cast<int>(v));
      const double total = r->Covariance({b})(5, 5), cal = r->CalibrationCovariance({b})(5, 5);
      EXPECT_NEAR(rows[q].sigma * rows[q].sigma, total, 1e-9 * total) << n;
      EXPECT_NEAR(rows[q].source_sigma[static_cast<int>(Source::kCalibration)] *
                      rows[q].source_sigma[static_cast<int>(Source::kCalibration)],
                  cal, 1e-9 * total) << n;
      EXPECT_GT(cal, 0.0) << n;
      ++checked;
    }
  }
  EXPECT_EQ(checked, 7);
  // The held group's centre projection depends on the calibration alone.
  ASSERT_GT(qs.Gc.cols(), 0);
  EXPECT_NE(rows[0].quantity.name.find("centre projection"), std::string::npos);
  EXPECT_NEAR(rows[0].share[static_cast<int>(Source::kCalibration)], 1.0, 1e-12);
}

// The tips triangulated in the Monte Carlo (pixels from the TRUE camera): amid the markers
// (their centroid is near (-20, 0, 27)), and 120 mm beyond them along the object's z.
const Eigen::Vector3d kTipInside(-20, 0, 25), kTipOutside(-20, 0, 145);


double Nees(const Eigen::VectorXd& e, const Eigen::MatrixXd& C) {
  return e.dot(C.ldlt().solve(e)) / static_cast<double>(e.size());
}

TEST(Consider, MonteCarloNeesWithAndWithoutTheConsiderTerm) {
  constexpr int kTrials = 300;
  constexpr double kTipSigmaPx = 0.3;
  const SyntheticJointSpec spec = PoseSpec(5);
  double pose_on = 0, pose_off = 0, rel_on = 0, rel_off = 0;
  double tip_on[2] = {}, tip_off[2] = {}, tip_share[2] = {};
  double cal_share_tz = 0;
  int n_pose = 0;
  std::mt19937_64 rng(11);
  for (int t = 0; t < kTrials; ++t) {
    const SyntheticJoint sj = MakeSyntheticJoint(spec, NoiseSwitches(), 50000 + t);
    auto r = SolveBundleAdjustment(sj.problem, BaOptions());
    ASSERT_TRUE(r.ok()) << r.status().message();
    const std::vector<int> views = ObjectViews(sj.problem);
    for (int v : views) {
      const int b = r->layout->view_block(v);
      const Pose6 e = Eigen::Map<const Pose6>(r->block(b)) - sj.true_poses[v];
      const Eigen::MatrixXd C_obs = r->ObservationCovariance({b});
      const Eigen::MatrixXd C_cal = r->CalibrationCovariance({b});
      pose_on += Nees(e, C_obs + C_cal);
      pose_off += Nees(e, C_obs);
      cal_share_tz += C_cal(5, 5) / (C_obs(5, 5) + C_cal(5, 5));
      ++n_pose;
    }
    // The relative pose of views +000 and +090.
    const auto rel = analysis::EstimateRelativePoses(*r, {{views[0], views[4]}});
    ASSERT_EQ(rel.size(), 1u);
    const analysis::RelativePoseError err =
        analysis::CompareRelativePose(rel[0], sj.true_poses[views[0]], sj.true_poses[views[4]]);
    rel_on += err.nees / 6.0;
    Matrix6 C_off = rel[0].covariance - rel[0].covariance_calibration;
    rel_off += Nees(err.error, C_off);
    // Two tips seen in all object views: amid the markers, and 120 mm beyond them.
    for (int k = 0; k < 2; ++k) {
      const Eigen::Vector3d tip = k == 0 ? kTipInside : kTipOutside;
      auto tp = analysis::TriangulatePoint(
          sj.problem, *r, TruePointPixels(sj, tip, views, kTipSigmaPx, &rng));
      ASSERT_TRUE(tp.ok()) << tp.status().message();
      const Eigen::Vector3d et = tp->p_in_object - tip;
      tip_on[k] += Nees(et, tp->covariance);
      tip_off[k] += Nees(et, tp->covariance - tp->covariance_calibration);
      tip_share[k] += tp->covariance_calibration.trace() / tp->covariance.trace();
      EXPECT_NEAR(tp->solve_trace_by_source[static_cast<int>(Source::kCalibration)],
                  tp->covariance_calibration.trace(), 1e-9 * tp->covariance.trace());
    }
  }
  pose_on /= n_pose, pose_off /= n_pose, cal_share_tz /= n_pose;
  rel_on /= kTrials, rel_off /= kTrials;
  for (int k = 0; k < 2; ++k) tip_on[k] /= kTrials, tip_off[k] /= kTrials, tip_share[k] /= kTrials;
  std::printf("held intrinsics from a 5-plate-view calibration with error, %d trials: NEES per dof "
              "with / without the consider term: poses %.3f / %.3f (calibration share of the tz "
              "variance %.0f %%), relative pose +000/+090 %.3f / %.3f, tip amid the markers "
              "%.3f / %.3f (calibration share %.1f %%), tip 120 mm beyond them %.3f / %.3f "
              "(share %.0f %%)\n",
              kTrials, pose_on, pose_off, 100 * cal_share_tz, rel_on, rel_off, tip_on[0],
              tip_off[0], 100 * tip_share[0], tip_on[1], tip_off[1], 100 * tip_share[1]);
  testing::RecordFigure("consider.trials", "%d", kTrials);
  testing::RecordFigure("consider.poses", "%.3f / %.1f", pose_on, pose_off);
  testing::RecordFigure("consider.tz_share", "%.0f %%", 100 * cal_share_tz);
  testing::RecordFigure("consider.relative_pose", "%.3f / %.2f", rel_on, rel_off);
  testing::RecordFigure("consider.tip_far", "%.3f / %.2f", tip_on[1], tip_off[1]);
  testing::RecordFigure("consider.tip_far_share", "%.0f %%", 100 * tip_share[1]);
  testing::RecordFigure("consider.tip_amid", "%.3f / %.3f", tip_on[0], tip_off[0]);
  testing::RecordFigure("consider.tip_amid_share", "%.1f %%", 100 * tip_share[0]);
  for (double x : {pose_on, rel_on, tip_on[0], tip_on[1]}) {
    EXPECT_GE(x, kNeesLow);
    EXPECT_LE(x, kNeesHigh);
  }
  // Without it: the poses, the relative pose and the far tip are overconfident. A point amid the
  // markers is triangulated by the same camera model that placed the views on the markers, so
  // the calibration error cancels there (its share is < 1 %: no consider term needed, none added).
  EXPECT_GT(pose_off, kNeesHigh);
  EXPECT_GT(rel_off, kNeesHigh);
  EXPECT_GT(tip_off[1], kNeesHigh);
  EXPECT_LT(tip_share[0], 0.01);
}

TEST(Consider, LeaveOneMarkerOutTreWithTheCalibrationConsidered) {
  // The TRE of the same pose problems: mean e^T (C_tri + C_ct)^-1 e / 3 over the markers and
  // trials in the band; the markers lie amid the others, so the calibration's part of
  // C_tri is small there (as for the inner tip above) but present.
  constexpr int kTrials = 40;
  const SyntheticJointSpec spec = PoseSpec(5);
  double m2 = 0, cal_share = 0;
  int n = 0;
  for (int t = 0; t < kTrials; ++t) {
    const SyntheticJoint sj = MakeSyntheticJoint(spec, NoiseSwitches(), 60000 + t);
    auto r = SolveBundleAdjustment(sj.problem, BaOptions());
    ASSERT_TRUE(r.ok()) << r.status().message();
    auto tre = analysis::LeaveOneMarkerOut(sj.problem, *r, BaOptions());
    ASSERT_TRUE(tre.ok()) << tre.status().message();
    for (const analysis::MarkerTre& m : tre->markers) {
      ASSERT_TRUE(m.skipped.empty()) << m.skipped;
      m2 += m.mahalanobis2 / 3.0;
      cal_share += m.covariance_calibration.trace() / m.covariance.trace();
      ++n;
    }
  }
  m2 /= n, cal_share /= n;
  std::printf("leave-one-marker-out TRE with the calibration considered, %d trials x 9 markers: "
              "mean e^T C^-1 e / 3 = %.3f; calibration share of tr(C_tri) %.2f %%\n",
              kTrials, m2, 100 * cal_share);
  testing::RecordFigure("consider.tre_trials", "%d", kTrials);
  testing::RecordFigure("consider.tre_nees", "%.3f", m2);
  testing::RecordFigure("consider.tre_share", "%.2f %%", 100 * cal_share);
  EXPECT_GE(m2, kNeesLow);
  EXPECT_LE(m2, kNeesHigh);
  EXPECT_GT(cal_share, 0.0);
}

TEST(Whitening2x2, PoseNeesWithFullBlobCovariancesAgainstTheIsotropicBound) {
  // Each object observation with its own anisotropic 2x2 covariance (axes ratio 3 in sigma):
  // whitened by the full 2x2 the pose NEES is ~1; whitened isotropically by the larger
  // eigenvalue it is conservative (NEES < 1) and the poses are less accurate.
  constexpr int kTrials = 200;
  SyntheticJointSpec spec;
  spec.num_plate_views = 10;
  spec.object_px_anisotropy = 3.0;
  double nees_full = 0, nees_iso = 0, e2_full = 0, e2_iso = 0;
  int n = 0;
  for (int t = 0; t < kTrials; ++t) {
    const SyntheticJoint sj = MakeSyntheticJoint(spec, NoiseSwitches(), 70000 + t);
    BaProblem iso = sj.problem;
    for (BaView& v : iso.views) {
      if (v.obs_covariance_px2.empty()) continue;
      for (size_t i = 0; i < v.uv_px.size(); ++i) v.obs_sigma_px.push_back(v.SigmaPx(i));
      v.obs_covariance_px2.clear();
    }
    auto rf = SolveBundleAdjustment(sj.problem, BaOptions());
    auto ri = SolveBundleAdjustment(iso, BaOptions());
    ASSERT_TRUE(rf.ok() && ri.ok());
    for (int v : ObjectViews(sj.problem)) {
      const int b = rf->layout->view_block(v);
      const Pose6 ef = Eigen::Map<const Pose6>(rf->block(b)) - sj.true_poses[v];
      const Pose6 ei = Eigen::Map<const Pose6>(ri->block(b)) - sj.true_poses[v];
      nees_full += Nees(ef, rf->Covariance({b}));
      nees_iso += Nees(ei, ri->Covariance({b}));
      e2_full += ef.tail<3>().squaredNorm();
      e2_iso += ei.tail<3>().squaredNorm();
      ++n;
    }
  }
  nees_full /= n, nees_iso /= n;
  std::printf(
      "anisotropic blobs (sigma axes ratio 3), %d trials: pose NEES per dof full 2x2 "
      "%.3f, isotropic larger-eigenvalue bound %.3f; RMS translation error %.4f / %.4f mm\n",
      kTrials,
      nees_full,
      nees_iso,
      std::sqrt(e2_full / n),
      std::sqrt(e2_iso / n));
  testing::RecordFigure("whitening.trials", "%d", kTrials);
  testing::RecordFigure("whitening.nees", "%.3f full 2x2 against %.3f", nees_full, nees_iso);
  testing::RecordFigure(
      "whitening.rms", "%.2f against %.2f mm", std::sqrt(e2_full / n), std::sqrt(e2_iso / n));
  EXPECT_GE(nees_full, kNeesLow);
  EXPECT_LE(nees_full, kNeesHigh);
  EXPECT_LT(nees_iso, nees_full);
  EXPECT_LT(e2_full, e2_iso);
}

TEST(Consider, BadConsideredCalibrationIsRefused) {
  SyntheticJointSpec spec = PoseSpec(5);
  SyntheticJoint sj = MakeSyntheticJoint(spec, NoiseSwitches(), 5);
  BaProblem p = sj.problem;
  p.groups[0].free[kFx] = true;  // a considered intrinsic that is free
  auto r = SolveBundleAdjustment(p, BaOptions());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("fx is free"), std::string::npos) << r.status().message();
  p = sj.problem;
  p.groups[0].consider_covariance(0, 0) = -1;
  r = SolveBundleAdjustment(p, BaOptions());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("positive semi-definite"), std::string::npos)
      << r.status().message();
  p = sj.problem;
  p.groups[0].consider_indices.pop_back();
  r = SolveBundleAdjustment(p, BaOptions());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("5x5"), std::string::npos) << r.status().message();
  p = sj.problem;
  p.views.back().obs_covariance_px2.assign(p.views.back().uv_px.size(),
                                           Eigen::Matrix2d::Identity());
  p.views.back().obs_covariance_px2[2](0, 1) = 3;
  p.views.back().obs_covariance_px2[2](1, 0) = 3;
  r = SolveBundleAdjustment(p, BaOptions());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("not symmetric positive definite"), std::string::npos)
      << r.status().message();
}

}  // namespace
}  // namespace ba
}  // namespace carmba
