// Test helpers shared by the engine's triangulation tests: object views of a synthetic joint
// problem, and pixels of a known point projected through the TRUE camera with Gaussian noise.
#pragma once

#include <random>
#include <vector>

#include "synthetic/synthetic_joint.h"
#include "analysis/triangulation.h"
#include "geometry/random_vector.h"

namespace carmba {
namespace ba {

inline std::vector<int> ObjectViews(const BaProblem& p) {
  std::vector<int> v;
  for (size_t i = 0; i < p.views.size(); ++i) {
    if (p.views[i].kind == ViewKind::kObject) v.push_back(static_cast<int>(i));
  }
  return v;
}

inline std::vector<analysis::PixelObservation> TruePointPixels(const SyntheticJoint& sj,
                                                     const Eigen::Vector3d& point,
                                                     const std::vector<int>& views,
                                                     double sigma_px,
                                                     std::mt19937_64* rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<analysis::PixelObservation> obs;
  for (int v : views) {
    analysis::PixelObservation o;
    o.view = v;
    ProjectPoint(sj.true_intrinsics.data(), sj.true_poses[v].data(), point.data(), o.uv_px.data());
    o.uv_px += sigma_px * RandomVector<2>(g, *rng);
    // Noise-free picks (sigma 0) still need a weight: equal weights give the same point.
    const double w = sigma_px > 0 ? sigma_px : 0.3;
    o.covariance_px2 = Eigen::Matrix2d::Identity() * w * w;
    obs.push_back(o);
  }
  return obs;
}

}  // namespace ba
}  // namespace carmba
