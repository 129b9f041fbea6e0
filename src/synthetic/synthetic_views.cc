#include "synthetic/synthetic_views.h"

#include <Eigen/Geometry>
#include <cmath>
#include <random>

#include "geometry/random_vector.h"
#include "util/random.h"

namespace carmba {

ObservationSet MakeSyntheticViews(const std::array<double, kNumIntrinsics>& intr,
                                  int width,
                                  int height,
                                  const GridSpec& grid,
                                  const SyntheticViewsOptions& o,
                                  std::vector<Pose6>* cam_from_plate) {
  Rng rng(o.seed);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  ObservationSet obs;
  obs.grid = grid;
  obs.width = width;
  obs.height = height;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : grid.PointsInPlate()) centre += p;
  centre /= grid.NumPoints();
  if (cam_from_plate) cam_from_plate->clear();
  int attempts = 0;
  while (static_cast<int>(obs.views.size()) < o.num_views && attempts < 1000 * o.num_views) {
    ++attempts;
    const double az = 2 * M_PI * U(rng);
    const double tilt = (o.min_tilt_deg + (o.max_tilt_deg - o.min_tilt_deg) * U(rng)) * M_PI / 180;
    const double spin = 2 * M_PI * U(rng);
    const Eigen::Matrix3d R =
        (Eigen::AngleAxisd(tilt, Eigen::Vector3d(std::cos(az), std::sin(az), 0)) *
         Eigen::AngleAxisd(spin, Eigen::Vector3d::UnitZ()))
            .toRotationMatrix();
    const double z = o.distance_min_mm + (o.distance_max_mm - o.distance_min_mm) * U(rng);
    const double half_fov_x = 0.5 * width / intr[kFx] * z,
                 half_fov_y = 0.5 * height / intr[kFy] * z;
    const double offset_y = 2 * U(rng) - 1;  // y before x (geometry/random_vector.h)
    const double offset_x = 2 * U(rng) - 1;
    const Eigen::Vector3d c_cam(offset_x * o.max_offset_fraction * half_fov_x,
                                offset_y * o.max_offset_fraction * half_fov_y, z);
    const Eigen::Vector3d t = c_cam - R * centre;
    const Pose6 pose = Rigid3{R, t}.ToPose();
    ViewObservations v;
    v.image = "synthetic_" + std::to_string(obs.views.size());
    bool inside = true;
    for (int id = 0; id < grid.NumPoints() && inside; ++id) {
      const Eigen::Vector3d P = grid.PointInPlate(id);
      double uv[2] = {0, 0};
      if (!ProjectPoint(intr.data(), pose.data(), P.data(), uv) || uv[0] < 2 ||
          uv[0] > width - 3 || uv[1] < 2 || uv[1] > height - 3) {
        inside = false;
      }
      v.point_ids.push_back(id);
      v.uv_px.emplace_back(uv[0], uv[1]);
    }
    if (!inside) continue;
    obs.views.push_back(v);
    if (cam_from_plate) cam_from_plate->push_back(pose);
  }
  return AddNoise(obs, o.noise_sigma_px, o.seed * 7919 + 13);
}

ObservationSet AddNoise(const ObservationSet& clean, double sigma_px, uint64_t seed) {
  ObservationSet noisy = clean;
  if (sigma_px <= 0) return noisy;
  Rng rng(seed);
  std::normal_distribution<double> N(0.0, sigma_px);
  for (auto& v : noisy.views) {
    for (auto& q : v.uv_px) q += RandomVector<2>(N, rng);
  }
  return noisy;
}

}  // namespace carmba
