#include "calib/conditioning.h"

#include <cmath>
#include <sstream>

namespace carmba {

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
  return out;
}

}  // namespace carmba
