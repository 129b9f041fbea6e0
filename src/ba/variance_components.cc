#include "ba/variance_components.h"

#include <cmath>
#include <cstdio>

#include "util/stats.h"

namespace carmba {
namespace ba {

const char* CovarianceScaleName(CovarianceScale s) {
  switch (s) {
    case CovarianceScale::kApriori:
      return "apriori";
    case CovarianceScale::kPerGroup:
      return "per_group";
    case CovarianceScale::kGlobal:
      return "global";
  }
  return "?";
}

bool ParseCovarianceScale(const std::string& name, CovarianceScale* out) {
  if (name == "apriori") {
    *out = CovarianceScale::kApriori;
  } else if (name == "per_group") {
    *out = CovarianceScale::kPerGroup;
  } else if (name == "global" || name == "aposteriori") {
    *out = CovarianceScale::kGlobal;
  } else {
    return false;
  }
  return true;
}

double VarianceComponent::SigmaScale() const { return applied ? std::sqrt(factor) : 1.0; }

std::array<double, kNumNoiseGroups> GroupRedundancies(const StateLayout& layout,
                                                      const Linearization& lin,
                                                      const SchurCovariance& covariance,
                                                      const GroupResiduals& residuals) {
  std::array<double, kNumNoiseGroups> red{};
  for (int k = 0; k < kNumNoiseGroups; ++k) red[k] = residuals.rows[k];
  const int n = covariance.num_free();
  if (n == 0) return red;
  const Eigen::MatrixXd C = covariance.Solve(Eigen::MatrixXd::Identity(n, n));
  std::vector<int> idx;
  for (const LinearizedBlock& row : lin.rows) {
    idx.clear();
    for (int b : row.blocks) {
      const BlockInfo& bi = layout.block(b);
      for (size_t c = 0; c < bi.free.size(); ++c) idx.push_back(bi.free_offset + static_cast<int>(c));
    }
    if (idx.empty()) continue;
    const Eigen::Index nr = row.J.front().rows();
    Eigen::MatrixXd A(nr, static_cast<Eigen::Index>(idx.size()));
    Eigen::Index col = 0;
    for (const Eigen::MatrixXd& J : row.J) {
      A.middleCols(col, J.cols()) = J;
      col += J.cols();
    }
    Eigen::MatrixXd Csub(idx.size(), idx.size());
    for (size_t i = 0; i < idx.size(); ++i) {
      for (size_t j = 0; j < idx.size(); ++j) Csub(i, j) = C(idx[i], idx[j]);
    }
    red[static_cast<int>(row.group)] -= (A * Csub * A.transpose()).trace();
  }
  return red;
}

std::vector<VarianceComponent> VarianceComponents(
    const GroupResiduals& residuals,
    const std::array<double, kNumNoiseGroups>& redundancy,
    const std::array<double, kNumNoiseGroups>& scale,
    const std::array<bool, kNumNoiseGroups>& applied) {
  std::vector<VarianceComponent> out;
  for (int k = 0; k < kNumNoiseGroups; ++k) {
    if (residuals.rows[k] == 0) continue;
    VarianceComponent c;
    c.group = static_cast<NoiseGroup>(k);
    c.num_rows = residuals.rows[k];
    c.redundancy = std::max(0.0, redundancy[k]);
    c.chi2_stated = scale[k] * scale[k] * residuals.chi2[k];
    c.estimable = c.redundancy >= kMinVarianceComponentRedundancy;
    c.applied = applied[k] && c.estimable;
    if (c.redundancy > 0.5) {
      c.factor = c.chi2_stated / c.redundancy;
      c.factor_sigma = c.factor * std::sqrt(2.0 / c.redundancy);
      c.p_value = RegularizedGammaQ(0.5 * c.redundancy, 0.5 * c.chi2_stated);
      c.outside_band = c.estimable &&
                       (c.p_value < kVarianceBandTail || c.p_value > 1.0 - kVarianceBandTail);
    } else {
      c.factor = 1;
      c.factor_sigma = 0;
      c.p_value = 1;
    }
    out.push_back(c);
  }
  return out;
}

std::vector<std::string> VarianceComponentWarnings(const std::vector<VarianceComponent>& components,
                                                   CovarianceScale scale) {
  std::vector<std::string> out;
  for (const VarianceComponent& c : components) {
    if (!c.outside_band) continue;
    char buf[400];
    const char* what = c.factor > 1 ? "larger" : "smaller";
    const char* action =
        c.applied                               ? "the covariances are scaled by it (covariance.scale: per_group)"
        : scale == CovarianceScale::kGlobal     ? "one global factor scales the covariances (covariance.scale: global)"
                                                : "the covariances use the stated sigmas (covariance.scale: apriori); "
                                                  "per_group would scale them";
    std::snprintf(buf, sizeof buf,
                  "%s: the residuals say the noise variance is %.3g +- %.2g times the stated one "
                  "(%s than stated; chi-square %.1f on redundancy %.1f, P = %.2g); %s",
                  NoiseGroupName(c.group), c.factor, c.factor_sigma, what, c.chi2_stated,
                  c.redundancy, c.p_value, action);
    out.push_back(buf);
  }
  return out;
}

}  // namespace ba
}  // namespace carmba
