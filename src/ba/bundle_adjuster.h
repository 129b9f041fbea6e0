// The bundle adjuster: builds the Ceres problem from a problem description (ba/problem.h) and
// options (HOW it is solved), solves it, and linearises it at the solution for the covariance
// and the error budget (ba/covariance.h). COLMAP's split: options / config of what is free /
// adjuster.
//
// Residual blocks (all whitened, ba/problem.h lists their sources):
//   plate view v, point j:   ReprojectionError(pose_v, plate point j, intrinsics of v's group)
//   object view v, marker m: ReprojectionError(pose_v, marker m, intrinsics of v's group)
//   marker m (free, with priors):  PointPriorRows x 2 (its CT covariance, ba/reprojection_error.h)
//   plate point j (free):    PointPriorRows x 2 (isotropic sigma_mm)
//   group g with a prior:    IntrinsicsPriorError (ba/priors.h)
// Held intrinsics with a considered calibration covariance (IntrinsicsGroup::consider_*) stay
// held; their Jacobian columns are linearised too, for the consider term of the covariance.
// Reprojections are whitened by each observation's 2x2 pixel covariance (BaView::
// obs_covariance_px2) or isotropic sigma. A robust loss acts on the reprojection blocks only,
// with its scale in px (whitened by the observation's isotropic sigma, BaView::SigmaPx). Held
// intrinsics are a ceres::SubsetManifold; constant blocks are set constant. Ordering for the Schur
// solvers: points first, then poses, then intrinsics (poses first when no point is free).
//
// Outliers: after the solve every observation whose whitened residual norm |r| exceeds
// `outlier_sigma` is listed; with `reject_sigma` > 0, the worst observation above it is dropped
// and the problem solved again (warm), until none is above it (at most 100 passes; a view left
// with fewer than 4 observations is an error).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "ba/covariance.h"
#include "ba/problem.h"
#include "ba/shadow_correction.h"
#include "ba/solver_kinds.h"
#include "ba/variance_components.h"
#include "util/status.h"

namespace carmba {
namespace ba {

// A first trust region for initial values near the optimum (a warm re-solve, a Monte Carlo trial
// started at the truth): about pure Gauss-Newton steps. From Ceres's default 1e4 the minimiser
// creeps along weakly determined directions for five more iterations, each lowering the cost by
// ~5e-9.
constexpr double kNearOptimumTrustRegionRadius = 1e8;

struct BaOptions {
  // ceres: Ceres with the analytic cost functions and the Schur ordering (every problem);
  // carmba_lm: carmba's own Schur Levenberg-Marquardt (ba/schur_lm.h) for calibration-structured
  // problems (one intrinsics group, plate views with one sigma, plate held, no prior, trivial
  // loss), several times faster there; tested to reach Ceres's optimum.
  Backend backend = Backend::kCeres;
  bool analytic_jacobians = true;  // false: the autodiff twins
  Loss loss = Loss::kTrivial;
  double loss_scale_px = 1.0;
  std::string linear_solver = "dense_schur";  // any Ceres linear solver name in lower case
  int max_iterations = 100;
  double function_tolerance = 1e-12;
  double gradient_tolerance = 1e-12;
  double parameter_tolerance = 1e-12;
  // The trust region of the first step (Ceres's initial_trust_region_radius; carmba_lm's first
  // damping is its reciprocal):
  // Ceres's default 1e4 for initial values that may be far from the optimum;
  // kNearOptimumTrustRegionRadius when they are near it (a Monte Carlo trial started at the
  // truth: ~4.5 iterations instead of ~10 to the same optimum), as a warm re-solve starts.
  double initial_trust_region_radius = 1e4;
  int num_threads = 1;
  bool compute_covariance = true;
  // false: a seeding solve -- return the solved state, iterations and termination only (no
  // residual statistics, outliers, linearisation or covariance; no rejection pass).
  bool evaluate_solution = true;
  // apriori: the stated sigmas; per_group: each observation group's sigmas scaled by its
  // estimated variance factor where its redundancy allows, the problem solved again until the
  // factors settle (ba/variance_components.h); global: one factor sigma0^2 for all. The variance
  // components are estimated and reported in every mode (with compute_covariance).
  CovarianceScale covariance_scale = CovarianceScale::kApriori;
  // The groups' sigmas are the stated ones times this (per_group's iteration sets it).
  std::array<double, kNumNoiseGroups> group_sigma_scale{1, 1, 1, 1, 1, 1};
  double outlier_sigma = 4.0;           // list observations with |r| above this (whitened)
  double reject_sigma = 0;              // > 0: drop observations above it and re-solve
  double min_reciprocal_condition = 1e-14;
  // Remove the offset of each sphere's cone-beam shadow centre from its projected centre
  // (ba/shadow_correction.h) when the sphere radii are known and the offset reaches 0.1 sigma:
  // one more solve.
  bool shadow_correction = true;

