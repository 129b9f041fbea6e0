// The calibration against a known truth (simulator truth.json or a reference camera.json): for a
// grid of pixels q, the TRUE ray of q (unprojected with the true intrinsics) is projected with the
// estimate; the difference to q, per coordinate, is divided by its 1-sigma from the intrinsics'
// covariance (marginal over the plate poses): Cov(q) = J_q Cov(theta) J_q^T with J_q the
// Jacobian of the projection with respect to the intrinsics.
//
// Both cameras share the camera frame (the same physical detector), so no transform is fitted:
// a fitted rotation (mrcal.projection_diff) absorbs part of a principal-point error and, in a
// narrow field of view, is itself uncertain at the 0.01 px level, which is more than the
// projection sigma of a good calibration.
#pragma once

#include <string>

#include "calib/calibrate.h"
#include "camera/camera.h"
#include "detect/observations.h"

namespace carmba {

struct TruthCheckRegion {
  int num_pixels = 0;          // grid pixels compared (inside the region, projectable)
  double max_sigmas = 0;       // largest |estimate - truth| / sigma, per coordinate
  double fraction_within_3_sigma = 0;
  double rms_diff_px = 0;      // of the 2-D difference
  double max_diff_px = 0;
  std::string worst;           // "pixel (u, v) u: error E px, sigma S px"
};

struct TruthCheck {
  TruthCheckRegion image;      // a grid over the whole image
  TruthCheckRegion observed;   // the grid pixels inside the convex hull of the detections
};

// `grid` pixels per side. Error when the estimate has no covariance (all intrinsics fixed) or
// the truth's image size differs.
StatusOr<TruthCheck> CompareWithTruth(const CalibrationResult& result,
                                      const Camera& truth,
                                      const ObservationSet& observations,
                                      int grid = 21);

}  // namespace carmba
