// A pose problem (WHAT is estimated from WHICH data) and a solver configuration (HOW), both read
// from YAML, and the bundle adjustment that solves one with the other.
//
// The bundle adjustment is the engine's (ba/bundle_adjuster.h, one Ceres problem over all views);
// this front end fills it:
//   * per view v a pose cam_from_object_v = [rx, ry, rz (rad), tx, ty, tz (mm)];
//   * per marker m its position p_m in the object frame, a parameter block shared by all views,
//     tied to its CT measurement by a prior whitened by the CT covariance (PointPriorRows). It fixes
//     the object frame (the gauge), and CT error enters the covariance and correlates the views;
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
//
// The reference of both files, every key with its units, is src/docs/formats.md (kept equal to
// the readers by tests/cli/docs_formats_test.cc); in short:
//
// PROBLEM FILE (problems/*.yaml); paths are relative to the problem file:
//   name: thesis_pose
//   camera: ../data/thesis/camera.json         # camera.json (camera/camera.h)
//   sigma_px: 1.0                               # pixel noise, 1 sigma per coordinate
//   markers:                                    # the fiducials, object frame (mm)
//     file: ../data/thesis/projections_table_5_2.csv
//     id_column: marker                         # default: id
//     columns: [x, y, z]                        # default: [x_mm, y_mm, z_mm]
//     sigma_mm: 0.3                             # isotropic CT sigma; or covariance columns
//                                               # cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz (mm^2)
//                                               # in the file (as `carmba ct-fiducials` writes)
//   observations:
//     file: ../data/thesis/projections_table_5_2.csv
//     format: wide         # wide: a row per marker, columns u_<view>, v_<view>;
//                          # long: columns view, marker, u_px, v_px
//   views: [0, 10, 30, 50, 90]                  # view ids to use (default: all in the file)
//   handedness: as_given                        # or mirrored (object y negated)
//   validation:                                 # pairs of views to compare
//     - {a: 0, b: 10, expected_deg: 10}
//   reference:                                  # optional, shown in the report
//     legacy_posit: {focal_px: 2158.0175, cx_px: 205.155, cy_px: 206.617, y_up: true}
//     rotations: ../data/thesis/posit_rotations_tables_5_3_to_5_5.csv
//     validation: ../data/thesis/validation_table_5_6.csv
//   truth: truth.json      # optional: per view cam_from_object {"views":[{"id","rvec","t_mm"}]}
//
// CONFIG FILE (configs/*.yaml):
//   name: posit_ba_analytic
//   initializer: posit            # legacy_posit | posit | epnp | sqpnp
//   refine: true                  # false: report the initialiser's poses (no bundle adjustment)
//   jacobians: analytic           # analytic | autodiff
//   loss: {type: trivial, scale_px: 1.0}   # trivial | huber | cauchy | soft_l1
//   linear_solver: dense_schur    # dense_qr | dense_normal_cholesky | dense_schur | sparse_schur |
//                                 # sparse_normal_cholesky | iterative_schur
//   max_iterations: 100
//   function_tolerance: 1e-12
//   gradient_tolerance: 1e-12
//   parameter_tolerance: 1e-12
//   covariance: {algorithm: schur, scale: apriori}  # or ceres::Covariance's dense_svd,
//                                                 # sparse_qr, eigen_sparse_qr;
//                                                 # aposteriori scales by s0^2
//   num_threads: 1
//   fix: [p1, p2, k3]             # joint problems: intrinsics held (default: none)
//   backend: ceres                # or carmba_lm (calibration-structured problems only)
//   outliers: {list_sigma: 4, reject_sigma: 0}   # list above 4 sigma; reject_sigma > 0 drops
//                                 # the worst above it and solves again, until none is left
//   tre: false                    # true: leave-one-marker-out target registration error
//                                 # (analysis/tre.h; one more solve per marker) in result.json/report
//   consider_calibration: true    # pose problems: camera.json's covariance enters the
//                                 # covariances (intrinsics held, their uncertainty considered)
// A calibration config given here (it has keys such as robust_loss, detection, crosscheck) is an
// error saying so.
#pragma once

#include <Eigen/Dense>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "ba/bundle_adjuster.h"
#include "analysis/relative_pose.h"
#include "analysis/tre.h"
#include "camera/camera.h"
#include "export/view_geometry.h"
#include "geometry/pose.h"
#include "util/progress.h"
#include "util/status.h"

