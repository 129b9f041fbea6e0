// The calibration bundle adjustment on observations projected with the camera model (seeded
// noise): recovery, residual statistics, covariance against a seeded Monte Carlo, constraints,
// degenerate input.
#include "calib/calibrate.h"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>

#include "ba/shadow_correction.h"
#include "figures.h"
#include "geometry/rotation.h"
#include "synthetic/synthetic_views.h"

namespace carmba {
namespace {

// A C-arm like the thesis's: 408 x 408, fx 2061, fy 2255, mild barrel distortion.
const std::array<double, kNumIntrinsics> kTruth = {2061.4, 2254.6, 203.7, 205.1, -0.3,
                                                   2.0,    0.0005, -0.0003, 0.0};

GridSpec Plate5x5() {
  GridSpec g;
  g.pattern = GridPattern::kCircles;
  g.rows = g.cols = 5;
  g.spacing_mm = 20;
  return g;
}

double Projected(const std::array<double, kNumIntrinsics>& a, double x, double y, int c) {
  const double p[3] = {x, y, 1.0};
  double uv[2];
  ProjectCamPoint(a.data(), p, uv);
  return uv[c];
}

TEST(CalibrateTest, RecoversNoiseFreeTruth) {
  // Noise-free data: the solution must reproduce the truth to solver precision.
  constexpr double kParamTol = 1e-4;  // px; LM stops at ~1e-12 relative cost change
  SyntheticViewsOptions so;
  so.noise_sigma_px = 0;
  so.num_views = 12;
  const ObservationSet obs = MakeSyntheticViews(kTruth, 408, 408, Plate5x5(), so);
  ASSERT_EQ(obs.views.size(), 12u);
  CalibrationOptions opt;
  opt.pixel_sigma_px = 0.1;
  auto r = Calibrate(obs, opt);
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_LT(r->rms_px, 1e-6);
  // Compare by projection over the field (k2/k3 trade off at this narrow field of view).
  for (double x : {-0.1, 0.0, 0.1}) {
    for (double y : {-0.09, 0.0, 0.09}) {
      for (int c = 0; c < 2; ++c) {
        EXPECT_NEAR(Projected(r->camera.params, x, y, c), Projected(kTruth, x, y, c), kParamTol);
      }
    }
  }
  EXPECT_NEAR(r->camera.params[kFx], kTruth[kFx], 1e-2);
  EXPECT_NEAR(r->camera.params[kCy], kTruth[kCy], 1e-2);
}

// A plate of metal spheres: each detected centre follows its cone-beam shadow, whose centre lies
// off the projection of the sphere's centre (through the lens: outwards for the ellipse, and the
// lens's curvature over the shadow moves it too; ba/shadow_correction.h). Noise-free centres with
// those offsets bias the intrinsics unless the plate's sphere diameter is given; with it the
// engine subtracts them and the truth comes back to solver precision.
TEST(CalibrateTest, PlateSphereShadowsAreCorrectedWhenTheDiameterIsGiven) {
  constexpr double kDiameterMm = 10;  // large spheres, near: offsets up to ~0.01 px
  SyntheticViewsOptions so;
  so.noise_sigma_px = 0;
  so.num_views = 12;
  so.distance_min_mm = 480;
  so.distance_max_mm = 560;
  std::vector<Pose6> poses;
  ObservationSet obs = MakeSyntheticViews(kTruth, 408, 408, Plate5x5(), so, &poses);
  double largest = 0;
  for (size_t v = 0; v < obs.views.size(); ++v) {
    const Eigen::Matrix3d R = RotationOf(poses[v].data());
    const Eigen::Vector3d t(poses[v][3], poses[v][4], poses[v][5]);
    for (size_t i = 0; i < obs.views[v].point_ids.size(); ++i) {
      const Eigen::Vector3d p = R * obs.grid.PointInPlate(obs.views[v].point_ids[i]) + t;
      const Eigen::Vector2d d = ba::SphereShadowOffsetPx(kTruth.data(), p, kDiameterMm / 2);
      obs.views[v].uv_px[i] += d;
      largest = std::max(largest, d.norm());
    }
  }
  std::cout << "largest offset " << largest << " px\n";
  ASSERT_GT(largest, 0.005);
  // The largest projection difference from the truth over the field (px).
  auto worst = [](const std::array<double, kNumIntrinsics>& a) {
    double w = 0;
    for (double x : {-0.1, 0.0, 0.1}) {
      for (double y : {-0.09, 0.0, 0.09}) {
        for (int c = 0; c < 2; ++c)
          w = std::max(w, std::abs(Projected(a, x, y, c) - Projected(kTruth, x, y, c)));
      }
    }
    return w;
  };
  CalibrationOptions opt;
  opt.pixel_sigma_px = 0.02;
  auto plain = Calibrate(obs, opt);
  ASSERT_TRUE(plain.ok()) << plain.status().message();
  EXPECT_FALSE(plain->engine->shadow.evaluated);
  obs.grid.sphere_diameter_mm = kDiameterMm;
  auto corrected = Calibrate(obs, opt);
  ASSERT_TRUE(corrected.ok()) << corrected.status().message();
  EXPECT_TRUE(corrected->engine->shadow.applied);
  EXPECT_NEAR(corrected->engine->shadow.max_px, largest, 0.05 * largest);
  std::cout << "projection off the truth: " << worst(plain->camera.params) << " px uncorrected, "
            << worst(corrected->camera.params) << " px corrected\n";
  testing::RecordFigure("plateshadow.without", "%.4f px", worst(plain->camera.params));
  testing::RecordFigure("plateshadow.with", "%.5f px", worst(corrected->camera.params));
  EXPECT_GT(worst(plain->camera.params), 0.004);
  EXPECT_LT(worst(corrected->camera.params), 5e-4);
  EXPECT_LT(corrected->rms_px, 1e-4);
  // The a-posteriori pixel sigma (none given): the threshold of 0.1 sigma is of the estimated
  // sigma, not of the nominal 1 px the solve whitens with.
  opt.pixel_sigma_px = 0;
  auto estimated = Calibrate(obs, opt);
  ASSERT_TRUE(estimated.ok()) << estimated.status().message();
  EXPECT_TRUE(estimated->engine->shadow.applied);
}

TEST(CalibrateTest, NoisyRmsAndTruthWithinThreeSigma) {
  constexpr double kNoise = 0.3;
  constexpr double kRmsRelTol = 0.1;  // 800 residuals: RMS relative spread ~ 2.5 %
  SyntheticViewsOptions so;
  so.noise_sigma_px = kNoise;
  so.seed = 7;
  const ObservationSet obs = MakeSyntheticViews(kTruth, 408, 408, Plate5x5(), so);
  CalibrationOptions opt;
  auto r = Calibrate(obs, opt);
  ASSERT_TRUE(r.ok()) << r.status().message();
  // The per-coordinate RMS is below sigma by sqrt(dof / 2N); the estimated sigma is unbiased.
  EXPECT_NEAR(r->sigma_px, kNoise, kRmsRelTol * kNoise);
  EXPECT_NEAR(r->rms_px, kNoise * std::sqrt(double(r->dof) / (2 * r->num_points)),
              kRmsRelTol * kNoise);
  EXPECT_NEAR(r->rms_opencv_px, std::sqrt(2.0) * r->rms_px, 1e-12);
  for (int i : {kFx, kFy, kCx, kCy}) {
    EXPECT_LT(std::abs(r->camera.params[i] - kTruth[i]), 3 * r->sigma[i]) << kIntrinsicNames[i];
  }
  ASSERT_EQ(r->projection_sigma.size(), 5u);
  EXPECT_EQ(r->views.size(), obs.views.size());
  EXPECT_EQ(r->worst.size(), 10u);
}

// Seeded Monte Carlo: kTrials re-solves of one geometry with fresh noise. Returns the sample
// standard deviation of fx, fy, cx, cy, and the RMS of the sigmas each re-solve reported.
void MonteCarlo(const ObservationSet& clean,
                const CalibrationOptions& opt,
                int trials,
                double noise_px,
                std::array<double, 4>* sd,
                std::array<double, 4>* rms_reported) {
  std::array<double, 4> sum{}, sum2{}, rep2{};
  for (int t = 0; t < trials; ++t) {
    auto r = Calibrate(AddNoise(clean, noise_px, 1000 + t), opt);
    ASSERT_TRUE(r.ok()) << r.status().message();
    for (int i = 0; i < 4; ++i) {
      const double d = r->camera.params[i] - kTruth[i];
      sum[i] += d;
      sum2[i] += d * d;
      rep2[i] += r->sigma[i] * r->sigma[i];
    }
  }
  for (int i = 0; i < 4; ++i) {
    const double mean = sum[i] / trials;
    (*sd)[i] = std::sqrt(sum2[i] / trials - mean * mean);
    (*rms_reported)[i] = std::sqrt(rep2[i] / trials);
  }
}

// 200 trials: the sample std of 200 draws is itself uncertain by ~5 %, so 15 % is a 3-sigma bound.
constexpr int kTrials = 200;
constexpr double kMcNoise = 0.3;
constexpr double kSigmaRelTol = 0.15;

TEST(CalibrateTest, CovarianceAtTruthMatchesMonteCarloFullModel) {
  // Full OPENCV5 model at this narrow field of view (~11 deg): the distortion terms are barely
  // determined, each noisy solution lands at a different k2/k3 (hundreds/thousands) and the
  // covariance evaluated there varies (cx sigma 6..24 px between trials). The linearised
  // covariance AT THE TRUTH (noise-free solve) must match the Monte Carlo spread.
  SyntheticViewsOptions so;
  so.noise_sigma_px = 0;
  so.seed = 3;
  const ObservationSet clean = MakeSyntheticViews(kTruth, 408, 408, Plate5x5(), so);
  CalibrationOptions opt;
  opt.pixel_sigma_px = kMcNoise;
  opt.initial_intrinsics.assign(kTruth.begin(), kTruth.end());
  auto at_truth = Calibrate(clean, opt);
  ASSERT_TRUE(at_truth.ok());
  std::array<double, 4> sd, rep;
  MonteCarlo(clean, opt, kTrials, kMcNoise, &sd, &rep);
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(sd[i] / at_truth->sigma[i], 1.0, kSigmaRelTol)
        << kIntrinsicNames[i] << ": Monte Carlo " << sd[i] << " at truth " << at_truth->sigma[i];
  }
  // fx, fy: the per-trial reported sigmas match too.
  for (int i : {kFx, kFy}) {
    EXPECT_NEAR(sd[i] / rep[i], 1.0, kSigmaRelTol) << kIntrinsicNames[i];
  }
}

TEST(CalibrateTest, ReportedCovarianceMatchesMonteCarloDistortionHeld) {
  // With the distortion held (at the truth) the problem is close to linear in the noise and every
  // re-solve's reported sigma of fx, fy, cx, cy must match the Monte Carlo spread. (With the
  // distortion free, the per-trial cx, cy sigmas are 1.25-1.6x below the spread: see the test
  // above, the next one and tests/calib/scene_monte_carlo_test.cc: the cause is the tangential
  // terms p1, p2, which trade with cx, cy along a curved valley, not k2 / k3.)
  SyntheticViewsOptions so;
  so.noise_sigma_px = 0;
  so.seed = 3;
  const ObservationSet clean = MakeSyntheticViews(kTruth, 408, 408, Plate5x5(), so);
  CalibrationOptions opt;
  opt.pixel_sigma_px = kMcNoise;
  opt.solve.fix = {"k1", "k2", "p1", "p2", "k3"};
  opt.initial_intrinsics.assign(kTruth.begin(), kTruth.end());
  std::array<double, 4> sd, rep;
  MonteCarlo(clean, opt, kTrials, kMcNoise, &sd, &rep);
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(sd[i] / rep[i], 1.0, kSigmaRelTol)
        << kIntrinsicNames[i] << ": Monte Carlo " << sd[i] << " reported " << rep[i];
  }
}

