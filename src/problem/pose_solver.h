// The pose front end: a pose problem (problem/problem.h: object views only, the intrinsics held at
// camera.json) solved with a solver configuration (problem/solver_config.h) by the engine.
//
// The bundle adjustment is the engine's (ba/bundle_adjuster.h, one Ceres problem over all views);
// this front end fills it:
//   * per view v a pose cam_from_object_v = [rx, ry, rz (rad), tx, ty, tz (mm)];
//   * per marker m its position p_m in the object frame, a parameter block shared by all views,
//     tied to its CT measurement by a prior whitened by the CT covariance (PointPriorRows). It
//     fixes the object frame (the gauge), and CT error enters the covariance and correlates the
//     views;
//   * per observation a ReprojectionError whitened by sigma_px, or by its 2x2 pixel covariance
//     when it has one (analytic Jacobians, or the autodiff twin); the intrinsics are read from the
//     camera file and held at its values. When camera.json has a covariance they are CONSIDERED
//     (config consider_calibration, default true): the covariances include the calibration's
//     uncertainty by the consider term (ba/covariance.h), the estimates are unchanged.
// Initial poses come from the configured initialiser (legacy_posit, posit, epnp, sqpnp).
// The covariance of all poses is computed jointly, by default from the analytic Jacobians with the
// markers eliminated by the Schur complement (ba/covariance.h), or with ceres::Covariance;
// per view it is reported as (rvec, t) and as small rotations about the camera axes (deg) and
// translations (mm).
#pragma once

#include <Eigen/Dense>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "analysis/relative_pose.h"
#include "analysis/tre.h"
#include "ba/bundle_adjuster.h"
#include "camera/camera.h"
#include "export/view_geometry.h"
#include "geometry/pose.h"
#include "io/object_views.h"
#include "problem/problem.h"
#include "problem/solver_config.h"
#include "util/progress.h"
#include "util/status.h"

namespace carmba {

struct ViewSolution {
  std::string id;
  Pose6 cam_from_object;               // in the problem's handedness
  Matrix6 covariance;                  // of [rvec (rad), t (mm)]
  Eigen::Vector3d sigma_rotation_deg;  // small rotations about the camera axes, 1 sigma
  Eigen::Vector3d sigma_translation_mm;
  double rms_px = 0;  // per-coordinate RMS of this view's reprojection residuals
  int num_observations = 0;
  Pose6 initial;  // the initialiser's pose
  double initial_rms_px = 0;
};

struct PairSolution {
  std::string a, b;
  double angle_view_dirs_deg = 0, sigma_view_dirs_deg = 0;
  double relative_rotation_deg = 0, sigma_relative_rotation_deg = 0;
  std::optional<double> expected_deg;
};

struct PoseSolution {
  std::vector<ViewSolution> views;
  std::vector<PairSolution> validation;
  Eigen::MatrixXd joint_covariance;        // 6V x 6V, views in order
  // Cov(view a's pose, view b's pose): joint_covariance's block (view a's own for a == b), as
  // ba::BaResult::ViewPoseCross but from the covariance algorithm the config chose.
  Matrix6 ViewPoseCross(size_t a, size_t b) const {
    return joint_covariance.block<6, 6>(6 * a, 6 * b);
  }
  std::map<int, Eigen::Vector3d> markers;  // refined marker positions (problem's handedness)
  bool has_covariance = false;
  // The statistics (chi2, dof, sigma0, its P value, the RMS, iterations, costs) are the engine's:
  // ba_result below. What the pose front end says differently:
  std::string config_name;
  std::string termination;  // the engine's TerminationText(), or NOT_REFINED
  // The engine's verdict (ba::BaResult::converged); true when the config does not refine (the
  // initial poses are the answer asked for).
  bool converged = true;
  double final_cost = 0;  // the engine's, or its initial cost when not refined
  double time_s = 0;      // wall time of initialisation + solve + covariance
  // Relative poses cam_b_from_cam_a with 6x6 covariances (analysis/relative_pose.h): every pair of
  // views when there are at most 10, else the validation pairs; empty without the engine's
  // covariance. Leave-one-marker-out TRE when the config asks (tre: true).
  std::vector<analysis::RelativePoseEstimate> relative_poses;
  std::optional<analysis::TreResult> tre;
  // The validation pairs as view indices (problem.object_views order = the engine's view order).
  std::vector<std::pair<int, int>> validation_pairs;
  // The engine's problem and result (ba/), for error budgets and further analysis; always set
  // by SolvePoseProblem.
  std::shared_ptr<const ba::BaProblem> ba_problem;
  std::shared_ptr<const ba::BaResult> ba_result;
};

// Solves a pose problem. Errors: a view whose initialiser fails, a non-finite initial cost,
// a rank-deficient covariance. `progress` (optional) is called once per view after its initial
// pose (the bundle adjustment that follows is one solve over all views).
StatusOr<PoseSolution> SolvePoseProblem(const Problem& problem,
                                        const SolverConfig& config,
                                        const ProgressFn& progress = nullptr);

// camera.json's covariance as a considered calibration (ba/problem.h IntrinsicsGroup::consider_*):
// the intrinsic indices of its names and the matrix; empty without a covariance.
StatusOr<std::pair<std::vector<int>, Eigen::MatrixXd>> ConsideredCalibration(const Camera& camera);

// What the solve says about itself (ba::SolveWarnings: chi-square and variance factors outside
// their bands, outliers), one sentence each: in result.json "warnings", the report and on stderr.
std::vector<std::string> PoseWarnings(const PoseSolution& solution);

// geometry.json's content (export/view_geometry.h): per view the problem's camera and
// cam_from_ct = cam_from_object (with the mirror when handedness is mirrored), the reference
// point the CT markers' centroid.
GeometrySet PoseSolutionGeometry(const Problem& problem, const PoseSolution& solution);

}  // namespace carmba
