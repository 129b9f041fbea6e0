// calib/conditioning.h: intrinsics that correlate beyond 0.99 are a warning (never "No warnings").
#include <gtest/gtest.h>

#include <Eigen/Core>

#include "calib/conditioning.h"

namespace carmba {
namespace {

// A 9 x 9 covariance with unit sigmas for the free parameters (`held`: zero row and column) and
// correlation `r` between parameters a and b.
Eigen::MatrixXd Covariance(int a, int b, double r, std::vector<int> held = {}) {
  Eigen::MatrixXd c = Eigen::MatrixXd::Identity(kNumIntrinsics, kNumIntrinsics);
  c(a, b) = c(b, a) = r;
  for (int h : held) {
    c.row(h).setZero();
    c.col(h).setZero();
  }
  return c;
}

TEST(IntrinsicsCorrelation, AboveThresholdIsAWarningBelowIsNot) {
  auto w = IntrinsicsCorrelationWarnings(Covariance(kFx, kFy, 0.9950));
  ASSERT_EQ(w.size(), 1u);
  EXPECT_EQ(w[0].rfind("fx and fy correlate at 0.9950 (|r| > 0.99): ", 0), 0u) << w[0];
  EXPECT_NE(w[0].find("add views that separate them"), std::string::npos) << w[0];
  // Negative correlation counts by its magnitude; a distortion term gets the advice to hold it.
  w = IntrinsicsCorrelationWarnings(Covariance(kCy, kP1, -0.9984), "c-arm");
  ASSERT_EQ(w.size(), 1u);
  EXPECT_EQ(w[0].rfind("c-arm: cy and p1 correlate at -0.9984", 0), 0u) << w[0];
  EXPECT_NE(w[0].find("hold the distortion term"), std::string::npos) << w[0];
  EXPECT_TRUE(IntrinsicsCorrelationWarnings(Covariance(kFx, kFy, 0.9899)).empty());
  EXPECT_TRUE(IntrinsicsCorrelationWarnings(Covariance(kK1, kK3, -0.98)).empty());
  // A held parameter (zero variance) is never part of a pair.
  EXPECT_TRUE(IntrinsicsCorrelationWarnings(Covariance(kK1, kK3, 0.999, {kK3})).empty());
}

TEST(IntrinsicsCorrelation, StrongestFirst) {
  Eigen::MatrixXd c = Covariance(kFx, kFy, 0.993);
  c(kK1, kK2) = c(kK2, kK1) = -0.9995;
  const auto w = IntrinsicsCorrelationWarnings(c);
  ASSERT_EQ(w.size(), 2u);
  EXPECT_EQ(w[0].rfind("k1 and k2", 0), 0u) << w[0];
  EXPECT_EQ(w[1].rfind("fx and fy", 0), 0u) << w[1];
}

// AssessConditioning (the report's Conditioning section) carries them: with such a pair the
// report cannot say "No warnings".
TEST(IntrinsicsCorrelation, ConditioningReportIncludesThem) {
  CalibrationResult r;
  r.free.assign(kNumIntrinsics, true);
  Eigen::MatrixXd c = Covariance(kFx, kFy, 0.995) * 4.0;  // sigma 2 px
  r.covariance = c;
  for (int i = 0; i < kNumIntrinsics; ++i) r.sigma[i] = 2.0;  // cx, cy well determined
  ConditioningReport rep = AssessConditioning(r, 1000, 1000);
  ASSERT_EQ(rep.warnings.size(), 1u);
  EXPECT_EQ(rep.warnings[0].rfind("fx and fy correlate", 0), 0u);
  r.covariance = Covariance(kFx, kFy, 0.5) * 4.0;
  rep = AssessConditioning(r, 1000, 1000);
  EXPECT_TRUE(rep.warnings.empty());
}

}  // namespace
}  // namespace carmba
