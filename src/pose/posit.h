// POSIT (DeMenthon & Davis, "Model-based object pose in 25 lines of code", IJCV 1995):
// pose from four or more NON-coplanar points by iterating scaled orthographic projection.
//
// Two modes:
//  * kLegacy reproduces OpenCV 1.x's cvPOSIT exactly as the thesis used it: float32 arithmetic,
//    object points relative to the FIRST point (the reference), the I and J vectors normalised
//    separately and NOT made orthogonal, k = i x j. Its "rotation" rows are therefore slightly
//    non-orthonormal (0.5-2 degrees on the thesis's data). Stops when the image vectors change by
//    less than `epsilon` (image units) or after `max_iterations`.
//  * kOrthonormal works in double and replaces [i; j; i x j] by the nearest proper rotation at
//    every iteration, so it returns a rotation.
//
// Image coordinates are relative to the principal point, in the same unit as `focal_length`
// (pixels with the focal length in pixels, or normalised coordinates with focal_length = 1).
// The axes are whatever the caller's camera uses: the thesis passed x = u - cx, y = cy - v
// (y UP, a legacy convention); PositPose() below passes the OpenCV/mrcal convention (y down).
//
// Errors (never a pose): fewer than 4 points, mismatched sizes, non-finite input, (near-)coplanar
// object points (smallest/largest singular value of the reference-relative object vectors below
// `coplanarity_threshold`), no convergence, a solution behind the camera.
#pragma once

#include <Eigen/Dense>
#include <vector>

#include "camera/camera.h"
#include "util/status.h"

namespace carmba {

enum class PositMode { kLegacy, kOrthonormal };

struct PositOptions {
  PositMode mode = PositMode::kOrthonormal;
  // cvPOSIT's CV_TERMCRIT_ITER | CV_TERMCRIT_EPS as in the thesis's tutorial code.
  int max_iterations = 100;
  double epsilon = 1e-4;  // image units
  // Object points whose spread along the third principal axis is below this fraction of the
  // first are rejected as coplanar.
  double coplanarity_threshold = 1e-3;
  // In kOrthonormal mode, failing to reach `epsilon` within max_iterations is an error.
  bool require_convergence = true;

  bool Check(std::string* error) const;
};

struct PositResult {
  Eigen::Matrix3d R;  // rows i, j, k (cam_from_object; exactly orthonormal only in kOrthonormal)
  Eigen::Vector3d t;  // the reference point's (first object point's) position in the camera, so
                      // p_in_cam = R (p - p_0) + t
  int iterations = 0;
  bool converged = false;
};

StatusOr<PositResult> Posit(const std::vector<Eigen::Vector3d>& object_points,
                            const std::vector<Eigen::Vector2d>& image_points,
                            double focal_length,
                            const PositOptions& options);

// Pose cam_from_object = [rvec, t] from pixel observations with the full camera model: pixels
// are undistorted to normalised coordinates (UnprojectToNormalized), POSIT runs in kOrthonormal
// mode in those (scaled by sqrt(fx fy), so `epsilon` stays in pixels), and the translation is
// re-expressed for the object frame's origin: p_in_cam = R p_in_object + t.
StatusOr<Eigen::Matrix<double, 6, 1>> PositPose(const Camera& camera,
                                                const std::vector<Eigen::Vector3d>& p_in_object,
                                                const std::vector<Eigen::Vector2d>& uv_px,
                                                const PositOptions& options);

}  // namespace carmba
