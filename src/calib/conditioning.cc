#include "calib/conditioning.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>
#include <utility>

namespace carmba {

std::vector<std::string> IntrinsicsCorrelationWarnings(const Eigen::MatrixXd& cov,
                                                       const std::string& group) {
  std::vector<std::pair<double, std::string>> found;
  const int n = static_cast<int>(std::min<Eigen::Index>(cov.rows(), kNumIntrinsics));
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      const double den = std::sqrt(cov(i, i) * cov(j, j));
      if (!(den > 0)) continue;  // a held parameter
      const double c = cov(i, j) / den;
      if (!(std::abs(c) > kIntrinsicsCorrelationWarn)) continue;
      std::ostringstream w;
      w << (group.empty() ? "" : group + ": ") << kIntrinsicNames[i] << " and "
        << kIntrinsicNames[j] << " correlate at " << std::fixed << std::setprecision(4) << c
        << " (|r| > " << std::setprecision(2) << kIntrinsicsCorrelationWarn
        << "): the data determine little more than one combination of them, so their separate "
           "values and sigmas mean little; "
        << (j >= kK1 ? "hold the distortion term (fix_k3, zero_tangential: "
                       "configs/calib_radial.yaml) only if the lens is known to lack it (held, "
                       "the other parameter's sigma no longer carries the trade-off), or add "
                       "views that separate them."
                     : "add views that separate them (stronger tilts, a wider range of "
                       "distances).");
      found.emplace_back(std::abs(c), w.str());
    }
  }
  std::stable_sort(found.begin(), found.end(),
                   [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<std::string> out;
  for (auto& f : found) out.push_back(std::move(f.second));
  return out;
}

ConditioningReport AssessConditioning(const CalibrationResult& r, int width, int height) {
  ConditioningReport out;
  for (int pp : {kCx, kCy}) {
    if (!r.free[pp]) continue;
    for (int d = kK1; d < kNumIntrinsics; ++d) {
      if (!r.free[d]) continue;
      const double den = std::sqrt(r.covariance(pp, pp) * r.covariance(d, d));
      if (!(den > 0)) continue;
      const double c = std::abs(r.covariance(pp, d) / den);
      if (c > out.max_pp_distortion_correlation) {
        out.max_pp_distortion_correlation = c;
        out.max_pp_distortion_pair = std::string(kIntrinsicNames[pp]) + "-" + kIntrinsicNames[d];
      }
    }
  }
  const bool tangential_free = r.free[kP1] || r.free[kP2];
  for (int pp : {kCx, kCy}) {
    if (!r.free[pp]) continue;
    const double size = pp == kCx ? width : height;
    const double fraction = r.sigma[pp] / size;
    if (!(fraction > kPrincipalPointSigmaWarnFraction)) continue;
    std::ostringstream w;
    w.precision(3);
    w << kIntrinsicNames[pp] << " is weakly determined (sigma " << r.sigma[pp] << " px = "
      << 100 * fraction << " % of the image): the linearised sigmas of cx, cy may understate their "
      << "real spread (seeded Monte Carlo on C-arm geometries at this level: 1.5-1.8x).";
    if (tangential_free) {
      w << " The free tangential terms trade with the principal point (largest correlation "
        << out.max_pp_distortion_pair << " " << out.max_pp_distortion_correlation
        << "): hold them (zero_tangential: true, and fix_k3: true as the thesis did: "
           "configs/calib_radial.yaml), or add "
           "more strongly tilted views or more precise detections.";
    } else {
      w << " Add more strongly tilted views or more precise detections, or hold the principal "
           "point.";
    }
    out.warnings.push_back(w.str());
  }
  for (auto& w : IntrinsicsCorrelationWarnings(r.covariance)) out.warnings.push_back(std::move(w));
  return out;
}

}  // namespace carmba
