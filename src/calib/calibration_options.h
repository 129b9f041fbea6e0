// How a calibration is solved (the calibration config, configs/calib_*.yaml), and its reader.
// Apart from the engine and its front end (calib/calibrate.h), so that a reader of the config
// needs neither.
#pragma once

#include <string>
#include <vector>

#include "problem/solver_config.h"
#include "util/status.h"

namespace carmba {

struct CalibrationOptions {
  // The solve, in the solver config's vocabulary and read by its reader (problem/solver_config.h
  // ReadSolveKeys: loss, outliers, backend, max_iterations, num_threads, fix, distortion; the
  // calibration config's older spellings are translated where it is read,
  // LoadCalibrationOptions). Defaults: backend carmba_lm, the rest as a solver config's.
  // fix: intrinsics held at their initial values, by name (fx fy cx cy k1 k2 p1 p2 k3).
  // distortion_auto: the distortion terms chosen by the data (k1 k2 | + p1 p2 | + k3 | all;
  // analysis/lens_models.h), the others held at 0; excludes zero_tangential, fix_k3 and
  // distortion names in `fix`. loss: trivial, huber, cauchy or soft_l1 on each point's whitened
  // residual norm, scale in px. outlier_sigma: points whose residual norm exceeds this many
  // sigmas are listed as outliers in the report (the calibration does not drop them:
  // reject_sigma must be 0). backend: carmba_lm, carmba's Schur-complement Levenberg-Marquardt
  // (plain least squares; with a robust loss Ceres is used), or ceres (DENSE_SCHUR, same cost).
  SolverConfig solve = DefaultCalibrationSolve();
  // fy = aspect_ratio_fy_over_fx * fx. The ratio: the given one, or (when 0) the closed-form
  // initial estimate's.
  bool fix_aspect_ratio = false;
  double aspect_ratio_fy_over_fx = 0;
  // p1 = p2 = 0, held.
  bool zero_tangential = false;
  // cx, cy held at principal_point_px, or at the image centre ((w-1)/2, (h-1)/2) when empty.
  bool fix_principal_point = false;
  std::vector<double> principal_point_px;
  // k3 = 0, held.
  bool fix_k3 = false;
  // Optional full initial intrinsics (9 values), replacing the closed-form initialisation of the
  // intrinsics (poses are still initialised from homographies).
  std::vector<double> initial_intrinsics;

  // Pixel noise sigma used to whiten and for the covariance; 0 = estimate from the residuals.
  double pixel_sigma_px = 0;
  // Calibration fails if fewer views remain.
  int min_views = 3;
  // Distance (mm, along the ray) for the projection uncertainty; 0 = the median plate distance.
  double uncertainty_distance_mm = 0;

  // The solve's checks (SolverConfig::Check) and the calibration's own.
  bool Check(std::string* error) const;
  // The solve as the engine runs it: `solve` with backend carmba_lm only without a robust loss
  // (ceres otherwise), Ceres's DENSE_SCHUR, the a-priori covariance scale (the calibration scales
  // by its own pixel sigma). Its ToBaOptions() is the one mapping of every problem kind onto the
  // engine's options.
  SolverConfig ToSolverConfig() const;

 private:
  static SolverConfig DefaultCalibrationSolve();
};

// Reads a calibration config (YAML, top-level keys = the field names above): how the calibration
// is solved, nothing else. Unknown keys are errors; `detection` and `crosscheck` (which older
// configs held) are errors naming where they went: the problem or --detection, and flags. The
// loss, the outlier listing and the back end are also read in the solver config's vocabulary:
// loss: {type: trivial | huber | cauchy, scale_px}, outliers: {list_sigma}, backend:
// carmba_lm | ceres; the older spelling (robust_loss none | huber | cauchy, robust_loss_scale_px,
// outlier_threshold_sigma, solver lm | ceres) is translated here, once.
Status LoadCalibrationOptions(const std::string& path, CalibrationOptions* options);

}  // namespace carmba