TEST(CalibrateTest, ReportedCovarianceMatchesMonteCarloFullModelAtLowNoise) {
  // The full model's per-trial sigmas are honest when the noise is small enough for the
  // linearisation to hold over its reach: 0.03 px (what the simulated scenes' images give, see
  // tests/calib/scene_monte_carlo_test.cc). At 0.3 px they are not (the first test), and with this
  // weak distortion (k1 = -0.3: the distortion centre barely pins the principal point) holding
  // p1, p2 and k3 does not cure it either (cx, cy 1.27x, 1.20x measured) - unlike the scenes with
  // strong distortion, where it does.
  constexpr double kLowNoise = 0.03;
  SyntheticViewsOptions so;
  so.noise_sigma_px = 0;
  so.seed = 3;
  const ObservationSet clean = MakeSyntheticViews(kTruth, 408, 408, Plate5x5(), so);
  CalibrationOptions opt;
  opt.pixel_sigma_px = kLowNoise;
  std::array<double, 4> sd, rep;
  MonteCarlo(clean, opt, kTrials, kLowNoise, &sd, &rep);
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(sd[i] / rep[i], 1.0, kSigmaRelTol)
        << kIntrinsicNames[i] << ": Monte Carlo " << sd[i] << " reported " << rep[i];
  }
}

