// The joint problem: calibration and pose as ONE bundle adjustment over all plate views, object
// views and the CT fiducials (the engine: ba/bundle_adjuster.h), with an error budget and the
// two-step comparison. A front end: it reads the problem, finds initial values, fills a
// ba::BaProblem (result.json and the report: report/joint_report.h).
//
// PROBLEM FILE (problems/*.yaml; paths relative to the file). The same vocabulary as the pose and
// calibration problems; a calibration-only or pose-only problem is this file with one kind of
// view (a pose-only one needs `camera`):
//   name: thesis_joint
//   description: ...
//   plate_views:                      # calibration plate views
//     observations: plate/observations.csv   # as `carmba detect` writes it (grid in its header)
//     # or images: DIR_OR_GLOB with pattern: circles, rows: 5, cols: 5, spacing_mm: 20
//     sigma_px: 0.05                  # detection noise, 1 sigma per coordinate
//     plate: {free: false, sigma_mm: 0.01}    # optional: sphere positions free, tied to the
//                                             # nominal grid by the manufacturing tolerance
//   object_views:
//     observations: object/observations.csv  # long: view, marker, u_px, v_px
//     sigma_px: 0.3
//     # or images: DIR_OR_GLOB (PNG/TIFF/DICOM, multi-frame DICOM: a view per frame) with
//     # detection: {diameter_mm: 2, ...} (detect/marker_views.h ReadObjectViewsOptions): marker
//     # blobs detected and labelled with the fiducials through `camera` (required then); each
//     # observation's 2x2 covariance from its blob's (sigma_px, if given, is not used); views
//     # with fewer than 4 markers found are skipped (listed in skipped_object_views)
//   fiducials: fiducials.csv          # as `carmba ct-fiducials` writes it: id, x_mm, y_mm, z_mm,
//                                     # cov_xx..cov_zz (the CT prior); or a map
//                                     # {file, id_column, columns, sigma_mm}
//   camera: camera.json               # optional: initial intrinsics (default: Zhang on the plate
//                                     # views); with `intrinsics: {prior: true}` its covariance is
//                                     # an intrinsics prior
//   intrinsics: {model: shared}       # or {model: per_group, groups: groups.csv} (columns view,
//                                     # group; a plate view is named by its image stem or number)
//                                     # or {model: per_group} with angles: one group per plate
//                                     # orientation, an object view in the nearest one's group;
//                                     # or {model: smooth, primary_order: 1, secondary_degree: 1}:
//                                     # fx fy cx cy as functions of the C-arm angles
//                                     # (ba/smooth_intrinsics.h), distortion shared.
//                                     # select: true|false (default true when every view has
//                                     # angles): compare the models by held-out orientation
//                                     # groups and AIC/BIC (analysis/flex_models.h) in the report
//   angles: views.csv                 # optional: C-arm angles per view (columns view, primary_deg,
//                                     # secondary_deg; view = image stem, plate view number or
//                                     # object view id); plate views read from DICOM images take
//                                     # their Positioner Primary / Secondary Angle instead
//   validation: [{a: VIEW, b: VIEW, expected_deg: X}, ...]   # object views
//   truth: truth.json                 # optional (the simulator's joint truth)
// The solver configuration (configs/, SolverConfig of problem/pose_problem.h) says how: the
// object views' initialiser, loss, linear solver, covariance, intrinsics held (`fix`), outliers.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "ba/bundle_adjuster.h"
#include "analysis/flex_models.h"
#include "analysis/lens_models.h"
#include "ba/quantities.h"
#include "analysis/relative_pose.h"
#include "analysis/tre.h"
#include "camera/camera.h"
#include "detect/observations.h"
#include "problem/pose_problem.h"

