// The one translation of a Problem (problem/problem.h) into the engine's problem (ba::BaProblem),
// for every problem kind. A front end chooses only what differs between the kinds:
//   - the intrinsics groups: a pose problem's one group held at camera.json (pose_solver.h), a
//     joint problem's groups calibrated from their plate views (joint/joint_solver.h);
//   - the plate views with their initial poses (from those calibrations);
//   - which group each object view belongs to.
// Everything else is assembled here, the same way for all:
//   - the plate's nominal points, free or held (BaPlate; detect/observations.h's
//     ToBaPlateProblem, which a calibration uses alone);
//   - the fiducials that some object view observes, in the problem's handedness, with their CT
//     covariance, in the order of the fiducials file (an unobserved one would add only its prior);
//   - the object views (ToBaObjectView), each initialised by the config's initializer with its
//     group's initial intrinsics;
//   - the C-arm angles of the views that have them;
//   - the validation pairs as view indices into BaProblem::views.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "ba/problem.h"
#include "problem/problem.h"
#include "problem/solver_config.h"
#include "util/progress.h"
#include "util/status.h"

namespace carmba {

// What the front end chose.
struct BaAssemblyInput {
  std::vector<ba::IntrinsicsGroup> groups;
  std::vector<ba::BaView> plate_views;  // kind kPlate, with group and initial pose
  std::vector<int> object_view_groups;  // per object view; empty: all in group 0
};

struct AssembledProblem {
  ba::BaProblem problem;
  std::vector<std::pair<int, int>> validation_pairs;  // Problem::validation as view indices
};

// The engine's view of an object view: its marker ids and pixels with their per-observation
// sigmas or covariances, `sigma_px` where an observation has none; no group and no initial pose.
ba::BaView ToBaObjectView(const PoseView& view, double sigma_px);

// The initial pose cam_from_object of one view from its 2-D/3-D pairs by `initializer` with the
// camera's intrinsics. Errors: the initialiser fails or returns an invalid pose.
StatusOr<Pose6> InitialObjectPose(const Camera& camera,
                                  Initializer initializer,
                                  const std::vector<Eigen::Vector3d>& p_in_object,
                                  const std::vector<Eigen::Vector2d>& uv_px);

// The whole engine problem. `progress` is called once per object view initialised. Errors name
// the problem file and the object view whose initial pose failed.
StatusOr<AssembledProblem> ToBaProblem(const Problem& problem,
                                       const SolverConfig& config,
                                       BaAssemblyInput input,
                                       const ProgressFn& progress = nullptr);

}  // namespace carmba
