// result.json, written by one writer for every problem kind that solves with the engine (pose and
// joint problems): the front ends' writers (pose: report/pose_json.cc; joint:
// report/joint_report.cc) fill a ResultContent with records of their views and pairs, and
// ResultJson writes the file's sections with one set of keys.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include <vector>

#include "analysis/relative_pose.h"
#include "analysis/tre.h"
#include "ba/bundle_adjuster.h"
#include "ba/quantities.h"
#include "geometry/pose.h"
#include "problem/problem.h"

namespace carmba {

// result.json's encoding of every pose (views, initial poses, truth, relative poses): {"R": 9
// values, row-major, "rvec": rad, "t_mm"}. Legacy POSIT's matrices are not poses (rows not
// exactly orthogonal, the legacy camera) and keep their own {R, t_mm}.
nlohmann::json PoseToJson(const Pose6& pose);

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

// What a problem kind's solution puts into result.json.
struct ResultContent {
  nlohmann::json problem;  // "problem": the file and what the kind states of it
  // The engine's problem and result (required): markers, outliers, statistics, variance
  // components, shadow correction, solver.
  const ba::BaProblem* engine_problem = nullptr;
  const ba::BaResult* engine_result = nullptr;
  std::string config_name;
  std::vector<ViewRecord> views;
  std::vector<PairRecord> validation;
  std::vector<ba::BudgetRow> error_budget;
  std::vector<std::string> warnings;
  std::vector<analysis::RelativePoseEstimate> relative_poses;
  std::optional<analysis::TreResult> tre;
  // The kind's additions to "statistics" and "solver" (key by key), and the sections only one
  // kind has (joint: intrinsics, state_layout, two_step_comparison, distortion_selection; pose:
  // joint_covariance).
  nlohmann::json statistics_extra = nlohmann::json::object();
  nlohmann::json solver_extra = nlohmann::json::object();
  nlohmann::json kind_sections = nlohmann::json::object();
};

// The whole result.json: problem, warnings, views, validation, relative_poses, tre (when
// computed), markers, outliers, rejected, error_budget, statistics, variance_components,
// shadow_correction, solver, and the kind's sections.
nlohmann::json ResultJson(const ResultContent& content, const ProblemTruth& truth);

}  // namespace carmba
