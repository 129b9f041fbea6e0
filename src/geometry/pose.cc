#include "geometry/pose.h"

#include "geometry/rotation.h"

namespace carmba {

Eigen::Vector3d Rigid3::Rvec() const { return RvecFromRotation(R); }

Pose6 Rigid3::ToPose() const {
  Pose6 p;
  p.head<3>() = Rvec();
  p.tail<3>() = t;
  return p;
}

Rigid3 Rigid3::FromRvec(const Eigen::Vector3d& rvec_rad, const Eigen::Vector3d& t_mm) {
  return {RotationOf(rvec_rad), t_mm};
}

Rigid3 Rigid3::FromPose(const Pose6& pose) { return FromRvec(pose.head<3>(), pose.tail<3>()); }

}  // namespace carmba
