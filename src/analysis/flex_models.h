// Intrinsics models of a C-arm whose geometry may depend on its orientation (issue 14), and
// their selection by held-out orientation groups.
//
// MODELS (applied to a problem whose views carry C-arm angles, ba/problem.h BaView):
//   shared:    one set of intrinsics for every view (a rigid C-arm).
//   per_group: one set per ORIENTATION GROUP -- the plate views' distinct (primary, secondary)
//              angle pairs (to 0.01 deg); an object view takes the group of the nearest plate
//              orientation (Euclidean in degrees).
//   smooth:    fx, fy, cx, cy as functions of the angles (ba/smooth_intrinsics.h), distortion
//              shared; an object view between calibrated angles takes the model at its angle.
//
// SELECTION. For each model:
//   * the full fit's chi2, number of free parameters k and residuals n:
//       AIC = chi2 + 2k,  BIC = chi2 + k ln(n)   (Gaussian likelihood with known sigmas, up to
//       a constant common to the models);
//   * held-out prediction: for each plate orientation group o in turn, the model is fitted to the
//     plate views of the OTHER groups, its intrinsics at o's angles are predicted (shared: the one
//     set; per_group: the nearest remaining group's; smooth: A(o) c), and o's plate views are
//     fitted with the intrinsics held at the prediction and only their poses free. The
//     prediction error is the RMS of those residuals (px per coordinate) and their chi2 per
//     residual, and -- since a pose absorbs most of an intrinsics error (a principal point shift
//     is nearly a rotation) -- the Mahalanobis distance of the predicted intrinsics from group o's
//     own calibration (its plate views alone, fx fy cx cy), with both covariances:
//       d2 = (x_pred - x_o)^T (C_pred + C_o)^-1 (x_pred - x_o),  E[d2] = 4 if the model holds.
//   The recommendation: the model with the lowest total held-out d2 per group, unless a simpler
//   model's is within the noise (below 4 + 2 sqrt(8)/sqrt(groups), i.e. consistent with its own
//   uncertainty), in which case the simplest consistent one (shared < smooth < per_group by
//   number of parameters). The reason is written out.
#pragma once

#include <string>
#include <vector>

#include "ba/bundle_adjuster.h"
#include "ba/problem.h"
#include "util/status.h"

namespace carmba {
namespace analysis {

enum class IntrinsicsModel { kShared, kPerGroup, kSmooth };
const char* IntrinsicsModelName(IntrinsicsModel m);

// The plate views' orientation groups: distinct angle pairs (deg), in order of first appearance.
std::vector<std::pair<double, double>> PlateOrientations(const ba::BaProblem& problem);

// Replaces problem->groups by the model's groups (template: problem->groups[0]'s initial values,
// free mask, image size) and sets every view's group. Errors: a view without angles under
// per_group or smooth (naming it), a smooth model with fewer orientation groups than
// coefficients (naming the counts; ba/problem.h Check).
Status ApplyIntrinsicsModel(IntrinsicsModel model,
                            const ba::SmoothBasis& basis,
                            ba::BaProblem* problem);

struct HeldOutGroup {
  std::string orientation;
  double rms_px = 0;         // held-out plate residuals, poses refitted, intrinsics predicted
  double chi2_per_residual = 0;
  double d2 = 0;             // Mahalanobis distance of the prediction from the group's own fit
};

struct ModelScore {
  IntrinsicsModel model;
  bool ok = false;
  std::string error;
  int num_free = 0, num_residuals = 0;
  double chi2 = 0, aic = 0, bic = 0;
  std::vector<HeldOutGroup> held_out;
  double held_out_rms_px = 0;     // over all held-out residuals
  double held_out_d2_mean = 0;    // mean d2 per group
};

struct ModelSelection {
  std::vector<ModelScore> scores;
  IntrinsicsModel recommended = IntrinsicsModel::kShared;
  std::string why;
};

// `problem`: views with angles (object views are ignored: the selection uses the plate views).
StatusOr<ModelSelection> SelectIntrinsicsModel(const ba::BaProblem& problem,
                                               const ba::SmoothBasis& basis,
                                               const ba::BaOptions& options,
                                               const std::vector<IntrinsicsModel>& models);

}  // namespace analysis
}  // namespace carmba