  bool Check(std::string* error) const;
};

struct BaOutlier {
  std::string view;
  bool plate = false;   // plate view (point id) or object view (marker id)
  int id = 0;
  double residual_sigma = 0;  // |whitened residual|
  double du_px = 0, dv_px = 0;
};

// One observation's residual at the solution: projection minus observation in px, and its norm
// whitened by the stated sigmas times its group's scale (BaOptions::group_sigma_scale). An
// observation the rejection pass dropped keeps NaN.
struct BaObservationResidual {
  double du_px = std::numeric_limits<double>::quiet_NaN();
  double dv_px = std::numeric_limits<double>::quiet_NaN();
  double sigma_norm = std::numeric_limits<double>::quiet_NaN();
  bool used() const { return !std::isnan(sigma_norm); }
};

struct BaViewStats {
  std::string id;
  int num_observations = 0;
  double rms_px = 0;  // per coordinate
};

struct BaResult {
  std::vector<double> state;   // the parameter buffer in layout order
  std::shared_ptr<StateLayout> layout;
  std::shared_ptr<Linearization> linearization;   // at the solution
  std::shared_ptr<SchurCovariance> covariance;    // null when not computed
  // 1 (a priori, per group) or, global, the a-posteriori variance factor robust_chi2 / dof
  // (sigma0^2 without a robust loss).
  double covariance_scale = 1.0;
  // Variance components of the observation groups (ba/variance_components.h); with per_group the
  // applied factors are in the weights of the final solve, so in every covariance and budget.
  std::vector<VarianceComponent> variance_components;
  int variance_iterations = 0;  // re-solves of the per_group estimate
  CovarianceScale scale_mode = CovarianceScale::kApriori;  // BaOptions::covariance_scale
  // The groups' sigma scales the final solve was weighted with (1: the stated sigmas).
  std::array<double, kNumNoiseGroups> group_sigma_scale{1, 1, 1, 1, 1, 1};

  // The cone-beam shadow-centre correction (ba/shadow_correction.h): evaluated when a sphere
  // radius is known; when applied, every statistic above and below is of the corrected pixels.
  ShadowCorrectionSummary shadow;
  // The offsets subtracted from the observed pixels (views x observations, problem order) when
  // the correction was applied; empty otherwise. A cross-check gives another solver the pixels
  // this solve saw: observed minus these.
  std::vector<std::vector<Eigen::Vector2d>> shadow_offsets;

  std::vector<BaViewStats> views;  // problem order
  // Every observation's residual, per view (problem order) and observation (BaView order): the
  // front ends' own statistics (per point, the worst, the calibration's outliers) come from here.
  std::vector<std::vector<BaObservationResidual>> residuals;
  double rms_plate_px = 0, rms_object_px = 0;  // per coordinate (NaN when no such view)
  // Sum of squared residuals (priors included, no loss) whitened by the STATED sigmas: the
  // test of the stated noise model, whatever covariance.scale applies.
  double chi2 = 0;
  // chi2 with each residual block's term weighted by its robust loss there (rho'(s), the weight
  // of iteratively reweighted least squares; 1 without a loss), at the final solve's weights:
  // a robust fit's a-posteriori sigma is sqrt(robust_chi2 / dof) x the stated one.
  double robust_chi2 = 0;
  int num_residuals = 0;
  int num_free = 0;
  int dof = 0;
  double sigma0 = 0;      // sqrt(chi2 / dof)
  double chi2_p_value = 0;
  std::vector<BaOutlier> outliers;   // above outlier_sigma, largest first
  std::vector<BaOutlier> rejected;   // dropped by the rejection pass
  std::vector<std::vector<char>> dropped;  // per view and observation: rejected (1) or used (0)

  Backend backend = Backend::kCeres;  // the minimiser that ran (BaOptions::backend)
  int iterations = 0;
  Termination termination = Termination::kNoConvergence;
  bool converged() const { return termination == Termination::kConvergence; }
  std::string TerminationText() const { return ba::TerminationText(termination, backend); }
  // At the problem's initial values: the cost and each view's per-coordinate pixel RMS (problem
  // order), at the stated sigmas.
  double initial_cost = 0, final_cost = 0;
  std::vector<double> initial_view_rms_px;
  double time_s = 0;

  const double* block(int b) const { return state.data() + layout->block(b).offset; }

