// The mrcal and OpenCV cross-checks on synthetic observations: mrcal (same problem) must agree
// with carmba's solution, its covariance and its projection; OpenCV must reach the same optimum.
#include "calib/crosscheck.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>

#include "synthetic/synthetic_views.h"
#include "util/file_util.h"
#include "scratch.h"

namespace carmba {
namespace {

const std::array<double, kNumIntrinsics> kCrosscheckTruth = {2061.4, 2254.6, 203.7, 205.1, -0.3,
                                                   2.0,    0.0005, -0.0003, 0.0};

TEST(CrossCheckTest, EmbeddedScriptMatchesFile) {
  auto text = ReadFile(std::string(CARMBA_SOURCE_DIR) + "/scripts/mrcal_crosscheck.py");
  ASSERT_TRUE(text.ok());
  EXPECT_EQ(*text, std::string(MrcalCrossCheckScript()))
      << "re-run cmake: the embedded script is generated from scripts/mrcal_crosscheck.py";
}

class CrossCheck : public ::testing::Test {
 protected:
  void SetUp() override {
    SyntheticViewsOptions so;
    so.seed = 21;
    so.noise_sigma_px = 0.3;
    GridSpec g;
    obs_ = MakeSyntheticViews(kCrosscheckTruth, 408, 408, g, so);
    auto r = Calibrate(obs_, CalibrationOptions());
    ASSERT_TRUE(r.ok()) << r.status().message();
    result_ = *r;
  }
  ObservationSet obs_;
  CalibrationResult result_;
};

TEST_F(CrossCheck, MrcalAgrees) {
  // The acceptance thresholds.
  constexpr double kRmsRelTol = 0.01;
  constexpr double kProjectionDiffPx = 0.05;
  constexpr double kSigmaRelTol = 0.10;
  MrcalCrossCheckOptions mo;
  const test::ScratchDir work("crosscheck_test");  // kept with CARMBA_KEEP_TMP set
  mo.work_dir = work.path();
  auto m = RunMrcalCrossCheck(obs_, result_, {{"truth", kCrosscheckTruth}}, mo);
  ASSERT_TRUE(m.ok()) << m.status().message();
  const double mrms = (*m)["rms_px"].get<double>();
  EXPECT_NEAR(result_.rms_px / mrms, 1.0, kRmsRelTol);
  EXPECT_LT((*m)["projection_diff"]["mrcal"]["rms_px"].get<double>(), kProjectionDiffPx);
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(result_.sigma[i] / (*m)["sigma"][i].get<double>(), 1.0, kSigmaRelTol)
        << kIntrinsicNames[i];
  }
  // mrcal's uncertainty formula at our solution equals ours (same definition, same sigma).
  constexpr double kUncertaintyRelTol = 0.02;
  const auto& mu = (*m)["projection_uncertainty_carmba_solution"];
  ASSERT_EQ(mu.size(), result_.projection_sigma.size());
  for (size_t i = 0; i < mu.size(); ++i) {
    EXPECT_NEAR(result_.projection_sigma[i].worst_px / mu[i]["worst_px"].get<double>(), 1.0,
                kUncertaintyRelTol)
        << result_.projection_sigma[i].where;
  }
}

TEST_F(CrossCheck, OpenCvReachesTheSameOptimum) {
  auto ref = RunOpenCvCalibration(obs_, CalibrationOptions(), result_);
  ASSERT_TRUE(ref.ok()) << ref.status().message();
  EXPECT_TRUE(ref->equivalent);
  EXPECT_NEAR(ref->rms_returned_px, std::sqrt(2.0) * ref->rms_px, 1e-12);
  // Same least-squares problem: the RMS agrees closely (OpenCV's LM stops a little earlier).
  constexpr double kRmsRelTol = 0.01;
  EXPECT_NEAR(result_.rms_px / ref->rms_px, 1.0, kRmsRelTol);
}

}  // namespace
}  // namespace carmba
