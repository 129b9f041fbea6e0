#include "problem/pose_solver.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "figures.h"
#include "geometry/rotation.h"
#include "report/pose_report.h"
#include "scratch.h"
#include "synthetic/synthetic_pose.h"
#include "test_util.h"
#include "util/stats.h"

namespace carmba {
namespace {

SolverConfig DefaultConfig() {
  SolverConfig c;
  c.name = "test";
  return c;
}

Camera ThesisCamera() {
  Camera cam;
  cam.width = cam.height = 408;
  cam.params = {2061.389, 2254.646, 203.655, 205.117, 0, 0, 0, 0, 0};
  return cam;
}

TEST(PoseSolver, ThesisProblemBeatsLegacyPositAndMatchesExpectedAngles) {
  auto problem = LoadProblem(test::SourcePath("problems/thesis_pose.yaml"));
  ASSERT_TRUE(problem.ok()) << problem.status().message();
  auto config = LoadSolverConfig(test::SourcePath("configs/posit_ba_analytic.yaml"));
  ASSERT_TRUE(config.ok()) << config.status().message();
  auto sol = SolvePoseProblem(*problem, *config);
  ASSERT_TRUE(sol.ok()) << sol.status().message();
  ASSERT_TRUE(sol->has_covariance);
  // Separate fx, fy and the calibrated principal point are used.
  EXPECT_NE(problem->camera->params[kFx], problem->camera->params[kFy]);
  EXPECT_DOUBLE_EQ(problem->camera->params[kCx], 203.655);

  const PoseComparison cmp = ComparePoseMethods(*problem, *config, *sol);
  ASSERT_TRUE(cmp.legacy_error.empty()) << cmp.legacy_error;
  ASSERT_EQ(cmp.legacy.size(), sol->views.size());
  for (size_t v = 0; v < sol->views.size(); ++v) {
    // "Well below": at most half of legacy POSIT's RMS on every view.
    EXPECT_LT(sol->views[v].rms_px, 0.5 * cmp.legacy[v].rms_px) << "view " << sol->views[v].id;
  }
  ASSERT_EQ(sol->validation.size(), 3u);
  for (const auto& p : sol->validation) {
    ASSERT_TRUE(p.expected_deg.has_value());
    EXPECT_LE(std::fabs(p.angle_view_dirs_deg - *p.expected_deg), 2 * p.sigma_view_dirs_deg)
        << p.a << "-" << p.b << ": " << p.angle_view_dirs_deg << " +- " << p.sigma_view_dirs_deg;
    EXPECT_GT(p.sigma_view_dirs_deg, 0);
  }
  // The legacy reproduction inside the comparison matches the printed R10, R30, R50.
  for (const auto& l : cmp.legacy) {
    if (l.id == "10" || l.id == "30" || l.id == "50") {
      ASSERT_TRUE(l.max_diff_to_reference.has_value());
      EXPECT_LT(*l.max_diff_to_reference, 3e-3) << l.id;
    }
  }
}

// All four initialisers and both Jacobian kinds converge to the same minimum.
TEST(PoseSolver, InitializersAndJacobiansAgree) {
  SyntheticPoseSpec spec;
  spec.camera = ThesisCamera();
  spec.camera.params[kK1] = -0.2;
  spec.markers = ThesisMarkers();
  const Problem p = MakeSyntheticPoseProblem(spec, 0.3, 0.1, 11);
  SolverConfig ref = DefaultConfig();
  auto base = SolvePoseProblem(p, ref);
  ASSERT_TRUE(base.ok()) << base.status().message();
  for (Initializer init : {Initializer::kLegacyPosit, Initializer::kEpnp, Initializer::kSqpnp}) {
    for (bool analytic : {true, false}) {
      SolverConfig c = DefaultConfig();
      c.initializer = init;
      c.analytic_jacobians = analytic;
      auto s = SolvePoseProblem(p, c);
      ASSERT_TRUE(s.ok()) << NameOf(kInitializerNames, init) << ": " << s.status().message();
      for (size_t v = 0; v < s->views.size(); ++v) {
        // Same minimum: poses to 1e-6 of the pose sigma scale.
        EXPECT_LT((s->views[v].cam_from_object - base->views[v].cam_from_object).norm(), 1e-5)
            << NameOf(kInitializerNames, init) << (analytic ? " analytic" : " autodiff") << " view "
            << v;
      }
      EXPECT_NEAR(s->ba_result->chi2, base->ba_result->chi2, 1e-8 * base->ba_result->chi2);
    }
  }
}

// Without refinement the initialiser's pose is reported and no covariance is claimed.
TEST(PoseSolver, UnrefinedReportsInitializerWithoutCovariance) {
  SyntheticPoseSpec spec;
  spec.camera = ThesisCamera();
  spec.markers = ThesisMarkers();
  const Problem p = MakeSyntheticPoseProblem(spec, 0.3, 0.1, 3);
  SolverConfig c = DefaultConfig();
  c.initializer = Initializer::kLegacyPosit;
  c.refine = false;
  auto s = SolvePoseProblem(p, c);
  ASSERT_TRUE(s.ok());
  EXPECT_FALSE(s->has_covariance);
  EXPECT_EQ(s->views[0].cam_from_object, s->views[0].initial);
  EXPECT_TRUE(std::isnan(s->validation[0].sigma_view_dirs_deg));
}

// Seeded Monte Carlo: the reported covariance matches the actual spread of the estimates.
// 200 trials of pixel noise (0.5 px) and CT noise (0.2 mm) on the 9-marker object; also the
// relative poses' 6x6 covariances (NEES) and the leave-one-marker-out TRE against its prediction.
TEST(PoseSolver, MonteCarloCovarianceIsHonest) {
  constexpr int kTrials = 200;
  SyntheticPoseSpec spec;
  spec.camera = ThesisCamera();
  spec.camera.params[kK1] = -0.15;
  spec.camera.params[kP1] = 1e-3;
  spec.markers = ThesisMarkers();
  SolverConfig config = DefaultConfig();
  config.tre = true;  // leave-one-marker-out TRE through the pose front end
  double nees_sum = 0;
  int nees_n = 0;
  double rel_nees = 0, tre_e2 = 0, tre_pred2 = 0;
  int rel_n = 0, tre_n = 0;
  // Relative-rotation angle per pair: errors and reported sigmas.
  std::vector<std::vector<double>> rr_err(spec.pairs.size());
  std::vector<double> rr_sigma_sum(spec.pairs.size(), 0);
  for (int trial = 0; trial < kTrials; ++trial) {
    const Problem p = MakeSyntheticPoseProblem(spec, 0.5, 0.2, 1000 + trial);
    auto s = SolvePoseProblem(p, config);
    ASSERT_TRUE(s.ok()) << s.status().message();
    for (const auto& v : s->views) {
      const Pose6& truth = p.truth.object_poses.at(v.id);
      const Pose6 e = v.cam_from_object - truth;  // covariance is of (rvec, t)
      nees_sum += e.dot(v.covariance.ldlt().solve(e)) / 6.0;
      ++nees_n;
    }
    ASSERT_EQ(s->relative_poses.size(), 10u);  // every pair of the 5 views
    for (const auto& rp : s->relative_poses) {
      const auto err =
          analysis::CompareRelativePose(rp,
                                        p.truth.object_poses.at(p.object_views[rp.view_a].id),
                                        p.truth.object_poses.at(p.object_views[rp.view_b].id));
      rel_nees += err.nees / 6.0;
      ++rel_n;
    }
    ASSERT_TRUE(s->tre.has_value());
    ASSERT_EQ(s->tre->num_evaluated, 9);
    for (const auto& m : s->tre->markers) {
      tre_e2 += m.error_mm * m.error_mm;
      tre_pred2 += m.predicted_rms_mm * m.predicted_rms_mm;
      ++tre_n;
    }
    for (size_t k = 0; k < s->validation.size(); ++k) {
      const auto& pr = s->validation[k];
      const double truth = RelativeRotationAngle(p.truth.object_poses.at(pr.a).data(),
                                                 p.truth.object_poses.at(pr.b).data()) *
                           kRadToDeg;
      rr_err[k].push_back(pr.relative_rotation_deg - truth);
      rr_sigma_sum[k] += pr.sigma_relative_rotation_deg;
    }
  }
  const double mean_nees = nees_sum / nees_n;
  // Expected 1; with 200 x 5 correlated 6-D samples its sampling spread is ~0.05.
  EXPECT_GE(mean_nees, 0.8);
  EXPECT_LE(mean_nees, 1.25);
  std::printf("mean NEES/6 over %d view estimates: %.3f\n", nees_n, mean_nees);
  // The relative poses' 6x6 covariances and the leave-one-out TRE (the band).
  std::printf("relative poses: mean NEES/6 over %d pair estimates %.3f; leave-one-marker-out: "
              "mean squared error / predicted over %d markers %.3f\n",
              rel_n, rel_nees / rel_n, tre_n, tre_e2 / tre_pred2);
  testing::RecordFigure("posemc.trials", "%d", kTrials);
  testing::RecordFigure("posemc.nees", "%.2f", mean_nees);
  testing::RecordFigure("posemc.relative_nees",
                        "%.3f (%d trials x %d pairs)",
                        rel_nees / rel_n,
                        kTrials,
                        rel_n / kTrials);
  testing::RecordFigure(
      "posemc.tre", "%.3f (%d trials x %d markers)", tre_e2 / tre_pred2, kTrials, tre_n / kTrials);
  EXPECT_GE(rel_nees / rel_n, 0.8);
  EXPECT_LE(rel_nees / rel_n, 1.25);
  EXPECT_GE(tre_e2 / tre_pred2, 0.8);
  EXPECT_LE(tre_e2 / tre_pred2, 1.25);
  std::string ratios;
  for (size_t k = 0; k < rr_err.size(); ++k) {
    double m = 0, ss = 0;
    for (double e : rr_err[k]) m += e;
    m /= kTrials;
    for (double e : rr_err[k]) ss += (e - m) * (e - m);
    const double empirical = std::sqrt(ss / (kTrials - 1));
    const double reported = rr_sigma_sum[k] / kTrials;
    std::printf("pair %zu: relative rotation sigma reported %.4f deg, empirical %.4f deg\n", k,
                reported, empirical);
    EXPECT_NEAR(reported / empirical, 1.0, 0.15) << "pair " << k;
    char r[16];
    std::snprintf(r, sizeof r, "%.2f", reported / empirical);
    ratios += (ratios.empty() ? "" : ", ") + std::string(r);
  }
  testing::RecordFigure(
      "posemc.sigma_ratios", "%s for the %zu pairs", ratios.c_str(), rr_err.size());
}

TEST(PoseSolver, DegenerateViewIsAnError) {
  SyntheticPoseSpec spec;
  spec.camera = ThesisCamera();
  spec.markers = {{0, 0, 0}, {30, 0, 0}, {0, 30, 0}, {30, 30, 0}, {15, 10, 0}};  // coplanar
  const Problem p = MakeSyntheticPoseProblem(spec, 0.3, 0.0, 5);                 // exact plane
  auto s = SolvePoseProblem(p, DefaultConfig());
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("coplanar"), std::string::npos) << s.status().message();
}

TEST(Stats, ChiSquareUpperTail) {
  // Reference values: scipy.stats.chi2.sf(x, k) (python3-scipy 1.10).
  EXPECT_NEAR(ChiSquareUpperTail(10.0, 10), 0.440493285, 1e-8);
  EXPECT_NEAR(ChiSquareUpperTail(3.84145882, 1), 0.05, 1e-8);
  EXPECT_NEAR(ChiSquareUpperTail(50.0, 20), 0.000221476638, 1e-11);
  EXPECT_NEAR(ChiSquareUpperTail(0.5, 6), 0.997839, 1e-6);
}

}  // namespace
}  // namespace carmba

