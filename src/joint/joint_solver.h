// The joint problem: calibration and pose as ONE bundle adjustment over all plate views, object
// views and the CT fiducials (the engine: ba/bundle_adjuster.h), with an error budget and the
// two-step comparison. A front end: it finds the initial values of a problem and fills a
// ba::BaProblem (result.json and the report: report/joint_report.h).
//
// The problem is problem/problem.h's (one schema for every problem kind); the solver
// configuration (problem/solver_config.h) says how: the object views' initialiser, loss, linear
// solver, covariance, intrinsics held (`fix`), outliers.
#pragma once

#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "analysis/flex_models.h"
#include "analysis/lens_models.h"
#include "analysis/relative_pose.h"
#include "analysis/tre.h"
#include "ba/bundle_adjuster.h"
#include "ba/quantities.h"
#include "camera/camera.h"
#include "detect/observations.h"
#include "problem/pose_solver.h"
#include "problem/problem.h"

namespace carmba {

struct MrcalCrossCheckOptions;  // calib/crosscheck.h

// One way of solving the object views' poses, for the comparison.
struct PoseSigmas {
  std::string method;
  std::vector<Eigen::Vector3d> sigma_rotation_deg;  // per object view
  std::vector<Eigen::Vector3d> sigma_translation_mm;
  std::vector<double> sigma_relative_rotation_deg;  // per validation pair
  std::vector<double> relative_rotation_deg;
  std::vector<Pose6> cam_from_object;  // the estimates, per object view
};

struct JointSolution {
  ba::BaProblem ba_problem;
  ba::BaResult result;
  std::vector<std::pair<int, int>> pairs;  // validation pairs as view indices
  std::vector<ba::BudgetRow> budget;
  std::vector<PoseSigmas> comparison;                 // joint, two-step, two-step with prior
  std::string comparison_error;                       // why the comparison is missing (if it is)
  std::string initial_intrinsics_from;                // "camera.json", "Zhang + calibration" ...
  std::optional<analysis::ModelSelection> selection;  // intrinsics models compared (flex)
  std::string selection_error;                        // why not (if asked and it failed)
  // The smooth model as solved: the problem's, with secondary_degree 0 when the plate views
  // cover one secondary angle and the file did not set it (model_note says so).
  ba::SmoothBasis smooth_basis;
  std::string model_note;
  // The distortion models compared on the plate views (analysis/lens_models.h; one shared group),
  // and the warning when the solved model's principal point strays from the recommended one's.
  std::optional<analysis::DistortionSelection> distortion;
  std::string distortion_error;
  std::string distortion_warning;
  // Relative poses of object views with 6x6 covariances (analysis/relative_pose.h: every pair when
  // there are at most 10 object views, else the validation pairs); the leave-one-marker-out TRE
  // when the config has tre: true (analysis/tre.h).
  std::vector<analysis::RelativePoseEstimate> relative_poses;
  std::optional<analysis::TreResult> tre;
};

StatusOr<JointSolution> SolveJointProblem(const Problem& problem, const SolverConfig& config);

// Cross-check with mrcal 2.2 (scripts/mrcal_crosscheck.py, joint mode, through /usr/bin/python3):
// the joint problem with the markers held at their CT positions and all nine intrinsics free,
// solved by the engine and by mrcal.optimize (plate views as boards, object views as fixed
// points seen by one camera extrinsics per view, one intrinsics; pixel weights 1 and
// sigma_plate / sigma_object), both from the same initial values. Returns carmba's and mrcal's
// intrinsics, RMS and their differences (relative for fx, fy, cx, cy; in sigmas for all nine).
// Errors: more than one intrinsics group, a view kind missing, mrcal failing (its message).
// `options`: the work directory and the interpreter (calib/crosscheck.h).
StatusOr<nlohmann::json> JointMrcalCrossCheck(const Problem& problem,
                                              const JointSolution& solution,
                                              const MrcalCrossCheckOptions& options);

// result.json's "mrcal_crosscheck": JointMrcalCrossCheck's JSON, or {"error": its message} (a
// failure is reported, not an error of the solve). `options.work_dir` is removed afterwards.
nlohmann::json JointMrcalCrossCheckJson(const Problem& problem,
                                        const JointSolution& solution,
                                        const MrcalCrossCheckOptions& options);

}  // namespace carmba
