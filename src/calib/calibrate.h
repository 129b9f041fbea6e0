// Intrinsic calibration of a C-arm (or any OPENCV5 camera) from views of a planar grid: a thin
// front end of the bundle-adjustment engine (ba/bundle_adjuster.h). It initialises in closed form,
// fills a ba::BaProblem -- one intrinsics group [fx, fy, cx, cy, k1, k2, p1, p2, k3], one
// cam_from_plate = (rvec, t) per view, the plate's points held at the nominal grid -- and lets the
// engine solve it (backend carmba_lm, carmba's Schur LM, for `solver: lm` without a robust loss;
// Ceres DENSE_SCHUR otherwise) and compute the covariance (ba/covariance.h):
//
//   residual of point j in view i:  r_ij = (project(intrinsics, pose_i, P_j) - q_ij) / sigma_px
//
// Initialisation: closed form, Zhang's homography method (calib/zhang_init.h).
//
// Constraints (the thesis's OpenCV flags): fixed parameters, a fixed aspect ratio fy = r fx, zero
// tangential distortion, a fixed principal point and fixed k3 are the engine's free mask and tie
// (IntrinsicsGroup::fy_over_fx): intrinsics = x0 + A delta, so the covariance of the free
// parameters delta maps to the 9x9 covariance A Cov(delta) A^T (zero rows for fixed parameters).
//
// Covariance: Cov(theta) = sigma^2 (J^T J)^-1 with J the unwhitened Jacobian at the solution and
// sigma the pixel noise (given, or the engine's a-posteriori estimate, sqrt(SSR / (2N - n_free)),
// with a robust loss the IRLS-weighted SSR: BaResult::robust_chi2). The intrinsics block
// is marginal over the plate poses (the engine's Schur complement eliminates them).
// Projection uncertainty at a pixel and a distance: mrcal's definition,
// calib/projection_uncertainty.h.
#pragma once

#include <Eigen/Core>
#include <array>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "analysis/lens_models.h"
#include "ba/bundle_adjuster.h"
#include "calib/calibration_options.h"
#include "camera/camera.h"
#include "detect/observations.h"
#include "geometry/pose.h"
#include "util/status.h"

namespace carmba {

struct ViewStats {
  std::string image;
  int num_points = 0;
  double rms_px = 0;  // per coordinate
  double max_px = 0;  // largest residual norm
  double tilt_deg = 0;    // angle between the plate normal and the optical axis
  double distance_mm = 0; // |t|
};

struct PointStats {
  int point_id = 0;
  int num_views = 0;
  double rms_px = 0;  // per coordinate
};

struct PointResidual {
  int view = 0;
  int point_id = 0;
  double du_px = 0, dv_px = 0;  // projection - observed
  double norm_px = 0;
};

struct ProjectionSigma {
  std::string where;         // "centre", "top-left", ...
  double u_px = 0, v_px = 0; // the pixel
  double sigma_u_px = 0, sigma_v_px = 0;
  double worst_px = 0;       // sqrt of the largest eigenvalue of Cov(q) (mrcal's worstdirection)
};

struct CalibrationResult {
  Camera camera;  // estimate with covariance (names = all 9; fixed ones have zero rows)
  std::array<double, kNumIntrinsics> initial_intrinsics{};
  std::vector<Pose6> cam_from_plate;  // rvec (rad), t (mm) per view
  std::vector<Pose6> initial_cam_from_plate;  // closed-form poses
  Eigen::Matrix<double, kNumIntrinsics, kNumIntrinsics> covariance;  // marginal over poses
  std::array<double, kNumIntrinsics> sigma{};  // sqrt(diag(covariance))
  std::vector<bool> free;                      // per intrinsic: estimated (not held)
  int num_free_intrinsics = 0;
  // With distortion_auto: the models compared and the one applied.
  std::optional<analysis::DistortionSelection> distortion;
  Eigen::MatrixXd intrinsics_from_free;        // A (9 x k): intrinsics = x0 + A delta
  ba::Loss loss = ba::Loss::kTrivial;          // as solved (the covariance weights by it)
  double loss_scale_px = 1.0;

  double sigma_px = 0;          // the pixel sigma used for whitening and covariance
  bool sigma_estimated = false;  // true if estimated from the residuals (the engine's robust_chi2)
  int num_points = 0;           // observed points (2 residuals each)
  int dof = 0;                  // 2N - free parameters (the engine's)
  double rms_px = 0;            // per-coordinate RMS, sqrt(SSR / 2N) (mrcal's figure; the engine's)
  double rms_opencv_px = 0;     // sqrt(SSR / N) = sqrt(2) rms_px (OpenCV's returned figure)
  std::vector<ViewStats> views;
  std::vector<PointStats> points;
  std::vector<PointResidual> worst;     // up to 10 largest residuals
  std::vector<PointResidual> outliers;  // norm > outlier_sigma * sigma_px
  double uncertainty_distance_mm = 0;
  std::vector<ProjectionSigma> projection_sigma;  // centre and the four corners

  // The final stage's iterations and termination: engine->iterations, engine->converged(),
  // engine->TerminationText().
  double solve_seconds = 0, covariance_seconds = 0;

  // The engine's solution (ba/bundle_adjuster.h): state, named layout, linearisation and Schur
  // covariance, whitened with the pixel sigma the solve used; covariance_scale, the engine's,
  // takes its covariance to `sigma_px` ((sigma_px / sigma used)^2: 1 for a given sigma).
  std::shared_ptr<const ba::BaResult> engine;
  double covariance_scale = 1.0;
};

// The observations the engine solved: `obs` (the calibration's input) minus the cone-beam shadow
// offsets it subtracted (BaResult::shadow_offsets; `obs` itself when none were). What a
// cross-check gives another solver, so that both fit the same pixels.
ObservationSet SolvedObservations(const ObservationSet& obs, const CalibrationResult& result);

// Calibrates. Errors: too few views, a view with < 4 points, initialisation failure (degenerate
// views), solver failure, a singular covariance (parameters not determined by the views).
StatusOr<CalibrationResult> Calibrate(const ObservationSet& observations,
                                      const CalibrationOptions& options);

// The solved plate's distance from the source, the median of the views' distance_mm, checked
// against plausible::kPlateDistanceMm. The solve is consistent at any scale: only the grid pitch
// fixes the distance, so a distance outside says the pitch is wrong (--spacing-mm 2 for 20 mm put
// the plate at 78 mm). The error names `pitch_source` (the flag or key the pitch came from) and
// the pitch, e.g.
//   the plate sits 78.1 mm from the source (median of 20 views), expected 100 .. 5000 mm: check
//   the grid pitch, --spacing-mm 2 (a unit slip? cm for mm)
Status CheckPlateDistance(const CalibrationResult& result,
                          double spacing_mm,
                          const std::string& pitch_source);

}  // namespace carmba
