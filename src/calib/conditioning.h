// Warnings about what a calibration's data determine poorly, for the report.
//
// The covariance of the intrinsics is a linearisation at the solution. On a narrow field of view
// (a C-arm's ~11 deg) the principal point is pinned only by the perspective of tilted plates and by
// the distortion centre; the tangential terms p1, p2 act almost like a principal-point shift. When
// the principal point's sigma is a sizeable part of the image, the cost along that valley is no
// longer quadratic over the noise's reach and the per-solve sigmas of cx, cy understate the real
// spread. Measured with a seeded Monte Carlo on the shipped scenes' geometry
// (tests/calib/scene_monte_carlo_test.cc): at 0.03 px noise (sigma cx ~2.5 px, 0.6 % of the
// image) the sigmas are honest within 8 %; at 0.3 px with p1, p2 free (sigma cx ~20-27 px, 5-6 %)
// they are 1.5-1.8x too small and vary 4-6x between trials; holding p1 = p2 = k3 = 0 brings them
// back within 5 %.
#pragma once

#include <string>
#include <vector>

#include "calib/calibrate.h"

namespace carmba {

// A principal-point sigma above this fraction of the image size triggers the warning (the Monte
// Carlo above: honest at 0.6 %, not at 5 %).
constexpr double kPrincipalPointSigmaWarnFraction = 0.02;

// Two intrinsics whose estimates correlate beyond this (in absolute value) are reported: the data
// determine little more than one combination of them, and their separate sigmas are large and
// unstable (mrcal and OpenCV users know it as fx-fy, cx-p1, k1-k2-k3 in a narrow field of view).
constexpr double kIntrinsicsCorrelationWarn = 0.99;

// One sentence per pair (i < j) of intrinsics in `covariance` (9 x 9, kIntrinsicNames order; a
// held parameter has zero variance and is skipped) whose |correlation| exceeds
// kIntrinsicsCorrelationWarn, strongest first, e.g. "k1 and k3 correlate at -0.9987 (|r| > 0.99):
// ...". `group` (optional) prefixes the names ("c-arm: k1 and k3 ...").
std::vector<std::string> IntrinsicsCorrelationWarnings(const Eigen::MatrixXd& covariance,
                                                       const std::string& group = "");

struct ConditioningReport {
  // One sentence each, empty when none: weakly determined principal point, intrinsics that
  // correlate above kIntrinsicsCorrelationWarn.
  std::vector<std::string> warnings;
  // The largest |correlation| between a principal-point coordinate and a distortion term, and
  // the pair's names ("cy-p2"); 0 and "" when none is free.
  double max_pp_distortion_correlation = 0;
  std::string max_pp_distortion_pair;
};

ConditioningReport AssessConditioning(const CalibrationResult& result, int width, int height);

}  // namespace carmba
