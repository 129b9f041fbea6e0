#include "synthetic/synthetic_joint.h"

#include <cstdio>
#include <random>

#include "geometry/random_vector.h"
#include "geometry/rotation.h"
#include "util/random.h"

namespace carmba {
namespace ba {

NoiseSwitches NoiseSwitches::Only(Source s) {
  NoiseSwitches n{false, false, false, false, false, false};
  switch (s) {
    case Source::kCalibration: n.calibration = true; break;
    case Source::kPlatePixels: n.plate_px = true; break;
    case Source::kObjectPixels: n.object_px = true; break;
    case Source::kCt: n.ct = true; break;
    case Source::kPlateManufacturing: n.plate_mfg = true; break;
    case Source::kIntrinsicsPrior: n.prior = true; break;
  }
  return n;
}

std::vector<Eigen::Vector3d> ThesisObjectMarkers() {
  return {{0.00, 0.00, 0.00},     {-58.85, 1.00, 14.00},  {13.35, 1.00, 14.00},
          {-8.25, -20.50, 24.00}, {-56.05, 19.00, 31.00}, {-27.07, -20.00, 31.00},
          {-15.01, -21.50, 40.00}, {-42.20, 18.75, 44.00}, {-1.40, 5.00, 49.00}};
}

SyntheticJoint MakeSyntheticJoint(const SyntheticJointSpec& spec,
                                  const NoiseSwitches& noise,
                                  uint64_t seed) {
  Rng geo(spec.geometry_seed);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  Rng rng(seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  auto g3 = [&] { return RandomVector<3>(gauss, rng); };

  SyntheticJoint out;
  BaProblem& p = out.problem;
  p.name = "synthetic_joint";
  out.true_intrinsics = spec.intrinsics;
  IntrinsicsGroup g;
  g.initial = spec.intrinsics;
  g.free = spec.free;
  g.width = spec.width;
  g.height = spec.height;
  if (spec.intrinsics_prior) {
    g.has_prior = true;
    g.prior.mean = spec.intrinsics;
    g.prior.indices = {kFx, kFy, kCx, kCy};
    g.prior.covariance = Eigen::MatrixXd::Zero(4, 4);
    for (int i = 0; i < 4; ++i) {
      g.prior.covariance(i, i) = spec.prior_sigma[i] * spec.prior_sigma[i];
      const double e = gauss(rng) * spec.prior_sigma[i];
      if (noise.prior) g.prior.mean[g.prior.indices[i]] += e;
    }
  }
  p.groups.push_back(g);

  // The plate: nominal grid centred on its middle; the true plate differs by manufacturing noise.
  const double w = (spec.plate_cols - 1) * spec.plate_spacing_mm;
  const double h = (spec.plate_rows - 1) * spec.plate_spacing_mm;
  std::vector<Eigen::Vector3d> true_plate;
  for (int r = 0; r < spec.plate_rows; ++r) {
    for (int c = 0; c < spec.plate_cols; ++c) {
      const Eigen::Vector3d nominal(c * spec.plate_spacing_mm, r * spec.plate_spacing_mm, 0);
      p.plate.points.push_back(nominal);
      Eigen::Vector3d t = nominal;
      if (spec.plate_free && noise.plate_mfg) t += spec.sigma_plate_mm * g3();
      true_plate.push_back(t);
    }
  }
  p.plate.free = spec.plate_free;
  p.plate.sigma_mm = spec.plate_free ? spec.sigma_plate_mm : 0.0;
  const double* K = spec.intrinsics.data();
  // Plate views: random tilt (axis in the plate plane), distance, and offset keeping the plate
  // inside the image.
  const double half_fov_x = 0.5 * spec.width / K[kFx], half_fov_y = 0.5 * spec.height / K[kFy];
  for (int v = 0; v < spec.num_plate_views; ++v) {
    const double tilt = spec.plate_max_tilt_deg * kDegToRad * (0.3 + 0.7 * std::abs(uni(geo)));
    const double phi = kPi * uni(geo);
    const Eigen::Vector3d axis(std::cos(phi), std::sin(phi), 0);
    const Eigen::Matrix3d R = RotationFromRvec(axis * tilt + Eigen::Vector3d(0, 0, 0.3 * uni(geo)));
    const double d = spec.plate_distance_mm * (1.0 + 0.1 * uni(geo));
    const Eigen::Vector3d centre_in_plate(w / 2, h / 2, 0);
    const double mx = std::max(0.0, half_fov_x * d - 0.75 * w),
                 my = std::max(0.0, half_fov_y * d - 0.75 * h);
    const Eigen::Vector2d offset = RandomVector<2>(uni, geo);
    const Eigen::Vector3d centre_in_cam(0.5 * mx * offset[0], 0.5 * my * offset[1], d);
    Pose6 pose;
    pose.head<3>() = RvecFromRotation(R);
    pose.tail<3>() = centre_in_cam - R * centre_in_plate;
    BaView view;
    char id[32];
    std::snprintf(id, sizeof id, "p%02d", v);
    view.id = id;
    view.kind = ViewKind::kPlate;
    view.sigma_px = spec.sigma_plate_px;
    view.initial = pose;
    for (size_t j = 0; j < true_plate.size(); ++j) {
      Eigen::Vector2d q;
      ProjectPoint(K, pose.data(), true_plate[j].data(), q.data());
      if (noise.plate_px) q += spec.sigma_plate_px * RandomVector<2>(gauss, rng);
      view.point_ids.push_back(static_cast<int>(j));
      view.uv_px.push_back(q);
    }
    out.true_poses.push_back(pose);
    p.views.push_back(view);
  }
  // The object and its views: the C-arm rotates about the object's y axis through its centroid.
  const auto markers = ThesisObjectMarkers();
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& m : markers) centroid += m;
  centroid /= static_cast<double>(markers.size());
  const Eigen::Matrix3d C_ct = Eigen::Vector3d(1.0, 1.0, 2.25).asDiagonal() *
                               (spec.sigma_ct_mm * spec.sigma_ct_mm);  // slices thicker in z
  for (size_t m = 0; m < markers.size(); ++m) {
    BaMarker bm;
    bm.id = static_cast<int>(m) + 1;
    bm.covariance = C_ct;
    bm.p_ct = markers[m];
    if (noise.ct) bm.p_ct += C_ct.llt().matrixL() * g3();
    p.markers.push_back(bm);
    out.true_markers.push_back(markers[m]);
  }
  const Eigen::Matrix3d R0 = RotationFromRvec(Eigen::Vector3d(0.3, -0.4, 0.2));
  std::vector<int> object_view_index;
  for (double a : spec.object_angles_deg) {
    const Eigen::Matrix3d Rv =
        RotationFromRvec(Eigen::Vector3d(0, 1, 0) * a * kDegToRad).transpose() * R0;
    Pose6 pose;
    pose.head<3>() = RvecFromRotation(Rv);
    pose.tail<3>() = Eigen::Vector3d(0, 0, spec.object_distance_mm) - Rv * centroid;
    BaView view;
    char id[32];
    std::snprintf(id, sizeof id, "%+04.0f", a);
    view.id = id;
    view.kind = ViewKind::kObject;
    view.sigma_px = spec.sigma_object_px;
    view.initial = pose;
    for (size_t m = 0; m < markers.size(); ++m) {
      Eigen::Vector2d q;
      ProjectPoint(K, pose.data(), markers[m].data(), q.data());
      if (spec.object_px_anisotropy > 1.0) {
        const double phi = kPi * uni(geo);
        Eigen::Matrix2d R;
        R << std::cos(phi), -std::sin(phi), std::sin(phi), std::cos(phi);
        const Eigen::Matrix2d C =
            spec.sigma_object_px * spec.sigma_object_px * R *
            Eigen::Vector2d(spec.object_px_anisotropy, 1.0 / spec.object_px_anisotropy)
                .asDiagonal() *
            R.transpose();
        view.obs_covariance_px2.push_back(0.5 * (C + C.transpose()));
        if (noise.object_px) q += C.llt().matrixL() * RandomVector<2>(gauss, rng);
      } else if (noise.object_px) {
        q += spec.sigma_object_px * RandomVector<2>(gauss, rng);
      }
      view.point_ids.push_back(static_cast<int>(m) + 1);
      view.uv_px.push_back(q);
    }
    object_view_index.push_back(static_cast<int>(p.views.size()));
    out.true_poses.push_back(pose);
    p.views.push_back(view);
  }
  for (size_t i = 1; i < object_view_index.size(); ++i) {
    out.pairs.emplace_back(object_view_index[0], object_view_index[i]);
  }
  if (!spec.consider_indices.empty()) {
    IntrinsicsGroup& grp = p.groups[0];
    grp.consider_indices = spec.consider_indices;
    grp.consider_covariance = spec.consider_covariance;
    if (noise.calibration) {
      const auto n = static_cast<Eigen::Index>(spec.consider_indices.size());
      Eigen::VectorXd z(n);
      for (Eigen::Index i = 0; i < n; ++i) z[i] = gauss(rng);
      const Eigen::VectorXd e = spec.consider_covariance.llt().matrixL() * z;
      for (Eigen::Index i = 0; i < n; ++i) grp.initial[spec.consider_indices[i]] += e[i];
    }
  }
  return out;
}

}  // namespace ba
}  // namespace carmba
