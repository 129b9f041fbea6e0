#include "calib/truth_check.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "camera/camera_model.h"

namespace carmba {
namespace {

struct Accumulator {
  TruthCheckRegion r;
  double ss = 0;
  int within = 0;

  void Add(double u, double v, const Eigen::Vector2d& diff, const Eigen::Vector2d& sigma) {
    ++r.num_pixels;
    ss += diff.squaredNorm();
    r.max_diff_px = std::max(r.max_diff_px, diff.norm());
    double worst = 0;
    for (int c = 0; c < 2; ++c) {
      const double n = std::abs(diff[c]) / sigma[c];
      worst = std::max(worst, n);
      if (n > r.max_sigmas) {
        r.max_sigmas = n;
        char buf[160];
        std::snprintf(buf, sizeof buf, "pixel (%.0f, %.0f) %c: error %.4f px, sigma %.4f px", u, v,
                      c ? 'v' : 'u', diff[c], sigma[c]);
        r.worst = buf;
      }
    }
    if (worst <= 3.0) ++within;
  }
  TruthCheckRegion Finish() {
    if (r.num_pixels > 0) {
      r.rms_diff_px = std::sqrt(ss / r.num_pixels);
      r.fraction_within_3_sigma = static_cast<double>(within) / r.num_pixels;
    }
    return r;
  }
};

}  // namespace

StatusOr<TruthCheck> CompareWithTruth(const CalibrationResult& result,
                                      const Camera& truth,
                                      const ObservationSet& observations,
                                      int grid) {
  const Camera& est = result.camera;
  if (truth.width != est.width || truth.height != est.height) {
    return Status::Error("truth: image size " + std::to_string(truth.width) + " x " +
                         std::to_string(truth.height) + " differs from the calibrated " +
                         std::to_string(est.width) + " x " + std::to_string(est.height));
  }
  if (grid < 2) return Status::Error("truth check: grid must be >= 2");
  if (!(result.covariance.diagonal().array() > 0).any()) {
    return Status::Error("truth check: no intrinsic was estimated (no covariance)");
  }
  // Convex hull of the detections: the region the calibration observed.
  std::vector<cv::Point2f> pts, hull;
  for (const auto& v : observations.views) {
    for (const auto& q : v.uv_px) {
      pts.emplace_back(static_cast<float>(q.x()), static_cast<float>(q.y()));
    }
  }
  if (pts.size() >= 3) cv::convexHull(pts, hull);

  Accumulator image, observed;
  for (int iy = 0; iy < grid; ++iy) {
    for (int ix = 0; ix < grid; ++ix) {
      const double q[2] = {(est.width - 1) * ix / double(grid - 1),
                           (est.height - 1) * iy / double(grid - 1)};
      double xy[2];
      if (!UnprojectToNormalized(truth.params.data(), q, xy)) continue;
      const double p[3] = {xy[0], xy[1], 1.0};
      double uv[2], J[2 * kNumIntrinsics];
      if (!ProjectCamPointWithJac(est.params.data(), p, uv, J, nullptr)) continue;
      const Eigen::Map<const Eigen::Matrix<double, 2, kNumIntrinsics, Eigen::RowMajor>> Jq(J);
      const Eigen::Matrix2d C = Jq * result.covariance * Jq.transpose();
      const Eigen::Vector2d sigma = C.diagonal().cwiseMax(0).cwiseSqrt();
      if (!(sigma.array() > 0).all() || !sigma.allFinite()) continue;
      const Eigen::Vector2d diff(uv[0] - q[0], uv[1] - q[1]);
      if (!diff.allFinite()) continue;
      image.Add(q[0], q[1], diff, sigma);
      if (hull.size() >= 3 &&
          cv::pointPolygonTest(
              hull, cv::Point2f(static_cast<float>(q[0]), static_cast<float>(q[1])), false) >= 0) {
        observed.Add(q[0], q[1], diff, sigma);
      }
    }
  }
  TruthCheck out;
  out.image = image.Finish();
  out.observed = observed.Finish();
  if (out.image.num_pixels == 0) {
    return Status::Error("truth check: no grid pixel could be projected");
  }
  return out;
}

}  // namespace carmba
