// result.json's views and validation pairs, written by one writer for every problem kind: the
// front ends' solutions (pose: report/pose_json.cc; joint: report/joint_report.cc) fill records,
// and these functions write the keys, so that a view or a pair has the same keys in every
// result.json.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "geometry/pose.h"
#include "problem/problem.h"

namespace carmba {

// One view of the solution.
struct ViewRecord {
  std::string id;
  bool plate = false;  // a plate view (cam_from_plate), else an object view (cam_from_object)
  std::string group;   // its intrinsics group
  Pose6 pose = Pose6::Zero();
  double rms_px = 0;  // per coordinate
  int num_observations = 0;
  std::optional<Pose6> initial;  // the initialiser's pose (none for a rig view: its rig's)
  double initial_rms_px = 0;
  // Object views: the covariance of [rvec (rad), t (mm)] (none when not computed) and the sigmas
  // of small rotations about the camera axes (deg) and of the translations (mm).
  std::optional<Matrix6> covariance;
  Eigen::Vector3d sigma_rotation_deg = Eigen::Vector3d::Constant(std::nan(""));
  Eigen::Vector3d sigma_translation_mm = Eigen::Vector3d::Constant(std::nan(""));
};

// {id, kind, group, cam_from_plate | cam_from_object, rms_px, num_observations, initial,
// initial_rms_px}; object views add covariance_6x6, covariance_order, sigma_rotation_deg,
// sigma_translation_mm and, where `truth` has the view, truth, rotation_error_deg and
// translation_error_mm.
nlohmann::json ViewJson(const ViewRecord& view, const ProblemTruth& truth);

// One validation pair: the relative rotation and the angle between the viewing directions of two
// object views, with their sigmas.
struct PairRecord {
  std::string a, b;
  std::optional<double> expected_deg;
  double relative_rotation_deg = 0, sigma_relative_rotation_deg = 0;
  double angle_view_dirs_deg = 0, sigma_view_dirs_deg = 0;
};

// {a, b, relative_rotation_deg, sigma_relative_rotation_deg, angle_view_dirs_deg,
// sigma_view_dirs_deg, expected_deg (null when not given)}, and true_relative_rotation_deg where
// `truth` has both views.
nlohmann::json PairJson(const PairRecord& pair, const ProblemTruth& truth);

}  // namespace carmba
