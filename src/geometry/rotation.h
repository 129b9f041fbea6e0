// Rotations and the validation metrics between views.
//
// A pose cam_from_object is [rx, ry, rz, tx, ty, tz]: p_in_cam = R(r) p_in_object + t, r a
// rotation vector in radians, t in mm (camera/camera_model.h).
//
// Metrics between two views a and b (thesis Table 5.6 and better):
//   * ViewDirectionAngle: the thesis's angle between the viewing directions expressed in the
//     object frame, v = inv(R) (0,0,1) = third row of R, angle = acos(v_a . v_b). It equals the
//     C-arm rotation only when the rotation axis is perpendicular to the viewing direction.
//   * RelativeRotationAngle: the angle of R_a^T R_b (the rotation taking view a's camera to view
//     b's), computed as atan2(|vee(M - M^T)| / 2, (trace(M) - 1) / 2) which is accurate at all
//     angles (acos of the trace loses precision near 0 and 180 degrees).
// Both are templates so that ceres::Jet gives their derivatives for covariance propagation.
#pragma once

#include <ceres/jet.h>
#include <ceres/rotation.h>

#include <Eigen/Dense>
#include <cmath>

namespace carmba {

constexpr double kPi = 3.14159265358979323846;
constexpr double kRadToDeg = 180.0 / kPi;
constexpr double kDegToRad = kPi / 180.0;

// The rotation matrix of a rotation vector (rad; the first three entries of a Pose6).
inline Eigen::Matrix3d RotationOf(const double* rvec) {
  Eigen::Matrix3d R;
  ceres::AngleAxisToRotationMatrix(rvec, ceres::ColumnMajorAdapter3x3(R.data()));
  return R;
}
inline Eigen::Matrix3d RotationOf(const Eigen::Vector3d& rvec) { return RotationOf(rvec.data()); }

// The left Jacobian J_l(r) of SO(3) (3x3 row-major into `J`): exp(r + d) ~= exp(J_l(r) d) exp(r).
// It maps a change of the rotation vector to a small rotation of the camera frame; used to turn
// covariances of rvec into covariances of small rotation angles.
//   J_l(r) = I + (1 - cos t)/t^2 [r]_x + (t - sin t)/t^3 [r]_x^2,  t = |r|.
void SO3LeftJacobian(const double* rvec, double* J);
Eigen::Matrix3d SO3LeftJacobian(const double* rvec);

// R(r) p for a rotation vector r, and the derivative of R(r) p with respect to r (3x3 row-major;
// may be null): d(R(r) p)/dr = -[R(r) p]_x J_l(r).
void RotatePointWithJac(const double* rvec, const double* p, double* Rp, double* J_Rp_r);

template <typename T>
T ViewDirectionAngle(const T* pose_a, const T* pose_b) {
  using std::atan2;
  using std::sqrt;
  T Ra[9], Rb[9];
  ceres::AngleAxisToRotationMatrix(pose_a, ceres::RowMajorAdapter3x3(Ra));
  ceres::AngleAxisToRotationMatrix(pose_b, ceres::RowMajorAdapter3x3(Rb));
  // third rows; angle via atan2(|a x b|, a . b)
  const T* va = Ra + 6;
  const T* vb = Rb + 6;
  const T c0 = va[1] * vb[2] - va[2] * vb[1];
  const T c1 = va[2] * vb[0] - va[0] * vb[2];
  const T c2 = va[0] * vb[1] - va[1] * vb[0];
  const T dot = va[0] * vb[0] + va[1] * vb[1] + va[2] * vb[2];
  return atan2(sqrt(c0 * c0 + c1 * c1 + c2 * c2), dot);
}

template <typename T>
T RelativeRotationAngle(const T* pose_a, const T* pose_b) {
  using std::atan2;
  using std::sqrt;
  T Ra[9], Rb[9];
  ceres::AngleAxisToRotationMatrix(pose_a, ceres::RowMajorAdapter3x3(Ra));
  ceres::AngleAxisToRotationMatrix(pose_b, ceres::RowMajorAdapter3x3(Rb));
  T M[9];  // Ra^T Rb
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      M[3 * i + j] = Ra[i] * Rb[j] + Ra[3 + i] * Rb[3 + j] + Ra[6 + i] * Rb[6 + j];
    }
  }
  const T s0 = M[7] - M[5], s1 = M[2] - M[6], s2 = M[3] - M[1];
  const T sin_t = sqrt(s0 * s0 + s1 * s1 + s2 * s2) / T(2);
  const T cos_t = (M[0] + M[4] + M[8] - T(1)) / T(2);
  return atan2(sin_t, cos_t);
}

// A metric of two poses (ViewDirectionAngle, RelativeRotationAngle, ...) and its gradient with
// respect to their 12 parameters (a's six, then b's), by ceres::Jet: for covariance propagation.
template <typename F>
double PairMetricWithGradient(const double* pose_a, const double* pose_b, F f, double* grad12) {
  using J = ceres::Jet<double, 12>;
  J pa[6], pb[6];
  for (int i = 0; i < 6; ++i) {
    pa[i] = J(pose_a[i], i);
    pb[i] = J(pose_b[i], 6 + i);
  }
  const J v = f(pa, pb);
  for (int i = 0; i < 12; ++i) grad12[i] = v.v[i];
  return v.a;
}

// Angle (rad) between inv(Ra)(0,0,1) and inv(Rb)(0,0,1) for general 3x3 matrices (the thesis's
// POSIT matrices are not exactly orthonormal: it inverted them as printed). The vectors are
// normalised before the angle is taken.
double ViewDirectionAngleOfMatrices(const Eigen::Matrix3d& Ra, const Eigen::Matrix3d& Rb);

// The rotation vector of a proper rotation (|r| <= pi).
Eigen::Vector3d RvecFromRotation(const Eigen::Matrix3d& R);
// The proper rotation closest to M in the Frobenius norm (SVD, det forced to +1).
Eigen::Matrix3d NearestRotation(const Eigen::Matrix3d& M);
// Largest deviation from orthonormality, max |M^T M - I|.
double OrthonormalityError(const Eigen::Matrix3d& M);
// Angle (rad) of Ra^T Rb for proper rotations.
double AngleBetweenRotations(const Eigen::Matrix3d& Ra, const Eigen::Matrix3d& Rb);

}  // namespace carmba
