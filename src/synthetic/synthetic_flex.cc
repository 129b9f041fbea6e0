#include "synthetic/synthetic_flex.h"

#include <cmath>
#include <cstdio>
#include <random>

#include "geometry/random_vector.h"
#include "util/random.h"

namespace carmba {
namespace ba {

SyntheticFlex MakeSyntheticFlex(const SyntheticFlexSpec& spec, uint64_t seed) {
  // The geometry (plate poses, object poses, CT noise) of the rigid synthetic joint problem.
  SyntheticJointSpec js;
  js.intrinsics = spec.intrinsics;
  js.free = spec.free;
  js.num_plate_views =
      static_cast<int>(spec.plate_orientations_deg.size()) * spec.plate_views_per_orientation;
  js.object_angles_deg.clear();
  for (const auto& o : spec.object_orientations_deg) js.object_angles_deg.push_back(o.first);
  js.sigma_plate_px = spec.sigma_plate_px;
  js.sigma_object_px = spec.sigma_object_px;
  js.sigma_ct_mm = spec.sigma_ct_mm;
  js.geometry_seed = spec.geometry_seed;
  NoiseSwitches ct_only = NoiseSwitches::Only(Source::kCt);
  const SyntheticJoint j = MakeSyntheticJoint(js, ct_only, seed);

  SyntheticFlex out;
  out.problem = j.problem;
  out.problem.name = "synthetic_flex";
  out.true_poses = j.true_poses;
  Rng rng(seed * 2654435761ULL + 17);
  std::normal_distribution<double> gauss(0.0, 1.0);
  int plate_k = 0, object_k = 0;
  for (size_t v = 0; v < out.problem.views.size(); ++v) {
    BaView& view = out.problem.views[v];
    std::pair<double, double> ang;
    bool between = false;
    if (view.kind == ViewKind::kPlate) {
      ang = spec.plate_orientations_deg[plate_k++ / spec.plate_views_per_orientation];
      char id[48];
      std::snprintf(id, sizeof id, "p%+04.0f%+04.0f_%d", ang.first, ang.second,
                    (plate_k - 1) % spec.plate_views_per_orientation);
      view.id = id;
    } else {
      ang = spec.object_orientations_deg[object_k++];
      between = true;
      for (const auto& o : spec.plate_orientations_deg) {
        if (std::abs(o.first - ang.first) < 1e-9 && std::abs(o.second - ang.second) < 1e-9)
          between = false;
      }
      char id[48];
      std::snprintf(id, sizeof id, "o%+05.1f%+05.1f", ang.first, ang.second);
      view.id = id;
    }
    view.has_angles = true;
    view.primary_deg = ang.first;
    view.secondary_deg = ang.second;
    const auto K = spec.flex.Apply(spec.intrinsics, ang.first, ang.second);
    const double sigma = view.kind == ViewKind::kPlate ? spec.sigma_plate_px : spec.sigma_object_px;
    for (size_t i = 0; i < view.point_ids.size(); ++i) {
      const Eigen::Vector3d p = view.kind == ViewKind::kPlate
                                    ? out.problem.plate.points[view.point_ids[i]]
                                    : j.true_markers[view.point_ids[i] - 1];
      Eigen::Vector2d q;
      ProjectPoint(K.data(), out.true_poses[v].data(), p.data(), q.data());
      view.uv_px[i] = q + sigma * RandomVector<2>(gauss, rng);
    }
    out.true_intrinsics.push_back(K);
    out.between.push_back(between);
  }
  return out;
}

}  // namespace ba
}  // namespace carmba