TEST(CalibrateTest, OwnLmAndCeresReachTheSameOptimum) {
  // Same cost, two minimisers: carmba's Schur LM (default) and Ceres DENSE_SCHUR.
  constexpr double kRmsRelTol = 1e-6;
  // Both stop on the flat valley where the principal point trades with the plate rotations; 0.01 px
  // is under 5 % of the projection sigma here (~0.2 px).
  constexpr double kProjTolPx = 0.01;
  SyntheticViewsOptions so;
  so.seed = 17;
  const ObservationSet obs = MakeSyntheticViews(kTruth, 408, 408, Plate5x5(), so);
  CalibrationOptions a, b;
  b.solve.backend = ba::Backend::kCeres;
  auto ra = Calibrate(obs, a);
  auto rb = Calibrate(obs, b);
  ASSERT_TRUE(ra.ok() && rb.ok());
  EXPECT_EQ(ra->engine->TerminationText(), "CONVERGENCE (carmba LM)");
  EXPECT_EQ(rb->engine->TerminationText(), "CONVERGENCE (Ceres)");
  EXPECT_NEAR(ra->rms_px / rb->rms_px, 1.0, kRmsRelTol);
  for (double x : {-0.08, 0.0, 0.08}) {
    for (int c = 0; c < 2; ++c) {
      EXPECT_NEAR(Projected(ra->camera.params, x, 0.05, c),
                  Projected(rb->camera.params, x, 0.05, c),
                  kProjTolPx);
    }
  }
}

