// Two dark blobs whose shadows touch (two beads a few px apart): the marker detector's half-peak
// region joins them and it rejects both as "merged" (detect/marker_blobs.h), because a centroid
// of either would be pulled by the other. FitBlobPair separates them by a least-squares fit of
// both at once in the image window around the merged region:
//   I(x, y) = b0 + bx dx + by dy - a1 g(x - c1) - a2 g(x - c2),  g(r) = exp(-|r|^2 / (2 s^2))
// (a plane of background, two Gaussian shadows of one width s), by Levenberg-Marquardt with the
// analytic Jacobian, started from the two darkest separated pixels of the lightly blurred window.
// Each centre's 2x2 covariance is the fit's: sigma^2 (J^T J)^-1 with sigma^2 the residual
// variance, times the image noise's correlation factor F (marker_blobs.h step 6): the model's
// misfit counts as noise, so a poor fit gives a wide covariance, not a confident wrong centre.
// Refused (nullopt, `why` says it): not two blobs (a single one, an edge), amplitudes below
// `min_contrast` of the background, centres closer than 0.5 or farther than 2.5 diameters, a width
// outside [0.1, 0.6] diameters, no convergence.
#pragma once

#include <opencv2/core.hpp>

#include <array>
#include <optional>
#include <string>

#include "detect/marker_blobs.h"

namespace carmba {

struct BlobPairFit {
  std::array<MarkerBlob, 2> blobs;
  double rms_grey = 0;    // residual RMS in the window (grey levels)
  int iterations = 0;
};

// `grey`: the image as float (CV_32F, 1 channel, X-ray polarity: metal dark); `centre`: the merged
// region's centre (px); `diameter_px`: one blob's expected diameter.
std::optional<BlobPairFit> FitBlobPair(const cv::Mat& grey, cv::Point2d centre, double diameter_px,
                                       double min_contrast, double correlation_factor,
                                       std::string* why = nullptr);

}  // namespace carmba
