// Is the lens model adequate? The candidate distortion models of the OPENCV5 family compared on
// the plate views (issue 21 §3): a C-arm's tangential distortion held at zero moves the
// principal point by several sigma while the chi-square stays unremarkable, so the comparison
// does not rest on the chi-square of one fit.
//
// CANDIDATES (fx fy cx cy as the problem has them; the distortion terms not in the model held at
// zero): k1 k2 | k1 k2 p1 p2 | k1 k2 k3 | k1 k2 p1 p2 k3.
//
// SCORES, each from the plate views alone (a calibration; object views and markers left out):
//   * the full fit: chi2 at the stated sigmas, free parameters k, residuals n;
//       AIC = chi2 + 2k,  BIC = chi2 + k ln(n);
//     its principal point with covariance;
//   * held-out (k-fold over the plate views, view i in fold i mod k): the intrinsics the model
//     would take without the fold (one Gauss-Newton step from the full fit, the poses eliminated:
//     exact for a linear model, no further solve), then the fold's views with the intrinsics held
//     there and only their poses free; the held-out chi2 per residual and RMS.
// RECOMMENDATION: the lowest AIC (the expected held-out log-likelihood; a term is kept when it
// lowers the chi-square by more than 2 per parameter) -- unless a model with more terms moves the
// principal point by more than kPrincipalPointWarnSigma of the AIC-best's sigma. In a C-arm's
// narrow field of view p1, p2 trade almost one to one with cx, cy: the chi-square cannot tell
// them apart, and a radial-only fit of a C-arm with tangential distortion puts the principal
// point several of its (too small) sigmas off. When the answer depends on a choice the data
// cannot make, the larger model is recommended: its sigmas carry the trade-off. The held-out
// scores and BIC are reported beside it, and the reason says what decided.
//
// WARNING: a solve whose distortion model is another candidate, and whose principal point lies
// more than kPrincipalPointWarnSigma of its own sigmas (Mahalanobis, that model's plate fit's
// covariance) from the recommended model's, is warned about, naming both models.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "ba/bundle_adjuster.h"
#include "ba/problem.h"
#include "util/status.h"

namespace carmba {
namespace analysis {

enum class DistortionModel { kRadial2, kRadial2Tangential, kRadial3, kFull };
constexpr std::array<DistortionModel, 4> kDistortionModels{
    DistortionModel::kRadial2, DistortionModel::kRadial2Tangential, DistortionModel::kRadial3,
    DistortionModel::kFull};
// "k1 k2", "k1 k2 p1 p2", "k1 k2 k3", "k1 k2 p1 p2 k3".
const char* DistortionModelName(DistortionModel m);
// The candidate whose free distortion terms are `free`'s (k1 k2 p1 p2 k3); false if none is.
bool DistortionModelOf(const std::array<bool, kNumIntrinsics>& free, DistortionModel* out);
// Frees the model's distortion terms in every group and holds the others at zero.
void ApplyDistortionModel(DistortionModel m, ba::BaProblem* problem);

constexpr double kPrincipalPointWarnSigma = 2.0;
constexpr int kDistortionFolds = 5;

struct DistortionScore {
  DistortionModel model = DistortionModel::kRadial2;
  bool ok = false;
  std::string error;
  int num_free = 0, num_residuals = 0;
  double chi2 = 0, aic = 0, bic = 0;
  double held_out_chi2_per_residual = 0, held_out_rms_px = 0;
  std::array<double, kNumIntrinsics> intrinsics{};
  std::vector<Pose6> plate_poses;  // the fit's, in the order of the problem's plate views
  Eigen::Vector2d principal_point = Eigen::Vector2d::Zero();
  Eigen::Matrix2d principal_point_covariance = Eigen::Matrix2d::Zero();
};

struct DistortionSelection {
  std::vector<DistortionScore> scores;  // kDistortionModels order
  DistortionModel recommended = DistortionModel::kRadial2;
  int folds = 0;
  // With an unknown pixel sigma (a calibration without pixel_sigma_px): every chi-square is at
  // the sigma the full model's residuals give, sqrt(chi2 / dof) of its fit, and every covariance
  // scaled to it (AIC needs the noise level; the largest model's is the least biased).
  bool sigma_estimated = false;
  double sigma_px = 0;
  std::string why;
  const DistortionScore* Score(DistortionModel m) const;
};

// Errors: no plate views, more than one intrinsics group or a smooth one, fewer than 2 plate
// views for the folds, every candidate failing.
StatusOr<DistortionSelection> SelectDistortionModel(const ba::BaProblem& problem,
                                                    const ba::BaOptions& options,
                                                    int folds = kDistortionFolds,
                                                    bool estimate_sigma = false);

// The fit's intrinsics (every group) and plate poses (the problem's plate views in order, as in
// the problem the selection ran on) as `problem`'s initial values: a solve with the fit's model
// then starts at the plate views' optimum.
void StartFromFit(const DistortionScore& fit, ba::BaProblem* problem);

// The warning of a solve with distortion model `solved` and principal point (cx, cy) (empty when
// it is the recommended model or within kPrincipalPointWarnSigma of it).
std::string DistortionWarning(const DistortionSelection& selection,
                              DistortionModel solved,
                              const Eigen::Vector2d& solved_principal_point);

}  // namespace analysis
}  // namespace carmba