TEST(CalibrateTest, ThesisConstraintsHold) {
  SyntheticViewsOptions so;
  so.seed = 11;
  const ObservationSet obs = MakeSyntheticViews(kTruth, 408, 408, Plate5x5(), so);
  CalibrationOptions opt;
  opt.fix_aspect_ratio = true;
  opt.aspect_ratio_fy_over_fx = 1.09375;
  opt.zero_tangential = true;
  opt.fix_principal_point = true;
  opt.solve.fix = {"k3"};
  auto r = Calibrate(obs, opt);
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_DOUBLE_EQ(r->camera.params[kCx], 203.5);
  EXPECT_DOUBLE_EQ(r->camera.params[kCy], 203.5);
  EXPECT_EQ(r->camera.params[kP1], 0.0);
  EXPECT_EQ(r->camera.params[kP2], 0.0);
  EXPECT_EQ(r->camera.params[kK3], 0.0);
  EXPECT_NEAR(r->camera.params[kFy] / r->camera.params[kFx], 1.09375, 1e-12);
  EXPECT_EQ(r->num_free_intrinsics, 3);  // f, k1, k2
  EXPECT_EQ(r->sigma[kCx], 0.0);
  EXPECT_GT(r->sigma[kFx], 0.0);
  // fy is fully correlated with fx.
  EXPECT_NEAR(r->sigma[kFy], 1.09375 * r->sigma[kFx], 1e-9 * r->sigma[kFx]);
}

TEST(CalibrateTest, RobustLossFlagsAnOutlier) {
  SyntheticViewsOptions so;
  so.seed = 5;
  so.noise_sigma_px = 0.3;
  ObservationSet obs = MakeSyntheticViews(kTruth, 408, 408, Plate5x5(), so);
  obs.views[4].uv_px[7] += Eigen::Vector2d(6.0, -4.0);
  CalibrationOptions opt;
  opt.solve.loss = ba::Loss::kCauchy;
  opt.solve.loss_scale_px = 1.0;
  auto r = Calibrate(obs, opt);
  ASSERT_TRUE(r.ok()) << r.status().message();
  ASSERT_FALSE(r->outliers.empty());
  EXPECT_EQ(r->outliers[0].view, 4);
  EXPECT_EQ(r->outliers[0].point_id, 7);
  EXPECT_EQ(r->worst[0].view, 4);
  // The pixel sigma is the engine's robust a-posteriori one: sum_i rho'(s_i) s_i over the dof
  // (Cauchy at scale 1 px, pixel sigma 1 px while solving: rho'(s) = 1 / (1 + s)), which the
  // outlier barely moves, where the plain chi2 would.
  double weighted = 0;
  for (const auto& view : r->engine->residuals) {
    for (const auto& res : view) {
      const double s = res.du_px * res.du_px + res.dv_px * res.dv_px;
      weighted += s / (1.0 + s);
    }
  }
  EXPECT_NEAR(r->sigma_px, std::sqrt(weighted / r->dof), 1e-12 * r->sigma_px);
  EXPECT_EQ(r->dof, r->engine->dof);
  EXPECT_GT(r->sigma_px, 0.2);
  EXPECT_LT(r->sigma_px, 0.4);
  EXPECT_GT(r->engine->sigma0, 1.2 * r->sigma_px);
}

