// The C-arm camera model: a pinhole with OpenCV's five-coefficient distortion.
//
// CONVENTION (stated once, used everywhere; OpenCV and mrcal use the same):
//   * Camera frame: x right, y down, z from the X-ray source (the centre of projection) towards
//     the detector. A point is in front of the source when z > 0.
//   * Pixel (0,0) is the CENTRE of the top-left pixel; u grows to the right, v downwards.
//   * Intrinsics in mrcal LENSMODEL_OPENCV5 order:
//       params = [fx, fy, cx, cy, k1, k2, p1, p2, k3]      (px, px, px, px, -, -, -, -, -)
//   * Projection of p_in_cam = (X, Y, Z):
//       x = X/Z, y = Y/Z, r2 = x^2 + y^2
//       a = 1 + k1 r2 + k2 r2^2 + k3 r2^3
//       xd = x a + 2 p1 x y + p2 (r2 + 2 x^2)
//       yd = y a + p1 (r2 + 2 y^2) + 2 p2 x y
//       u = fx xd + cx,   v = fy yd + cy
//   * Poses are `cam_from_object` = (rvec, t): p_in_cam = R(rvec) p_in_object + t, rvec a
//     Rodrigues rotation vector (radians), t in mm.
//
// Legacy conventions (the thesis's y-up POSIT image coordinates, DICOM positioner angles) are
// converted to this one at the boundary only.
//
// Each function comes as a `template <typename T>` (runs on double and ceres::Jet, the autodiff
// twin) and a double-only `...WithJac` kernel writing row-major Jacobians J_out_in.
#pragma once

#include <ceres/rotation.h>

#include <cmath>

namespace carmba {

constexpr int kNumIntrinsics = 9;  // fx, fy, cx, cy, k1, k2, p1, p2, k3
constexpr int kNumPoseParams = 6;  // rx, ry, rz (rad), tx, ty, tz (mm)

enum IntrinsicIndex { kFx = 0, kFy, kCx, kCy, kK1, kK2, kP1, kP2, kK3 };

// Projects a point given in the camera frame. Returns false if the point is not in front of the
// source (Z <= 0) or the input is not finite.
template <typename T>
bool ProjectCamPoint(const T* intrinsics, const T* p_in_cam, T* uv) {
  using std::isfinite;
  if (!(p_in_cam[2] > T(0))) return false;
  const T x = p_in_cam[0] / p_in_cam[2];
  const T y = p_in_cam[1] / p_in_cam[2];
  const T r2 = x * x + y * y;
  const T& k1 = intrinsics[kK1];
  const T& k2 = intrinsics[kK2];
  const T& p1 = intrinsics[kP1];
  const T& p2 = intrinsics[kP2];
  const T& k3 = intrinsics[kK3];
  const T a = T(1) + r2 * (k1 + r2 * (k2 + r2 * k3));
  const T xd = x * a + T(2) * p1 * x * y + p2 * (r2 + T(2) * x * x);
  const T yd = y * a + p1 * (r2 + T(2) * y * y) + T(2) * p2 * x * y;
  uv[0] = intrinsics[kFx] * xd + intrinsics[kCx];
  uv[1] = intrinsics[kFy] * yd + intrinsics[kCy];
  return true;
}

// Projects p_in_object through the pose cam_from_object = (rvec, t) = pose[0..5].
template <typename T>
bool ProjectPoint(const T* intrinsics, const T* pose, const T* p_in_object, T* uv) {
  T p_in_cam[3];
  ceres::AngleAxisRotatePoint(pose, p_in_object, p_in_cam);
  p_in_cam[0] += pose[3];
  p_in_cam[1] += pose[4];
  p_in_cam[2] += pose[5];
  return ProjectCamPoint(intrinsics, p_in_cam, uv);
}

// Analytic kernel: projection of a camera-frame point with
//   J_uv_intrinsics (2x9, row-major) and J_uv_p_in_cam (2x3). Either Jacobian may be null.
bool ProjectCamPointWithJac(const double* intrinsics,
                            const double* p_in_cam,
                            double* uv,
                            double* J_uv_intrinsics,
                            double* J_uv_p_in_cam);

// Analytic kernel: projection through a pose with J_uv_intrinsics (2x9), J_uv_pose (2x6, order
// rx ry rz tx ty tz) and J_uv_p_in_object (2x3). Any Jacobian may be null.
bool ProjectPointWithJac(const double* intrinsics,
                         const double* pose,
                         const double* p_in_object,
                         double* uv,
                         double* J_uv_intrinsics,
                         double* J_uv_pose,
                         double* J_uv_p_in_object);

// Undistorts a pixel: returns the normalised pinhole coordinates (x, y) = (X/Z, Y/Z) whose
// projection is `uv`, by Gauss-Newton from the undistorted guess. Returns false if it does not
// converge to 1e-9 px (strong distortion far outside the calibrated field).
bool UnprojectToNormalized(const double* intrinsics, const double* uv, double* xy);
// The same Gauss-Newton started from `seed_xy` (e.g. the solution of a nearby pixel), at most
// `max_iterations` steps. UnprojectToNormalized is this from the undistorted guess with 50 steps.
bool UnprojectToNormalizedFrom(const double* intrinsics,
                               const double* uv,
                               const double* seed_xy,
                               int max_iterations,
                               double* xy);

}  // namespace carmba
