// Leave-one-marker-out target registration error (issue 11; shared/notes/joint-ba.md).
//
// For each marker k of a solved problem: solve the problem again without marker k (its CT prior
// and all its observations gone; an object view left with fewer than 4 markers is left out of
// that solve; observations the full solve rejected stay out), triangulate marker k from its
// pixels in the remaining object views (analysis/triangulation.h: the reduced solve's poses and
// intrinsics, with their covariance), and compare with its CT position:
//   e_k = p_triangulated - p_ct.
// What the covariance predicts, independently of the reduced solve (marker k is in neither its
// CT priors nor its pixels):  E[e e^T] = C_triangulated + C_ct,k, so
//   predicted_rms_mm = sqrt(tr(C_tri) + tr(C_ct,k))   (compare with |e_k|),
//   predicted_tre_mm = sqrt(tr(C_tri))                 (the error against the TRUE position).
// Beside it, Fitzpatrick, West & Maurer's formula for the same layout (IEEE TMI 17(5), 1998):
//   TRE^2 ~= FLE^2 / N (1 + 1/3 sum_a d_a^2 / f_a^2),
// N the remaining markers, d_a the target's distance from principal axis a of their
// configuration, f_a their RMS distance from it. It is a formula for 3-D/3-D point registration
// with isotropic localisation error; here FLE^2 = FLE_ct^2 + FLE_xray^2, the mean 3-D CT error of
// the markers (tr of their CT covariances) plus the mean 3-D error of their X-ray triangulation
// from pixel noise alone (the full solve's poses held). To compare with |e_k| the target's own
// localisation is added: fitzpatrick_rms_mm = sqrt(TRE_F^2 + tr(C_pixels,k) + tr(C_ct,k)).
// With a considered calibration (held intrinsics with a covariance) C_tri includes its part
// (analysis/triangulation.h), also given on its own (covariance_calibration).
#pragma once

#include <Eigen/Dense>
#include <string>
#include <vector>

#include "ba/bundle_adjuster.h"
#include "util/status.h"

namespace carmba {
namespace analysis {

// Fitzpatrick's <TRE^2> (mm^2) at `target` for `fiducials` (>= 3, not collinear) and <FLE^2>
// (mm^2, 3-D). Returns NaN for fewer than 3 fiducials or a collinear layout.
double FitzpatrickTre2(const std::vector<Eigen::Vector3d>& fiducials,
                       const Eigen::Vector3d& target,
                       double fle2_mm2);

struct MarkerTre {
  int marker_id = 0;
  std::string skipped;              // why it was not evaluated (empty: evaluated)
  int num_views = 0;                // views it was triangulated from
  int num_views_left_out = 0;       // object views left out of the reduced solve (< 4 markers)
  Eigen::Vector3d p_ct = Eigen::Vector3d::Zero();
  Eigen::Vector3d p_triangulated = Eigen::Vector3d::Zero();
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();     // of p_triangulated (solve + pixels)
  Eigen::Matrix3d covariance_pixels = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d covariance_calibration =
      Eigen::Matrix3d::Zero();  // considered calibration's part
  Eigen::Matrix3d ct_covariance = Eigen::Matrix3d::Zero();
  double error_mm = 0;              // |p_triangulated - p_ct|
  double predicted_rms_mm = 0;      // sqrt(tr(C_tri) + tr(C_ct))
  double predicted_tre_mm = 0;      // sqrt(tr(C_tri))
  double fitzpatrick_tre_mm = 0;    // the formula's registration part
  double fitzpatrick_rms_mm = 0;    // with the target's own localisation added
  double mahalanobis2 = 0;          // e^T (C_tri + C_ct)^-1 e (chi-square, 3 dof)
  double max_ray_angle_deg = 0;
};

struct TreResult {
  std::vector<MarkerTre> markers;   // problem.markers order
  int num_evaluated = 0;
  double rms_error_mm = 0;          // over the evaluated markers: sqrt(mean |e|^2)
  double rms_predicted_mm = 0;      // sqrt(mean predicted_rms^2)
  double rms_fitzpatrick_mm = 0;    // sqrt(mean fitzpatrick_rms^2)
  double mean_mahalanobis2_per_dof = 0;  // mean e^T C^-1 e / 3
  double fle_ct_mm = 0, fle_xray_mm = 0, fle_mm = 0;  // RMS 3-D localisation errors
  double time_s = 0;
};

// `options` as for the full solve (its reject_sigma is not used: the full solve's rejections are
// kept). Errors: the full result has no covariance. A marker that cannot be evaluated (seen in
// fewer than two views, a reduced problem the engine refuses) is listed with the reason.
StatusOr<TreResult> LeaveOneMarkerOut(const ba::BaProblem& problem,
                                      const ba::BaResult& full,
                                      const ba::BaOptions& options);

}  // namespace analysis
}  // namespace carmba