namespace carmba {


enum class Handedness { kAsGiven, kMirrored };

struct Marker {
  int id = 0;
  Eigen::Vector3d p_in_object;   // as measured (CT), mm; before any mirroring
  Eigen::Matrix3d covariance;    // mm^2
};

struct Observation {
  int marker_id = 0;
  Eigen::Vector2d uv_px;
  // This observation's pixel sigma (px, per coordinate); 0 = the problem's sigma_px. Set for
  // detected marker blobs (detect/marker_views.h).
  double sigma_px = 0;
  // Its full 2x2 pixel covariance (px^2); zero = none (isotropic sigma_px). Detected blobs carry
  // one, as do observations.csv files with columns cov_uu, cov_uv, cov_vv. The bundle adjustment
  // whitens by it in full.
  Eigen::Matrix2d covariance_px2 = Eigen::Matrix2d::Zero();
  bool HasCovariance() const { return covariance_px2(0, 0) > 0; }
};

// An object view: the markers seen in one image. The one form of an object view between the
// readers (problem/pixel_csv.h, detect/marker_views.h ToPoseViews) and the engine, in pose and
// joint problems alike.
struct PoseView {
  std::string id;
  std::vector<Observation> observations;
};

// The engine's view of an object view (the one translation, for the pose and the joint
// problems): its marker ids and pixels with their per-observation sigmas or covariances,
// `sigma_px` where an observation has none; no group and no initial pose yet.
ba::BaView ToBaObjectView(const PoseView& view, double sigma_px);

struct ValidationPair {
  std::string a, b;
  std::optional<double> expected_deg;
};

struct LegacyPositReference {
  double focal_px = 0, cx_px = 0, cy_px = 0;
  bool y_up = true;
};

struct PoseProblem {
  std::string name;
  std::string path;  // the problem file, for messages
  Camera camera;
  double sigma_px = 1.0;
  std::vector<Marker> markers;
  // Diameter of the marker spheres (mm), when known (detected from images): the engine then
  // corrects each blob for its cone-beam shadow's offset (ba/shadow_correction.h). 0 = unknown.
  double marker_diameter_mm = 0;
  std::vector<PoseView> views;
  Handedness handedness = Handedness::kAsGiven;
  std::vector<ValidationPair> validation;
  // Reference values for the report (thesis).
  std::optional<LegacyPositReference> legacy_reference;
  std::map<std::string, Eigen::Matrix3d> reference_rotations;     // by view id
  std::map<std::pair<std::string, std::string>, double> reference_angles_deg;
  // Ground truth, when known (simulated problems): cam_from_object of the markers' true frame.
  std::map<std::string, Pose6> truth_poses;
  std::map<int, Eigen::Vector3d> truth_markers;

  // Consistency: ids unique, every observation names a marker, >= 4 observations per view,
  // validation pairs name views. Error names the problem file.
  Status Check() const;
};

enum class Initializer { kLegacyPosit, kPosit, kEpnp, kSqpnp };

struct SolverConfig {
  std::string name = "default";
  std::string path;
  Initializer initializer = Initializer::kPosit;
  bool refine = true;               // run the bundle adjustment
  bool analytic_jacobians = true;   // false: autodiff twin
  std::string loss = "trivial";     // trivial | huber | cauchy | soft_l1
  double loss_scale_px = 1.0;
  std::string linear_solver = "dense_schur";
  int max_iterations = 100;
  double function_tolerance = 1e-12;
  double gradient_tolerance = 1e-12;
  double parameter_tolerance = 1e-12;
  // schur: the engine's, from the residuals' Jacobians with the markers eliminated
  //        (ba/covariance.h; the fastest);
  // dense_svd | sparse_qr (SuiteSparse) | eigen_sparse_qr: ceres::Covariance (references).
  std::string covariance_algorithm = "schur";
  // per_group: each observation group's sigmas scaled by its estimated variance factor where its
  // redundancy allows (ba/variance_components.h); apriori: the stated sigmas; global: sigma0^2.
  ba::CovarianceScale covariance_scale = ba::CovarianceScale::kPerGroup;
  int num_threads = 1;
  // Joint problems (joint/joint_problem.h): intrinsics held at their initial values, by name
  // (fx fy cx cy k1 k2 p1 p2 k3); pose problems hold all of them.
  std::vector<std::string> fix;
  // Joint problems with plate views: auto selects the distortion terms (k1 k2 | + p1 p2 | + k3 |
  // all) by AIC with held-out plate views (analysis/lens_models.h); `fix` then names none of them.
  // given: the terms `fix` leaves free (the selection is still run and warns when the given
  // model's principal point is more than 2 sigma from the recommended one's).
  bool distortion_auto = false;
  // Observations whose whitened residual exceeds outlier_sigma are listed; reject_sigma > 0
  // drops them one at a time and solves again (ba/bundle_adjuster.h).
  double outlier_sigma = 4.0;
  double reject_sigma = 0;
  // The engine's minimiser: ceres, or carmba_lm for calibration-structured problems
  // (ba/bundle_adjuster.h).
  std::string backend = "ceres";
  // Leave-one-marker-out target registration error (analysis/tre.h): one more solve per marker.
  bool tre = false;
  // Pose problems: when camera.json has a covariance, the intrinsics (held at its values) are
  // CONSIDERED: the poses' covariance (and everything derived from it) includes the
  // calibration's uncertainty (ba/covariance.h). false: the residuals' part only.
  bool consider_calibration = true;

