// Triangulation of a point seen in two or more object views of a solved bundle adjustment (an
// instrument tip, an unmatched blob, a marker left out of the solve), in the object (CT) frame,
// with a 3x3 covariance that includes the solve's uncertainty (poses, intrinsics, and through
// them the CT and plate sources) and the point's own pixel noise (issue 11).
//
// Estimate: X minimises sum_i (q_i(X) - z_i)^T W_i (q_i(X) - z_i) over the views i that see it,
// q_i(X) = project(intrinsics of view i's group, cam_i_from_object, X) with the calibrated
// OPENCV5 model (camera/camera_model.h), W_i = Sigma_i^-1 (the pixel covariance). Started from
// the rays' least-squares midpoint (pixels undistorted with the calibrated model), then
// Gauss-Newton in pixels.
//
// Covariance, first order (implicit function theorem at the optimum): with J_i = dq_i/dX (2x3),
// B_i = dq_i/dtheta over the free state theta (intrinsics and pose of view i), N = sum J_i^T W_i
// J_i,
//   dX = -N^-1 sum_i J_i^T W_i (B_i dtheta - dz_i),
//   C_X = N^-1  (the point's pixels)  +  G C_theta G^T,  G = -N^-1 sum_i J_i^T W_i B_i,
// the two independent (the point's pixels are not in the solve). C_theta is the engine's
// covariance (ba/covariance.h, G H^-1 G^T by one solve), scaled by the result's covariance_scale;
// the solve's part is split by noise source with the engine's error budget.
// Held intrinsics with a considered calibration covariance Sigma_c (a pose problem with
// camera.json's covariance): X depends on them directly (q_i uses them, Gc = -N^-1 sum_i J_i^T
// W_i dq_i/dc) and through the solve's estimate (D = dtheta/dc, ba/covariance.h), so
//   C_X += (G D + Gc) Sigma_c (G D + Gc)^T   (covariance_calibration, budget kCalibration).
//
// Self-check: the stacked pixel residuals r against their covariance M = Sigma (the pixels) +
// B C_theta B^T (the solve's, correlated between the views), the point's directions taken out:
// chi2 = min_dX (r + J dX)^T M^-1 (r + J dX) on 2n - 3 degrees of freedom. Outside its band (P <
// 0.5 %) with three or more rays, the ray whose removal leaves the smallest chi-square is rejected
// (its pixel is reported against the point the others give) and the point triangulated again, while
// at least three rays remain and the chi-square is out of band; a point whose rays still do not
// meet within their covariances is a warning.
//
// Warnings and errors: fewer than two views is an error ("seen in one view only"), as are a
// plate view, a view given twice, non-finite pixels, a pixel that cannot be undistorted, rays
// that meet behind a source and rays so parallel that N is singular. Rays closer than
// `min_ray_angle_deg` (the largest angle between any two rays) give a warning that says the angle.
#pragma once

#include <Eigen/Dense>
#include <array>
#include <string>
#include <vector>

#include "ba/bundle_adjuster.h"
#include "util/status.h"

namespace carmba {
namespace analysis {

struct PixelObservation {
  int view = 0;                       // problem view index (an object view)
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();
  Eigen::Matrix2d covariance_px2 = Eigen::Matrix2d::Identity();  // pixel covariance, px^2
};

struct TriangulationOptions {
  double min_ray_angle_deg = 5.0;   // warn when the widest pair of rays is closer than this
  double outlier_p = 0.005;         // chi-square tail below which the rays are inconsistent
  int max_iterations = 50;          // Gauss-Newton
  bool Check(std::string* error) const;
};

struct TriangulatedPoint {
  Eigen::Vector3d p_in_object = Eigen::Vector3d::Zero();   // mm, the solve's object frame
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();    // total, mm^2
  Eigen::Matrix3d covariance_pixels = Eigen::Matrix3d::Zero();  // N^-1: the point's own pixels
  Eigen::Matrix3d covariance_solve = Eigen::Matrix3d::Zero();   // G C_theta G^T (residuals)
  Eigen::Matrix3d covariance_calibration = Eigen::Matrix3d::Zero();  // considered calibration
  // Variance (trace, mm^2) of the solve's and the calibration's parts by noise source
  // (ba/problem.h Source order; kCalibration is covariance_calibration's trace).
  std::array<double, ba::kNumSources> solve_trace_by_source{};
  double max_ray_angle_deg = 0;     // widest angle between two of the rays
  // q_i(X) - z_i, per observation as given (rejected ones too, against the final point).
  std::vector<Eigen::Vector2d> residual_px;
  std::vector<char> rejected;       // per observation as given: 1 if rejected as an outlier
  double rms_px = 0;                // per coordinate, over the rays used
  double chi2 = 0;                  // of the rays used, whitened by their pixel covariances
  int dof = 0;                      // 2 x rays used - 3
  double chi2_p_value = 1;
  // One sentence each: nearly parallel rays, a rejected ray, rays that do not meet.
  std::vector<std::string> warnings;
};

// A point farther than this many times the markers' largest distance from their centroid is
// "far outside the markers" (a warning).
constexpr double kOutsideMarkersFactor = 2.0;

StatusOr<TriangulatedPoint> TriangulatePoint(const ba::BaProblem& problem,
                                             const ba::BaResult& result,
                                             const std::vector<PixelObservation>& observations,
                                             const TriangulationOptions& options = {});

}  // namespace analysis
}  // namespace carmba
