// Variance components per observation group (Förstner 1979; Koch, "Parameter Estimation and
// Hypothesis Testing in Linear Models", sec. 3.6): does each group's stated noise hold, and how
// much larger or smaller is it?
//
// Groups: the residual blocks of a bundle adjustment by where their noise comes from (finer than
// the error budget's sources, ba/problem.h: object pixels picked by hand and marker blobs found
// by the detector are different noise models although both are "object pixels").
//
// After a solve with whitened residuals v and whitened Jacobian A (loss-corrected), the
// redundancy number of a residual row i is  r_i = 1 - a_i^T (A^T A)^-1 a_i  (the diagonal of
// I - A (A^T A)^-1 A^T); a group's redundancy is r_k = sum of its rows' r_i (rows that touch no
// free parameter count 1 each), and the redundancies of all groups add up to the degrees of
// freedom n - u. The group's variance factor is estimated as
//     f_k = v_k^T v_k / r_k,      sigma(f_k) ~ f_k sqrt(2 / r_k),
// and in the iterated estimate the group's sigmas are multiplied by sqrt(f_k) and the problem
// solved again until every factor of the rescaled problem is 1 (ba/bundle_adjuster.cc). A group
// whose redundancy is under `min_redundancy` cannot be estimated: its stated sigmas are kept.
//
// The band: the chi-square of the group at its STATED sigmas, v_k^T v_k (stated), is compared
// with a chi-square distribution of r_k degrees of freedom; outside [0.5 %, 99.5 %] it is flagged
// (the stated sigmas are too small or too large for the data).
#pragma once

#include <array>
#include <string>
#include <vector>

#include "ba/covariance.h"
#include "ba/problem.h"
#include "util/enum_names.h"

namespace carmba {
namespace ba {

// How the covariance is scaled (config `covariance.scale`).
enum class CovarianceScale {
  kApriori,   // the stated sigmas; the components are estimated and reported only
  kPerGroup,  // each estimable group's sigmas scaled by its factor, iterated (the default)
  kGlobal     // one a-posteriori factor for all: robust_chi2 / dof, sigma0^2 without a loss
              // (formerly `aposteriori`)
};
// Names (util/enum_names.h); "aposteriori" is the former name of global.
inline constexpr EnumName<CovarianceScale> kCovarianceScaleNames[] = {
    {CovarianceScale::kPerGroup, "per_group"},
    {CovarianceScale::kApriori, "apriori"},
    {CovarianceScale::kGlobal, "global"},
    {CovarianceScale::kGlobal, "aposteriori"}};

constexpr double kMinVarianceComponentRedundancy = 20;
constexpr double kVarianceBandTail = 0.005;  // two-sided band [0.5 %, 99.5 %]

struct VarianceComponent {
  NoiseGroup group = NoiseGroup::kPlatePixels;
  int num_rows = 0;           // scalar residuals of the group
  double redundancy = 0;      // r_k
  double chi2_stated = 0;     // v_k^T v_k at the stated sigmas (at the final solution)
  double factor = 1;          // f_k, the variance factor: true sigma^2 / stated sigma^2
  double factor_sigma = 0;    // f_k sqrt(2 / r_k)
  double p_value = 1;         // P(X > chi2_stated), X ~ chi-square(r_k)
  bool estimable = false;     // r_k >= kMinVarianceComponentRedundancy
  bool applied = false;       // in the weights of the final solve and so in every covariance
  bool outside_band = false;  // p_value outside [kVarianceBandTail, 1 - kVarianceBandTail]
  double SigmaScale() const;  // sqrt(factor) when applied, else 1
};

// The per-group sums of one evaluation at the solution: rows and chi-square at the weights the
// problem was solved with (the stated sigmas times `scale`).
struct GroupResiduals {
  std::array<int, kNumNoiseGroups> rows{};
  std::array<double, kNumNoiseGroups> chi2{};
};

// The redundancy of each group: its rows minus sum over its linearised rows of a_i^T C a_i
// (C = H^-1 over the free state; dense, from `covariance`).
std::array<double, kNumNoiseGroups> GroupRedundancies(const StateLayout& layout,
                                                      const Linearization& lin,
                                                      const SchurCovariance& covariance,
                                                      const GroupResiduals& residuals);

// The components of the groups that have rows, given the residuals and redundancies of a solve
// whose group sigmas were the stated ones times `scale` (so f_k = scale_k^2 chi2_k / r_k and
// chi2_stated = scale_k^2 chi2_k); `applied` marks the groups whose scale is in the weights.
std::vector<VarianceComponent> VarianceComponents(
    const GroupResiduals& residuals,
    const std::array<double, kNumNoiseGroups>& redundancy,
    const std::array<double, kNumNoiseGroups>& scale,
    const std::array<bool, kNumNoiseGroups>& applied);

// One sentence per flagged group, e.g. "detected blobs: the residuals are 2.1 +- 0.3 times the
// stated variance (chi-square 171 on redundancy 82, P = 3e-08); the covariances are scaled by
// it per group (covariance.scale: per_group)". Empty when every group is within its band.
std::vector<std::string> VarianceComponentWarnings(const std::vector<VarianceComponent>& components,
                                                   CovarianceScale scale);

}  // namespace ba
}  // namespace carmba