namespace carmba {

struct MrcalCrossCheckOptions;  // calib/crosscheck.h

struct JointTruth {
  std::optional<Camera> camera;
  std::map<std::string, Pose6> object_poses;  // cam_from_object by view id
  // Per-view true intrinsics of a flexing C-arm ("view_intrinsics": [{"id", "camera"}]).
  std::map<std::string, std::array<double, kNumIntrinsics>> view_intrinsics;
};

struct JointProblem {
  std::string name, description;
  std::string path;
  // Plate views.
  ObservationSet plate;                 // empty views when there are none
  std::vector<std::string> plate_view_ids;  // image stems (or numbers), per plate view
  double plate_sigma_px = 0;
  bool plate_free = false;
  double plate_sigma_mm = 0;
  std::vector<std::string> skipped_images;  // plate images without a usable grid ("file: why")
  // Object views.
  std::vector<PoseView> object_views;   // problem/pose_problem.h: the one object-view form
  double object_sigma_px = 0;  // from images: the median of the per-observation sigmas
  // From images: the detection's marker diameter (mm), for the engine's cone-beam shadow
  // correction (ba/shadow_correction.h); 0 = unknown.
  double marker_diameter_mm = 0;
  std::vector<std::string> skipped_object_views;  // object images not labelled ("view: why")
  std::vector<Marker> fiducials;
  // Intrinsics.
  std::optional<Camera> camera;
  bool camera_prior = false;
  bool per_group = false;
  std::map<std::string, std::string> group_of_view;  // per_group: view id -> group name
  bool smooth = false;                               // model smooth
  ba::SmoothBasis smooth_basis;
  bool secondary_degree_given = false;  // intrinsics.secondary_degree was in the file
  bool select_model = true;
  // C-arm angles (deg) by view id (plate view ids as plate_view_ids, object view ids), and where
  // each came from ("views.csv:12", "DICOM image.dcm").
  std::map<std::string, std::pair<double, double>> angles;
  std::map<std::string, std::string> angles_from;
  std::vector<ValidationPair> validation;
  JointTruth truth;
};

// "shared", "per_group" or "smooth": the problem's intrinsics model as the files spell it.
inline const char* IntrinsicsModelName(const JointProblem& p) {
  return p.smooth ? "smooth" : p.per_group ? "per_group" : "shared";
}

StatusOr<JointProblem> LoadJointProblem(const std::string& yaml_path);
// True if the YAML file is a joint problem (has plate_views or object_views).
bool IsJointProblemFile(const std::string& yaml_path);

// One way of solving the object views' poses, for the comparison.
struct PoseSigmas {
  std::string method;
  std::vector<Eigen::Vector3d> sigma_rotation_deg;    // per object view
  std::vector<Eigen::Vector3d> sigma_translation_mm;
  std::vector<double> sigma_relative_rotation_deg;    // per validation pair
  std::vector<double> relative_rotation_deg;
  std::vector<Pose6> cam_from_object;                 // the estimates, per object view
};

struct JointSolution {
  ba::BaProblem ba_problem;
  ba::BaResult result;
  std::vector<std::pair<int, int>> pairs;        // validation pairs as view indices
  std::vector<ba::BudgetRow> budget;
  std::vector<PoseSigmas> comparison;            // joint, two-step, two-step with prior
  std::string comparison_error;                  // why the comparison is missing (if it is)
  std::string initial_intrinsics_from;           // "camera.json", "Zhang + calibration" ...
  std::optional<analysis::ModelSelection> selection;   // intrinsics models compared (flex)
  std::string selection_error;                   // why not (if asked and it failed)
  // The smooth model as solved: the problem's, with secondary_degree 0 when the plate views
  // cover one secondary angle and the file did not set it (model_note says so).
  ba::SmoothBasis smooth_basis;
  std::string model_note;
  // The distortion models compared on the plate views (analysis/lens_models.h; one shared group), and
  // the warning when the solved model's principal point strays from the recommended one's.
  std::optional<analysis::DistortionSelection> distortion;
  std::string distortion_error;
  std::string distortion_warning;
  // Relative poses of object views with 6x6 covariances (analysis/relative_pose.h: every pair when
  // there are at most 10 object views, else the validation pairs); the leave-one-marker-out TRE
  // when the config has tre: true (analysis/tre.h).
  std::vector<analysis::RelativePoseEstimate> relative_poses;
  std::optional<analysis::TreResult> tre;
};

StatusOr<JointSolution> SolveJointProblem(const JointProblem& problem, const SolverConfig& config);

// Cross-check with mrcal 2.2 (scripts/mrcal_crosscheck.py, joint mode, through /usr/bin/python3):
// the joint problem with the markers held at their CT positions and all nine intrinsics free,
// solved by the engine and by mrcal.optimize (plate views as boards, object views as fixed
// points seen by one camera extrinsics per view, one intrinsics; pixel weights 1 and
// sigma_plate / sigma_object), both from the same initial values. Returns carmba's and mrcal's
// intrinsics, RMS and their differences (relative for fx, fy, cx, cy; in sigmas for all nine).
// Errors: more than one intrinsics group, a view kind missing, mrcal failing (its message).
// `options`: the work directory and the interpreter (calib/crosscheck.h).
StatusOr<nlohmann::json> JointMrcalCrossCheck(const JointProblem& problem,
                                              const JointSolution& solution,
                                              const MrcalCrossCheckOptions& options);

// result.json's "mrcal_crosscheck": JointMrcalCrossCheck's JSON, or {"error": its message} (a
// failure is reported, not an error of the solve). `options.work_dir` is removed afterwards.
nlohmann::json JointMrcalCrossCheckJson(const JointProblem& problem,
                                        const JointSolution& solution,
                                        const MrcalCrossCheckOptions& options);

}  // namespace carmba
