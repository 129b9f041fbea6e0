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

namespace {

// The scene's random draws: `geo` (uniform) for the geometry, `rng` (Gaussian) for the noise, each
// in a fixed order so that a seed gives the same scene.
struct Draws {
  Draws(uint64_t geometry_seed, uint64_t noise_seed) : geo(geometry_seed), rng(noise_seed) {}
  Rng geo;
  std::uniform_real_distribution<double> uni{-1.0, 1.0};
  Rng rng;
  std::normal_distribution<double> gauss{0.0, 1.0};
  Eigen::Vector3d Gauss3() { return RandomVector<3>(gauss, rng); }
};

// The one intrinsics group, with its prior on fx, fy, cx, cy drawn about the truth.
IntrinsicsGroup TrueGroup(const SyntheticJointSpec& spec, const NoiseSwitches& noise, Draws* d) {
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
      const double e = d->gauss(d->rng) * spec.prior_sigma[i];
      if (noise.prior) g.prior.mean[g.prior.indices[i]] += e;
    }
  }
  return g;
}

// The plate: nominal grid (into `p`) from its first point; returns the true plate, which differs by
// manufacturing noise.
std::vector<Eigen::Vector3d> AddPlate(const SyntheticJointSpec& spec,
                                      const NoiseSwitches& noise,
                                      Draws* d,
                                      BaProblem* p) {
  std::vector<Eigen::Vector3d> true_plate;
  for (int r = 0; r < spec.plate_rows; ++r) {
    for (int c = 0; c < spec.plate_cols; ++c) {
      const Eigen::Vector3d nominal(c * spec.plate_spacing_mm, r * spec.plate_spacing_mm, 0);
      p->plate.points.push_back(nominal);
      Eigen::Vector3d t = nominal;
      if (spec.plate_free && noise.plate_mfg) t += spec.sigma_plate_mm * d->Gauss3();
      true_plate.push_back(t);
    }
  }
  p->plate.free = spec.plate_free;
  p->plate.sigma_mm = spec.plate_free ? spec.sigma_plate_mm : 0.0;
  return true_plate;
}

// A random plate pose: tilt (axis in the plate plane), distance, and an offset keeping the plate
// inside the image.
Pose6 RandomPlatePose(const SyntheticJointSpec& spec, Draws* d) {
  const double* K = spec.intrinsics.data();
  const double w = (spec.plate_cols - 1) * spec.plate_spacing_mm;
  const double h = (spec.plate_rows - 1) * spec.plate_spacing_mm;
  const double half_fov_x = 0.5 * spec.width / K[kFx], half_fov_y = 0.5 * spec.height / K[kFy];
  const double tilt = spec.plate_max_tilt_deg * kDegToRad * (0.3 + 0.7 * std::abs(d->uni(d->geo)));
  const double phi = kPi * d->uni(d->geo);
  const Eigen::Vector3d axis(std::cos(phi), std::sin(phi), 0);
  const Eigen::Matrix3d R = RotationOf(axis * tilt + Eigen::Vector3d(0, 0, 0.3 * d->uni(d->geo)));
  const double dist = spec.plate_distance_mm * (1.0 + 0.1 * d->uni(d->geo));
  const Eigen::Vector3d centre_in_plate(w / 2, h / 2, 0);
  const double mx = std::max(0.0, half_fov_x * dist - 0.75 * w),
               my = std::max(0.0, half_fov_y * dist - 0.75 * h);
  const Eigen::Vector2d offset = RandomVector<2>(d->uni, d->geo);
  const Eigen::Vector3d centre_in_cam(0.5 * mx * offset[0], 0.5 * my * offset[1], dist);
  Pose6 pose;
  pose.head<3>() = RvecFromRotation(R);
  pose.tail<3>() = centre_in_cam - R * centre_in_plate;
  return pose;
}

// The plate views: the true plate's projections at random poses, with pixel noise.
void AddPlateViews(const SyntheticJointSpec& spec,
                   const NoiseSwitches& noise,
                   const std::vector<Eigen::Vector3d>& true_plate,
                   Draws* d,
                   SyntheticJoint* out) {
  for (int v = 0; v < spec.num_plate_views; ++v) {
    const Pose6 pose = RandomPlatePose(spec, d);
    BaView view;
    char id[32];
    std::snprintf(id, sizeof id, "p%02d", v);
    view.id = id;
    view.kind = ViewKind::kPlate;
    view.sigma_px = spec.sigma_plate_px;
    view.initial = pose;
    for (size_t j = 0; j < true_plate.size(); ++j) {
      Eigen::Vector2d q;
      ProjectPoint(spec.intrinsics.data(), pose.data(), true_plate[j].data(), q.data());
      if (noise.plate_px) q += spec.sigma_plate_px * RandomVector<2>(d->gauss, d->rng);
      view.point_ids.push_back(static_cast<int>(j));
      view.uv_px.push_back(q);
    }
    out->true_poses.push_back(pose);
    out->problem.views.push_back(view);
  }
}