namespace carmba {
namespace {

// The four covariance back-ends compute the same matrix: carmba's Schur complement against
// ceres::Covariance (dense SVD, SuiteSparse QR, Eigen sparse QR), with analytic and autodiff
// Jacobians, with and without a robust loss that is active on some residuals, on one view and on
// five views that share the markers.
TEST(PoseSolver, CovarianceAlgorithmsAgree) {
  constexpr double kRelTol = 1e-8;
  for (int views : {1, 5}) {
    SyntheticPoseSpec spec;
    spec.camera = ThesisCamera();
    spec.markers = ThesisMarkers();
    if (views == 1) spec.view_angles_deg = {30}, spec.pairs.clear();
    const Problem p = MakeSyntheticPoseProblem(spec, 0.5, 0.2, 21);
    for (const ba::Loss loss : {ba::Loss::kTrivial, ba::Loss::kHuber, ba::Loss::kCauchy}) {
      for (bool analytic : {true, false}) {
        SolverConfig c = DefaultConfig();
        c.loss = loss;
        c.loss_scale_px = 0.4;  // below the 0.5 px noise: the loss is active on some residuals
        c.analytic_jacobians = analytic;
        c.covariance_algorithm = ba::CovarianceAlgorithm::kDenseSvd;
        auto ref = SolvePoseProblem(p, c);
        ASSERT_TRUE(ref.ok()) << ref.status().message();
        ASSERT_EQ(ref->joint_covariance.rows(), 6 * views);
        for (const ba::CovarianceAlgorithm algo : {ba::CovarianceAlgorithm::kSchur,
                                                   ba::CovarianceAlgorithm::kSparseQr,
                                                   ba::CovarianceAlgorithm::kEigenSparseQr}) {
          c.covariance_algorithm = algo;
          const char* algo_name = NameOf(ba::kCovarianceAlgorithmNames, algo);
          auto s = SolvePoseProblem(p, c);
          ASSERT_TRUE(s.ok()) << algo_name;
          const double rel = (s->joint_covariance - ref->joint_covariance).norm() /
                             ref->joint_covariance.norm();
          EXPECT_LT(rel, kRelTol) << algo_name << ", " << views << " views, loss "
                                  << NameOf(ba::kLossNames, loss)
                                  << (analytic ? ", analytic" : ", autodiff");
        }
      }
    }
  }
}

// A robust loss changes the covariance (so the test above compares something the loss affects).
TEST(PoseSolver, RobustLossEntersTheSchurCovariance) {
  SyntheticPoseSpec spec;
  spec.camera = ThesisCamera();
  spec.markers = ThesisMarkers();
  const Problem p = MakeSyntheticPoseProblem(spec, 0.5, 0.2, 21);
  SolverConfig c = DefaultConfig();
  auto plain = SolvePoseProblem(p, c);
  c.loss = ba::Loss::kCauchy;
  c.loss_scale_px = 0.4;
  auto robust = SolvePoseProblem(p, c);
  ASSERT_TRUE(plain.ok() && robust.ok());
  EXPECT_GT((plain->joint_covariance - robust->joint_covariance).norm() /
                plain->joint_covariance.norm(),
            1e-3);
}

// A name no table holds is an error naming the file, the line, the key and the names it takes.
TEST(PoseSolver, UnknownCovarianceAlgorithmIsRejected) {
  const test::ScratchDir dir("solver_config");
  dir.Write("c.yaml", "name: c\ncovariance: {algorithm: cholmod}\n");
  auto c = LoadSolverConfig(dir.File("c.yaml"));
  ASSERT_FALSE(c.ok());
  const std::string& m = c.status().message();
  EXPECT_NE(m.find("c.yaml:2"), std::string::npos) << m;
  EXPECT_NE(m.find("covariance.algorithm"), std::string::npos) << m;
  EXPECT_NE(m.find("schur|dense_svd|sparse_qr|eigen_sparse_qr, got 'cholmod'"), std::string::npos)
      << m;
  for (const auto& [yaml, expected] :
       {std::pair<std::string, std::string>{"loss: {type: l2}", "soft_l1, got 'l2'"},
        {"backend: levmar", "ceres|carmba_lm, got 'levmar'"}}) {
    dir.Write("l.yaml", "name: l\n" + yaml + "\n");
    auto l = LoadSolverConfig(dir.File("l.yaml"));
    ASSERT_FALSE(l.ok()) << yaml;
    EXPECT_NE(l.status().message().find(expected), std::string::npos) << l.status().message();
  }
}

}  // namespace
}  // namespace carmba
