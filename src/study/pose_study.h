// The production run function of `carmba study`: pose problems (problem/problem.h,
// problem/pose_solver.h) solved with solver configurations, with Monte Carlo noise and accuracy
// against the truth; and synthetic intrinsic calibrations (calib/calibrate.h), see the end of
// this comment.
//
// Problem entries of a study file:
//   - name: thesis_tables
//     file: ../../problems/thesis_pose.yaml     # a pose problem file
//     options: {monte_carlo: resimulate}        # optional, see below
//   - name: sim_thesis_object
//     synthetic:                                # MakeSyntheticPoseProblem with ground truth
//       camera: ../../data/thesis/camera.json   # relative to the study file
//       markers: thesis                         # or a list of [x, y, z] (mm, object frame)
//       view_angles_deg: [0, 10, 30, 50, 90]    # optional (these are the defaults)
//       source_to_object_mm: 700
//       rotation_axis: [0, 1, 0]
//       base_rvec: [0.3, -0.4, 0.2]
//       pairs: [[0, 1], [0, 4], [2, 3]]         # view-index pairs compared (validation)
//       sigma_px: 0.5                           # defaults when the study does not sweep them
//       sigma_ct_mm: 0.1
//
// Problem-file Monte Carlo (`options.monte_carlo`):
//   none (default)  the measured data are solved as they are (every trial is the same solve);
//                   accuracy is against the problem's truth when it has one, and against the
//                   validation pairs' expected angles (e.g. the thesis's nominal C-arm angles).
//   resimulate      the measured data are solved once with the reference solver (SQPnP + bundle
//                   adjustment); those poses and the measured marker positions become the truth
//                   of a semi-synthetic problem with the real geometry, whose observations and
//                   markers are re-drawn per trial with Gaussian noise (pixel_noise_px, default
//                   the problem's sigma_px; ct_noise_mm, default 0.3 mm or the markers' own
//                   sigma).
//
// Swept variables understood (others are an error of the run, naming them):
//   pixel_noise_px  pixel noise sigma (synthetic / resimulate; also the whitening sigma_px)
//   ct_noise_mm     CT marker noise sigma (synthetic / resimulate)
//   num_views       use the first N views (>= 1)
//   k1              radial distortion k1 of the camera (synthetic only)
//
// The result of a run (the members the summary reads, study/run_store.h):
//   errors:        rotation_deg, translation_mm (RMS over views of the angle of R_est R_true^T
//                  and of |t_est - t_true|), tre_mm (RMS over views and markers of the true marker
//                  positions mapped by the estimated vs the true pose, in the camera frame),
//                  validation_deg (RMS over pairs of relative-rotation angle - expected)
//   signed_errors: v0_rx_deg, v0_ry_deg, v0_rz_deg (first view, small rotation about the camera
//                  axes, log(R_est R_true^T)), v0_tx_mm, v0_ty_mm, v0_tz_mm, and per validation
//                  pair pair_<a>_<b>_deg (relative rotation angle estimated - true)
//   sigmas:        the solver's 1-sigma for the same names (when it computed a covariance)
//   values:        rms_px, iterations, sigma0, chi2_p_value
//   converged, residuals_px (reprojection residuals, px, per coordinate)
//   budget:        predicted 1-sigma contributions of pixel noise and CT noise to the first
//                  view's rotation and translation (v0_rotation_deg.pixel_noise,
//                  v0_rotation_deg.ct_noise, v0_translation_mm.*): the covariance
//                  (A_px + A_ct)^-1 split as Sigma A_px Sigma + Sigma A_ct Sigma (trivial loss,
//                  refined configs only; their squares add up to the reported variance)
//
// Calibration problems (synthetic only; their configs are calibration option files such as
// configs/calib_thesis.yaml, read with LoadCalibrationOptions):
//   - name: thesis_plate
//     synthetic:
//       kind: calibration
//       camera: ../../data/thesis/camera.json   # the true intrinsics and image size
//       pattern: circles                        # circles | acircles | chessboard
//       rows: 5
//       cols: 5
//       spacing_mm: 20
//       num_views: 16
//       noise_px: 0.3                           # default when pixel_noise_px is not swept
//       min_tilt_deg: 5, max_tilt_deg: 30, distance_min_mm: 650, distance_max_mm: 850,
//       max_offset_fraction: 0.6                # optional (synthetic/synthetic_views.h)
// Swept variables: pixel_noise_px, num_views, k1 (true radial distortion).
// Result: errors focal_px (RMS of the fx and fy errors), principal_point_px; signed_errors and
// sigmas per free intrinsic (fx_px, fy_px, cx_px, cy_px, k1, ...); values rms_px, iterations,
// sigma_px, projection_sigma_worst_px.
#pragma once

#include "study/runner.h"

namespace carmba {

// A run function for pose studies. Problems, configs and reference solutions are loaded once
// and cached (thread-safe); the solver runs single-threaded (num_threads forced to 1).
RunFunction PoseStudyRunFunction();

}  // namespace carmba