TEST(CalibrateTest, FrontoParallelViewsAreRejected) {
  SyntheticViewsOptions so;
  so.min_tilt_deg = 0;
  so.max_tilt_deg = 0;
  so.seed = 2;
  const ObservationSet obs = MakeSyntheticViews(kTruth, 408, 408, Plate5x5(), so);
  auto r = Calibrate(obs, CalibrationOptions());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("fronto-parallel"), std::string::npos)
      << r.status().message();
}

TEST(CalibrateTest, TooFewViewsAndBadOptions) {
  SyntheticViewsOptions so;
  so.num_views = 2;
  const ObservationSet obs = MakeSyntheticViews(kTruth, 408, 408, Plate5x5(), so);
  CalibrationOptions opt;
  opt.min_views = 3;
  auto r = Calibrate(obs, opt);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("min_views is 3"), std::string::npos);
  opt.solve.fix = {"f"};
  r = Calibrate(obs, opt);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("unknown intrinsic 'f'"), std::string::npos);
}

}  // namespace
}  // namespace carmba

namespace carmba {
namespace {

// `distortion: auto` in a calibration (the pixel sigma unknown, estimated from the full model):
// on the tangential C-arm above the recommended model is the one solved, every free intrinsic lands
// within 3 sigma of the truth, and the estimated pixel sigma is the noise's; conflicting flags are
// refused.
TEST(CalibrateTest, DistortionAutoChoosesTheTermsAndRefusesConflictingFlags) {
  SyntheticViewsOptions so;
  so.noise_sigma_px = 0.1;
  so.num_views = 20;
  so.seed = 61;
  const ObservationSet obs = MakeSyntheticViews(kTruth, 408, 408, Plate5x5(), so);
  CalibrationOptions opt;
  opt.solve.distortion_auto = true;
  auto r = Calibrate(obs, opt);
  ASSERT_TRUE(r.ok()) << r.status().message();
  ASSERT_TRUE(r->distortion.has_value());
  EXPECT_TRUE(r->distortion->sigma_estimated);
  EXPECT_NEAR(r->distortion->sigma_px, 0.1, 0.02);
  // The free terms are the recommended model's (here k1 k2: at these pixel sigmas the principal
  // point's sigma, 6.4 px, covers what p1 p2 would move it by).
  analysis::DistortionModel solved;
  std::array<bool, kNumIntrinsics> free{};
  for (int i = 0; i < kNumIntrinsics; ++i) free[i] = r->free[i];
  ASSERT_TRUE(analysis::DistortionModelOf(free, &solved));
  EXPECT_EQ(solved, r->distortion->recommended) << r->distortion->why;
  for (int i = 0; i < kNumIntrinsics; ++i) {
    if (!r->free[i]) {
      EXPECT_EQ(r->camera.params[i], 0.0) << kIntrinsicNames[i];
      continue;
    }
    EXPECT_LT(std::abs(r->camera.params[i] - kTruth[i]), 3 * r->sigma[i]) << kIntrinsicNames[i];
  }
  std::string err;
  CalibrationOptions bad = opt;
  bad.zero_tangential = true;
  EXPECT_FALSE(bad.Check(&err));
  EXPECT_EQ(err, "distortion: auto chooses the distortion terms itself; remove zero_tangential "
                 "(or set distortion: given)");
  bad = opt;
  bad.solve.fix = {"k3"};
  EXPECT_FALSE(bad.Check(&err));
  EXPECT_EQ(err,
            "fix: 'k3' with distortion: auto (the selection decides the distortion terms: remove "
            "it from fix, or set distortion: given)");
}

}  // namespace
}  // namespace carmba