  // Typed access: a value by what it is, not where it sits in the state (COLMAP's BACovariance
  // getters, mrcal's state-index functions). Indices are the problem's: view v, intrinsics group
  // g, marker m (index in BaProblem::markers), plate point p (its id).
  //
  // View v's pose (rvec rad, t mm) as solved: cam_from_plate, cam_from_object, or for a rig view
  // its rig's pose (the view's pose is cam_from_rig times it).
  Pose6 ViewPose(int v) const { return Eigen::Map<const Pose6>(block(layout->view_block(v))); }
  // Group g's intrinsics (LENSMODEL_OPENCV5 order; a smooth group's reference values).
  std::array<double, kNumIntrinsics> GroupIntrinsics(int g) const {
    std::array<double, kNumIntrinsics> x;
    const double* b = block(layout->group_block(g));
    std::copy(b, b + kNumIntrinsics, x.begin());
    return x;
  }
  Eigen::Vector3d MarkerPosition(int m) const {
    return Eigen::Map<const Eigen::Vector3d>(block(layout->marker_block(m)));
  }
  Eigen::Vector3d PlatePoint(int p) const {
    return Eigen::Map<const Eigen::Vector3d>(block(layout->plate_point_block(p)));
  }
  // Their covariances (as Covariance: scaled, with the considered calibration's part).
  Matrix6 ViewPoseCovariance(int v) const { return Covariance({layout->view_block(v)}); }
  Eigen::MatrixXd GroupIntrinsicsCovariance(int g) const {
    return Covariance({layout->group_block(g)});
  }
  Eigen::Matrix3d MarkerCovariance(int m) const { return Covariance({layout->marker_block(m)}); }
  // Cov(block a, block b): a's parameters in rows, b's in columns (Covariance({a}) for a == b).
  Eigen::MatrixXd Cross(int block_a, int block_b) const {
    if (block_a == block_b) return Covariance({block_a});
    const int na = layout->block(block_a).size, nb = layout->block(block_b).size;
    return Covariance({block_a, block_b}).block(0, na, na, nb);
  }
  // Cov(view a's pose, view b's pose).
  Matrix6 ViewPoseCross(int a, int b) const {
    return Cross(layout->view_block(a), layout->view_block(b));
  }
  // The joint covariance of several views' poses, 6 rows and columns per view in the given order.
  Eigen::MatrixXd ViewPosesCovariance(const std::vector<int>& views) const {
    return Covariance(ViewBlocks(views));
  }
  std::vector<int> ViewBlocks(const std::vector<int>& views) const {
    std::vector<int> blocks;
    for (int v : views) blocks.push_back(layout->view_block(v));
    return blocks;
  }

  // Covariance of blocks (ambient parameters): the residuals' part scaled by covariance_scale,
  // plus the considered calibration's part (ba/covariance.h; zero without one).
  Eigen::MatrixXd Covariance(const std::vector<int>& blocks) const {
    return ObservationCovariance(blocks) + CalibrationCovariance(blocks);
  }
  // The two parts of Covariance.
  Eigen::MatrixXd ObservationCovariance(const std::vector<int>& blocks) const {
    return covariance->BlockCovariance(blocks) * covariance_scale;
  }
  Eigen::MatrixXd CalibrationCovariance(const std::vector<int>& blocks) const {
    return covariance->BlockConsiderCovariance(blocks);
  }
};

// Solves. Errors name what is wrong: problem consistency, a non-finite initial cost, a failed
// solve, a rank-deficient covariance (naming the null direction).
StatusOr<BaResult> SolveBundleAdjustment(const BaProblem& problem, const BaOptions& options);

// What a solve says about itself, one sentence each (for stderr, result.json "warnings" and the
// report): the chi-square at the stated sigmas outside its band [0.5 %, 99.5 %], each group's
// variance factor outside its band (ba/variance_components.h), and every observation listed as
// an outlier or rejected (the first kMaxListedOutliers by name, then how many more).
constexpr int kMaxListedOutliers = 10;
std::vector<std::string> SolveWarnings(const BaResult& result);

// The covariance of `blocks` (ambient parameters, as BaResult::ObservationCovariance: without a
// considered calibration's part) by ceres::Covariance
// over the same Ceres problem at the solution: `algorithm` one of ceres::Covariance's (not
// kSchur). The reference the Schur covariance is tested against, and the configs'
// alternative covariance algorithms.
StatusOr<Eigen::MatrixXd> CeresBlockCovariance(const BaProblem& problem,
                                               const BaOptions& options,
                                               const BaResult& result,
                                               const std::vector<int>& blocks,
                                               CovarianceAlgorithm algorithm);

}  // namespace ba
}  // namespace carmba