  bool Check(std::string* error) const;
  // The engine's options: the one mapping of a solver config onto ba::BaOptions, for every
  // problem kind. refine: false gives a solve of 0 iterations with no covariance and no
  // rejection (the initial poses evaluated).
  ba::BaOptions ToBaOptions() const;
};

StatusOr<PoseProblem> LoadPoseProblem(const std::string& yaml_path);

// Reads the `validation` list of a problem file ({a: VIEW, b: VIEW, expected_deg: X} entries)
// into `out`; errors are recorded in `root` (YamlMap::Finish reports them).
class YamlMap;
void ReadValidationPairs(YamlMap& root, std::vector<ValidationPair>* out);

// Reads markers (fiducials) from a CSV: ids in `id_column`, positions (mm) in `columns`, and the
// covariance from the columns cov_xx, cov_xy, cov_xz, cov_yy, cov_yz, cov_zz (mm^2, as `carmba
// ct-fiducials` writes them) or, when sigma_mm > 0, isotropic sigma_mm. Without either the error
// names `sigma_key`. Errors name file:line.
StatusOr<std::vector<Marker>> ReadMarkersCsv(const std::string& path,
                                             const std::string& id_column,
                                             const std::vector<std::string>& columns,
                                             double sigma_mm,
                                             const std::string& sigma_key);

// The initial pose cam_from_object of one view from its 2-D/3-D pairs by `initializer` with the
// camera's intrinsics. Errors: the initialiser fails or returns an invalid pose.
StatusOr<Pose6> InitialObjectPose(const Camera& camera,
                                  Initializer initializer,
                                  const std::vector<Eigen::Vector3d>& p_in_object,
                                  const std::vector<Eigen::Vector2d>& uv_px);
StatusOr<SolverConfig> LoadSolverConfig(const std::string& yaml_path);
const char* InitializerName(Initializer i);

struct ViewSolution {
  std::string id;
  Pose6 cam_from_object;              // in the problem's handedness
  Matrix6 covariance;                 // of [rvec (rad), t (mm)]
  Eigen::Vector3d sigma_rotation_deg; // small rotations about the camera axes, 1 sigma
  Eigen::Vector3d sigma_translation_mm;
  double rms_px = 0;                  // per-coordinate RMS of this view's reprojection residuals
  int num_observations = 0;
  Pose6 initial;                      // the initialiser's pose
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
  Eigen::MatrixXd joint_covariance;   // 6V x 6V, views in order
  std::map<int, Eigen::Vector3d> markers;  // refined marker positions (problem's handedness)
  bool has_covariance = false;
  // Statistics
  double rms_px = 0;                  // per-coordinate RMS over all reprojection residuals
  double chi2 = 0;                    // sum of squared whitened residuals (incl. priors)
  int num_residuals = 0;              // scalar residuals
  int num_parameters = 0;             // free scalar parameters
  int dof = 0;
  double sigma0 = 0;                  // sqrt(chi2 / dof), the a-posteriori factor
  double sigma_aposteriori_px = 0;    // sigma0 * sigma_px
  double chi2_p_value = 0;            // P(X > chi2) for X ~ chi2(dof)
  // Solver
  std::string config_name;
  int iterations = 0;
  std::string termination;
  double initial_cost = 0, final_cost = 0;
  double time_s = 0;                  // wall time of initialisation + solve + covariance
  // Relative poses cam_b_from_cam_a with 6x6 covariances (analysis/relative_pose.h): every pair of
  // views when there are at most 10, else the validation pairs; empty without the engine's
  // covariance. Leave-one-marker-out TRE when the config asks (tre: true).
  std::vector<analysis::RelativePoseEstimate> relative_poses;
  std::optional<analysis::TreResult> tre;
  // The validation pairs as view indices (problem.views order = the engine's view order).
  std::vector<std::pair<int, int>> validation_pairs;
  // The engine's problem and result (ba/), for error budgets and further analysis; always set
  // by SolvePoseProblem.
  std::shared_ptr<const ba::BaProblem> ba_problem;
  std::shared_ptr<const ba::BaResult> ba_result;
};

// Solves a pose problem. Errors: a view whose initialiser fails, a non-finite initial cost,
// a rank-deficient covariance. `progress` (optional) is called once per view after its initial
// pose (the bundle adjustment that follows is one solve over all views).
StatusOr<PoseSolution> SolvePoseProblem(const PoseProblem& problem,
                                        const SolverConfig& config,
                                        const ProgressFn& progress = nullptr);

// camera.json's covariance as a considered calibration (ba/problem.h IntrinsicsGroup::consider_*):
// the intrinsic indices of its names and the matrix; empty without a covariance.
StatusOr<std::pair<std::vector<int>, Eigen::MatrixXd>> ConsideredCalibration(const Camera& camera);

// The problem's marker positions in its handedness (mirrored: y negated).
Eigen::Vector3d MarkerInProblemFrame(const PoseProblem& problem, const Marker& m);

// What the solve says about itself (ba::SolveWarnings: chi-square and variance factors outside
// their bands, outliers), one sentence each: in result.json "warnings", the report and on stderr.
std::vector<std::string> PoseWarnings(const PoseSolution& solution);

// geometry.json's content (export/view_geometry.h): per view the problem's camera and
// cam_from_ct = cam_from_object (with the mirror when handedness is mirrored), the reference
// point the CT markers' centroid.
GeometrySet PoseSolutionGeometry(const PoseProblem& problem, const PoseSolution& solution);

}  // namespace carmba
