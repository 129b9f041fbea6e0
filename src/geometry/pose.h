// The one pose of carmba: a rigid transform target_from_source, p_in_target = R p_in_source + t
// (t in mm; camera/camera_model.h states the camera convention), in two forms:
//   Pose6   [rx, ry, rz (rad, Rodrigues rotation vector), tx, ty, tz]: the parameter form, as
//           the bundle-adjustment engine estimates it (ba/problem.h), calibration and pose
//           report it, and result files write it;
//   Rigid3  {R, t}: the matrix form, for applying and composing transforms (the simulator's
//           C-arm geometry, rigid fits of marker sets).
// Rigid3::FromPose and Rigid3::ToPose convert between them with geometry/rotation.h's Rodrigues
// conversions.
#pragma once

#include <Eigen/Core>

namespace carmba {

using Pose6 = Eigen::Matrix<double, 6, 1>;
using Matrix6 = Eigen::Matrix<double, 6, 6>;

struct Rigid3 {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();

  Eigen::Vector3d operator*(const Eigen::Vector3d& p) const { return R * p + t; }
  Rigid3 operator*(const Rigid3& b) const { return {R * b.R, R * b.t + t}; }
  Rigid3 Inverse() const { return {R.transpose(), -(R.transpose() * t)}; }

  // The rotation vector (rad) of R.
  Eigen::Vector3d Rvec() const;
  // [Rvec(), t].
  Pose6 ToPose() const;
  static Rigid3 FromRvec(const Eigen::Vector3d& rvec_rad, const Eigen::Vector3d& t_mm);
  static Rigid3 FromPose(const Pose6& pose);
};

}  // namespace carmba
