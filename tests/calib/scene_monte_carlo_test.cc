// Seeded Monte Carlo of the calibration on the shipped simulator scenes' geometry (true projected
// sphere centres + Gaussian pixel noise): does the spread of fx, fy, cx, cy over the trials match
// the sigmas each trial reports?
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <vector>

#include "calib/calibrate.h"
#include "calib/conditioning.h"
#include "figures.h"
#include "scene_test_util.h"
#include "synthetic/synthetic_views.h"

namespace carmba {
namespace {

struct McResult {
  std::array<double, 4> spread{};         // sample standard deviation over the trials
  std::array<double, 4> at_truth{};       // sigma of the noise-free solve (covariance at the truth)
  std::array<double, 4> rms_reported{};   // RMS of the per-trial reported sigmas
  std::array<double, 4> min_reported{}, max_reported{};
};

McResult RunMonteCarlo(const ObservationSet& clean, CalibrationOptions opt, int trials,
                       double noise_px) {
  McResult m;
  opt.pixel_sigma_px = noise_px;
  auto at_truth = Calibrate(clean, opt);
  EXPECT_TRUE(at_truth.ok()) << at_truth.status().message();
  std::array<double, 4> sum{}, sum2{}, rep2{};
  m.min_reported.fill(1e300);
  for (int t = 0; t < trials; ++t) {
    auto r = Calibrate(AddNoise(clean, noise_px, 500 + t), opt);
    EXPECT_TRUE(r.ok()) << r.status().message();
    if (!r.ok()) continue;
    for (int i = 0; i < 4; ++i) {
      const double d = r->camera.params[i] - at_truth->camera.params[i];
      sum[i] += d, sum2[i] += d * d, rep2[i] += r->sigma[i] * r->sigma[i];
      m.min_reported[i] = std::min(m.min_reported[i], r->sigma[i]);
      m.max_reported[i] = std::max(m.max_reported[i], r->sigma[i]);
    }
  }
  for (int i = 0; i < 4; ++i) {
    const double mean = sum[i] / trials;
    m.spread[i] = std::sqrt((sum2[i] - trials * mean * mean) / (trials - 1));
    m.at_truth[i] = at_truth->sigma[i];
    m.rms_reported[i] = std::sqrt(rep2[i] / trials);
  }
  return m;
}

void Print(const std::string& what, const McResult& m) {
  for (int i = 0; i < 4; ++i) {
    std::cout << what << " " << kIntrinsicNames[i] << ": spread " << m.spread[i]
              << ", spread / sigma at truth " << m.spread[i] / m.at_truth[i]
              << ", spread / RMS reported " << m.spread[i] / m.rms_reported[i] << " (reported "
              << m.min_reported[i] << " .. " << m.max_reported[i] << ")\n";
  }
}

// The range of spread / RMS reported sigma over the intrinsics `which` of `ms` (results.md).
void RecordRatioRange(const std::string& key,
                      const std::vector<McResult>& ms,
                      std::initializer_list<int> which) {
  double lo = 1e300, hi = 0;
  for (const McResult& m : ms) {
    for (int i : which) {
      lo = std::min(lo, m.spread[i] / m.rms_reported[i]);
      hi = std::max(hi, m.spread[i] / m.rms_reported[i]);
    }
  }
  testing::RecordFigure(key, "%.2f-%.2fx", lo, hi);
}

// 200 trials: the sample standard deviation of 200 draws is itself uncertain by 1/sqrt(2 * 199) =
// 5 %, so 15 % (the bound) is a 3-sigma test.
constexpr int kSceneTrials = 200;
constexpr double kSceneSigmaRelTol = 0.15;
// The scenes' images give detection errors of 0.032 px (thesis) and 0.017 px (pincushion) RMS
// against the truth (tests/detect/simulated_scene_test.cc); 0.03 px covers both.
constexpr double kSceneNoisePx = 0.03;
// What OpenCV's blob centres on real intensifier images give (and what the older tests used).
constexpr double kCoarseNoisePx = 0.3;

const char* const kScenes[] = {"thesis_calibration", "calib_7x6_pincushion"};

void ExpectMatches(const std::string& what, const McResult& m, std::initializer_list<int> which) {
  for (int i : which) {
    EXPECT_NEAR(m.spread[i] / m.at_truth[i], 1.0, kSceneSigmaRelTol)
        << what << " " << kIntrinsicNames[i];
    EXPECT_NEAR(m.spread[i] / m.rms_reported[i], 1.0, kSceneSigmaRelTol)
        << what << " " << kIntrinsicNames[i];
  }
}

TEST(SceneMonteCarlo, FullModelAtTheScenesDetectionNoise) {
  std::vector<McResult> ms;
  // Free OPENCV5 (all nine intrinsics) at the noise the scenes' images give: the problem is close
  // to linear over the noise's reach, and every trial's sigmas are honest. Measured: spread /
  // reported 0.99-1.08 (thesis), 0.95-1.03 (pincushion).
  for (const char* name : kScenes) {
    const McResult m = RunMonteCarlo(SceneTruthObservations(LoadShippedScene(name)),
                                     CalibrationOptions(), kSceneTrials, kSceneNoisePx);
    Print(std::string(name) + " OPENCV5, 0.03 px", m);
    ExpectMatches(name, m, {0, 1, 2, 3});
    ms.push_back(m);
  }
  RecordRatioRange("calibmc.full_fine", ms, {0, 1, 2, 3});
  testing::RecordFigure("calibmc.trials", "%d", kSceneTrials);
}

TEST(SceneMonteCarlo, TangentialAndK3HeldAtCoarseNoise) {
  std::vector<McResult> ms;
  // At 0.3 px the free tangential terms make the principal point non-linear (next test). With
  // p1 = p2 = 0 and k3 = 0 held (the thesis's zero-tangential and fixed-k3 settings; the principal
  // point and focal lengths free) every trial's sigmas match the spread again: measured 1.03-1.05
  // (thesis). The pincushion scene's small true p1, p2 (< 0.05 px at the corners) are then absorbed
  // by the other parameters; this tests the covariance against the spread, not the bias.
  for (const char* name : kScenes) {
    CalibrationOptions opt;
    opt.zero_tangential = true;
    opt.fix_k3 = true;
    const McResult m = RunMonteCarlo(
        SceneTruthObservations(LoadShippedScene(name)), opt, kSceneTrials, kCoarseNoisePx);
    Print(std::string(name) + " p1 = p2 = k3 = 0, 0.3 px", m);
    ExpectMatches(name, m, {0, 1, 2, 3});
    ms.push_back(m);
  }
  RecordRatioRange("calibmc.radial_coarse", ms, {0, 1, 2, 3});
}

TEST(SceneMonteCarlo, FreeTangentialAtCoarseNoiseIsNonlinearNotACovarianceBug) {
  std::vector<McResult> ms;
  // FINDING (documented, asserted so that a change shows): free OPENCV5 at 0.3 px on these narrow
  // fields of view (11-13 deg). The tangential terms p1, p2 act on the image almost like a shift
  // of the principal point, so cx, cy lie in a long curved valley of the cost; each trial's
  // covariance, evaluated where that trial landed in the valley, differs by a factor ~4-6 in the
  // sigma of cx, cy (thesis: 4.0 .. 26.5 px), and their RMS is 1.5-1.8x below the spread; the
  // estimates are not Gaussian either (thesis cx: spread 0.77x the sigma at the truth).
  // Not a covariance bug: the same code on the same geometry is honest at 0.03 px (first test,
  // the linearisation then holds over the noise's reach) and at 0.3 px with p1, p2 held (second
  // test); holding only k2 and k3 does not cure it (1.14-1.26x). fx, fy stay honest throughout.
  for (const char* name : kScenes) {
    const McResult m = RunMonteCarlo(SceneTruthObservations(LoadShippedScene(name)),
                                     CalibrationOptions(), kSceneTrials, kCoarseNoisePx);
    Print(std::string(name) + " OPENCV5, 0.3 px", m);
    ExpectMatches(name, m, {0, 1});
    for (int i : {2, 3}) {
      EXPECT_GT(m.max_reported[i] / m.min_reported[i], 2.0) << name << " " << kIntrinsicNames[i];
    }
    EXPECT_GT(std::max(m.spread[2] / m.rms_reported[2], m.spread[3] / m.rms_reported[3]),
              1.0 + kSceneSigmaRelTol)
        << name;
    ms.push_back(m);
  }
  RecordRatioRange("calibmc.full_coarse_pp", ms, {2, 3});
}

TEST(SceneMonteCarlo, ConditioningWarningWhereTheSigmasAreNotHonest) {
  // The report's warning (calib/conditioning.h) fires exactly in the regime the Monte Carlo tests
  // above find dishonest: free OPENCV5 at 0.3 px, not at 0.03 px, not with p1 = p2 = k3 = 0 held.
  for (const char* name : kScenes) {
    const sim::XrayScene scene = LoadShippedScene(name);
    const ObservationSet clean = SceneTruthObservations(scene);
    auto warnings = [&](double noise, bool hold) {
      CalibrationOptions opt;
      opt.pixel_sigma_px = noise;
      opt.zero_tangential = opt.fix_k3 = hold;
      auto r = Calibrate(clean, opt);
      EXPECT_TRUE(r.ok());
      const ConditioningReport c = AssessConditioning(*r, clean.width, clean.height);
      // The principal-point warnings (correlations beyond 0.99, fx-fy on these narrow views,
      // are warned about in every regime and are tested in conditioning_test.cc).
      size_t n = 0;
      for (const auto& w : c.warnings) {
        std::cout << name << " " << noise << " px: " << w << "\n";
        n += w.find(" correlate at ") == std::string::npos;
      }
      return n;
    };
    EXPECT_GT(warnings(kCoarseNoisePx, false), 0u) << name;
    EXPECT_EQ(warnings(kSceneNoisePx, false), 0u) << name;
    EXPECT_EQ(warnings(kCoarseNoisePx, true), 0u) << name;
  }
}

}  // namespace
}  // namespace carmba
