#include "ba/variance_components.h"

#include <cmath>
#include <cstdio>

#include "util/stats.h"

namespace carmba {
namespace ba {

double VarianceComponent::SigmaScale() const { return applied ? std::sqrt(factor) : 1.0; }

std::array<double, kNumNoiseGroups> GroupRedundancies(const StateLayout& layout,
                                                      const Linearization& lin,
                                                      const SchurCovariance& covariance,
                                                      const GroupResiduals& residuals) {
  std::array<double, kNumNoiseGroups> red{};
  for (int k = 0; k < kNumNoiseGroups; ++k) red[k] = residuals.rows[k];
  const int n = covariance.num_free();
  if (n == 0) return red;
  // sum_i a_i^T C a_i over ALL rows is trace(C H) = n: the group with the most rows gets its
  // share by subtraction, so C is needed only over the blocks the other groups' rows touch.
  int largest = 0;
  for (int k = 1; k < kNumNoiseGroups; ++k) {
    if (residuals.rows[k] > residuals.rows[largest]) largest = k;
  }
  std::vector<int> column_of(n, -1), columns;
  for (const LinearizedBlock& row : lin.rows) {
    if (static_cast<int>(row.group) == largest) continue;
    for (int b : row.blocks) {
      const BlockInfo& bi = layout.block(b);
      for (size_t c = 0; c < bi.free.size(); ++c) {
        const int k = bi.free_offset + static_cast<int>(c);
        if (column_of[k] < 0) column_of[k] = static_cast<int>(columns.size()), columns.push_back(k);
      }
    }
  }
  Eigen::MatrixXd E = Eigen::MatrixXd::Zero(n, static_cast<Eigen::Index>(columns.size()));
  for (size_t c = 0; c < columns.size(); ++c) E(columns[c], static_cast<Eigen::Index>(c)) = 1;
  const Eigen::MatrixXd C = E.transpose() * covariance.Solve(E);  // over `columns`
  double others = 0;
  std::vector<int> idx;
  for (const LinearizedBlock& row : lin.rows) {
    if (static_cast<int>(row.group) == largest) continue;
    idx.clear();
    for (int b : row.blocks) {
      const BlockInfo& bi = layout.block(b);
      for (size_t c = 0; c < bi.free.size(); ++c)
        idx.push_back(column_of[bi.free_offset + static_cast<int>(c)]);
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
    for (size_t a = 0; a < idx.size(); ++a) {
      for (size_t b = 0; b < idx.size(); ++b) Csub(a, b) = C(idx[a], idx[b]);
    }
    const double t = (A * Csub * A.transpose()).trace();
    red[static_cast<int>(row.group)] -= t;
    others += t;
  }
  red[largest] -= n - others;
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
    const char* action = c.applied
                             ? "the covariances are scaled by it (covariance.scale: per_group)"
                         : scale == CovarianceScale::kGlobal
                             ? "one global factor scales the covariances (covariance.scale: global)"
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
