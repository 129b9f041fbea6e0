// The one pose type of carmba: a rigid transform target_from_source as
// [rx, ry, rz (rad, Rodrigues rotation vector), tx, ty, tz (mm)], p_in_target = R(r) p + t
// (camera/camera_model.h states the camera convention). Used by calibration (cam_from_plate),
// pose (cam_from_object) and the bundle-adjustment engine (ba/problem.h).
#pragma once

#include <Eigen/Core>

namespace carmba {

using Pose6 = Eigen::Matrix<double, 6, 1>;
using Matrix6 = Eigen::Matrix<double, 6, 6>;

}  // namespace carmba
