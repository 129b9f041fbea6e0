// The closed-form start of a calibration (no OpenCV calibrateCamera): Zhang's homography method
// with the principal point held at the image centre (or the given one) and zero skew. Each view's
// homography H (plate mm -> pixel relative to the principal point, normalised DLT) gives two
// linear constraints on B = K^-T K^-1 = diag(1/fx^2, 1/fy^2, 1):
//   h1^T B h2 = 0,   h1^T B h1 - h2^T B h2 = 0
// solved for (b11, b22, b33) by SVD; then the poses follow from K^-1 H = lambda [r1 r2 t].
// Distortion starts at 0. If the views do not determine the focal lengths (e.g. all
// fronto-parallel: the b33 column vanishes) the initialisation fails with a clear error.
#pragma once

#include <array>
#include <vector>

#include "calib/calibrate.h"

namespace carmba {

struct CalibrationStart {
  std::array<double, kNumIntrinsics> intrinsics{};
  // fy = fy_over_fx * fx when the aspect ratio is held (the given ratio or the initial
  // estimate's), 0 otherwise: IntrinsicsGroup::fy_over_fx.
  double fy_over_fx = 0;
  std::vector<Pose6> cam_from_plate;  // rvec (rad), t (mm) per view
};

// The start for `obs` under `options` (their initial_intrinsics replace Zhang's; the held
// parameters are set to their held values). Errors name the view without a homography, or the
// degenerate geometry.
StatusOr<CalibrationStart> InitialiseCalibration(const ObservationSet& obs,
                                                 const CalibrationOptions& options);

}  // namespace carmba
