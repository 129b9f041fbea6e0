// Projection uncertainty of a calibration, mrcal's definition: the point p_cam = d * unproject(q)
// is fixed in the frame averaged over the plate poses,
//   q(theta) = project(intrinsics, mean_i T_i(theta) T_i0^-1 p_cam),
// and Cov(q) = G H^-1 G^T with G = dq/dtheta over the engine's free state, by the engine's Schur
// covariance (SchurCovariance::Solve), scaled to the result's sigma_px.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "calib/calibrate.h"

namespace carmba {

// Pixel (u_px, v_px) at distance_mm for a solved calibration of `observations`. Errors: no
// covariance, observations that are not the calibration's, a pixel that cannot be unprojected.
StatusOr<ProjectionSigma> ProjectionUncertainty(const ObservationSet& observations,
                                                const CalibrationResult& result,
                                                double u_px,
                                                double v_px,
                                                double distance_mm);

// The same for many pixels at once; a pixel that cannot be unprojected gets NaN sigmas.
StatusOr<std::vector<ProjectionSigma>> ProjectionUncertainties(
    const ObservationSet& observations,
    const CalibrationResult& result,
    const std::vector<Eigen::Vector2d>& pixels,
    double distance_mm);

// The uncertainty at the image centre and its four corners ("centre", "top-left", ...) at
// `distance_mm` (0: the median plate distance), into result->projection_sigma and
// result->uncertainty_distance_mm. A corner that cannot be unprojected is left out.
void ProjectionSigmaAtCentreAndCorners(int width, int height, double distance_mm,
                                       CalibrationResult* result);

}  // namespace carmba