// The thesis object's markers with their CT covariance (slices thicker in z), measured with noise.
void AddMarkers(const SyntheticJointSpec& spec,
                const NoiseSwitches& noise,
                Draws* d,
                SyntheticJoint* out) {
  const auto markers = ThesisObjectMarkers();
  const Eigen::Matrix3d C_ct =
      Eigen::Vector3d(1.0, 1.0, 2.25).asDiagonal() * (spec.sigma_ct_mm * spec.sigma_ct_mm);
  for (size_t m = 0; m < markers.size(); ++m) {
    BaMarker bm;
    bm.id = static_cast<int>(m) + 1;
    bm.covariance = C_ct;
    bm.p_ct = markers[m];
    if (noise.ct) bm.p_ct += C_ct.llt().matrixL() * d->Gauss3();
    out->problem.markers.push_back(bm);
    out->true_markers.push_back(markers[m]);
  }
}

// One marker's projection with its pixel noise: isotropic, or with a random anisotropic
// covariance (stored in the view) when the spec asks for one.
Eigen::Vector2d ObservedMarker(const SyntheticJointSpec& spec,
                               const NoiseSwitches& noise,
                               const Pose6& pose,
                               const Eigen::Vector3d& marker,
                               Draws* d,
                               BaView* view) {
  Eigen::Vector2d q;
  ProjectPoint(spec.intrinsics.data(), pose.data(), marker.data(), q.data());
  if (spec.object_px_anisotropy > 1.0) {
    const double phi = kPi * d->uni(d->geo);
    Eigen::Matrix2d R;
    R << std::cos(phi), -std::sin(phi), std::sin(phi), std::cos(phi);
    const Eigen::Matrix2d C =
        spec.sigma_object_px * spec.sigma_object_px * R *
        Eigen::Vector2d(spec.object_px_anisotropy, 1.0 / spec.object_px_anisotropy).asDiagonal() *
        R.transpose();
    view->obs_covariance_px2.push_back(0.5 * (C + C.transpose()));
    if (noise.object_px) q += C.llt().matrixL() * RandomVector<2>(d->gauss, d->rng);
  } else if (noise.object_px) {
    q += spec.sigma_object_px * RandomVector<2>(d->gauss, d->rng);
  }
  return q;
}

// The object views: the C-arm rotates about the object's y axis through its markers' centroid;
// the validation pairs are the first view with each other.
void AddObjectViews(const SyntheticJointSpec& spec,
                    const NoiseSwitches& noise,
                    Draws* d,
                    SyntheticJoint* out) {
  const auto& markers = out->true_markers;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& m : markers) centroid += m;
  centroid /= static_cast<double>(markers.size());
  const Eigen::Matrix3d R0 = RotationOf(Eigen::Vector3d(0.3, -0.4, 0.2));
  std::vector<int> object_view_index;
  for (double a : spec.object_angles_deg) {
    const Eigen::Matrix3d Rv =
        RotationOf(Eigen::Vector3d(0, 1, 0) * a * kDegToRad).transpose() * R0;
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
      view.uv_px.push_back(ObservedMarker(spec, noise, pose, markers[m], d, &view));
      view.point_ids.push_back(static_cast<int>(m) + 1);
    }
    object_view_index.push_back(static_cast<int>(out->problem.views.size()));
    out->true_poses.push_back(pose);
    out->problem.views.push_back(view);
  }
  for (size_t i = 1; i < object_view_index.size(); ++i) {
    out->pairs.emplace_back(object_view_index[0], object_view_index[i]);
  }
}

// Intrinsics held at a calibration with its covariance considered: the held values drawn from it.
void ConsiderCalibration(const SyntheticJointSpec& spec,
                         const NoiseSwitches& noise,
                         Draws* d,
                         IntrinsicsGroup* grp) {
  if (spec.consider_indices.empty()) return;
  grp->consider_indices = spec.consider_indices;
  grp->consider_covariance = spec.consider_covariance;
  if (!noise.calibration) return;
  const auto n = static_cast<Eigen::Index>(spec.consider_indices.size());
  Eigen::VectorXd z(n);
  for (Eigen::Index i = 0; i < n; ++i) z[i] = d->gauss(d->rng);
  const Eigen::VectorXd e = spec.consider_covariance.llt().matrixL() * z;
  for (Eigen::Index i = 0; i < n; ++i) grp->initial[spec.consider_indices[i]] += e[i];
}

}  // namespace

SyntheticJoint MakeSyntheticJoint(const SyntheticJointSpec& spec,
                                  const NoiseSwitches& noise,
                                  uint64_t seed) {
  Draws d(spec.geometry_seed, seed);
  SyntheticJoint out;
  out.problem.name = "synthetic_joint";
  out.true_intrinsics = spec.intrinsics;
  out.problem.groups.push_back(TrueGroup(spec, noise, &d));
  const std::vector<Eigen::Vector3d> true_plate = AddPlate(spec, noise, &d, &out.problem);
  AddPlateViews(spec, noise, true_plate, &d, &out);
  AddMarkers(spec, noise, &d, &out);
  AddObjectViews(spec, noise, &d, &out);
  ConsiderCalibration(spec, noise, &d, &out.problem.groups[0]);
  return out;
}

}  // namespace ba
}  // namespace carmba
