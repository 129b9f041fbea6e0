// Synthetic pose problems with ground truth (synthetic/synthetic_pose.h).
#include <random>

#include "geometry/random_vector.h"
#include "geometry/rotation.h"
#include "synthetic/synthetic_pose.h"
#include "util/random.h"

namespace carmba {

std::vector<Eigen::Vector3d> ThesisMarkers() {
  // Thesis Table 5.1, object frame (origin marker 1), mm.
  return {{0.00, 0.00, 0.00},     {-58.85, 1.00, 14.00},  {13.35, 1.00, 14.00},
          {-8.25, -20.50, 24.00}, {-56.05, 19.00, 31.00}, {-27.07, -20.00, 31.00},
          {-15.01, -21.50, 40.00}, {-42.20, 18.75, 44.00}, {-1.40, 5.00, 49.00}};
}

Problem MakeSyntheticPoseProblem(const SyntheticPoseSpec& spec,
                                 double sigma_px,
                                 double sigma_ct_mm,
                                 uint64_t seed) {
  Rng rng(seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  Problem p;
  p.name = "synthetic";
  p.path = "<synthetic seed " + std::to_string(seed) + ">";
  p.camera = spec.camera;
  p.object_sigma_px = sigma_px;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& m : spec.markers) centroid += m;
  centroid /= static_cast<double>(spec.markers.size());
  for (size_t i = 0; i < spec.markers.size(); ++i) {
    Marker m;
    m.id = static_cast<int>(i) + 1;
    p.truth.markers[m.id] = spec.markers[i];
    m.p_in_object = spec.markers[i] + sigma_ct_mm * RandomVector<3>(gauss, rng);
    m.covariance = Eigen::Matrix3d::Identity() * sigma_ct_mm * sigma_ct_mm;
    p.fiducials.push_back(m);
  }
  // Views: the C-arm rotates about `rotation_axis` (through the object centre) by the angle.
  const Eigen::Matrix3d R0 = RotationOf(spec.base_rvec);
  const Eigen::Vector3d axis = spec.rotation_axis.normalized();
  for (size_t v = 0; v < spec.view_angles_deg.size(); ++v) {
    const Eigen::Matrix3d Rv =
        RotationOf(axis * spec.view_angles_deg[v] * kDegToRad).transpose() * R0;
    const Eigen::Vector3d t = Eigen::Vector3d(0, 0, spec.source_to_object_mm) - Rv * centroid;
    Pose6 pose;
    pose.head<3>() = RvecFromRotation(Rv);
    pose.tail<3>() = t;
    PoseView view;
    char id[32];
    std::snprintf(id, sizeof(id), "%g", spec.view_angles_deg[v]);
    view.id = id;
    for (size_t i = 0; i < spec.markers.size(); ++i) {
      Observation o;
      o.marker_id = static_cast<int>(i) + 1;
      ProjectPoint(spec.camera.params.data(), pose.data(), spec.markers[i].data(), o.uv_px.data());
      o.uv_px += sigma_px * RandomVector<2>(gauss, rng);
      view.observations.push_back(o);
    }
    p.truth.object_poses[view.id] = pose;
    p.object_views.push_back(view);
  }
  for (const auto& [a, b] : spec.pairs) {
    ValidationPair vp;
    vp.a = p.object_views[a].id;
    vp.b = p.object_views[b].id;
    vp.expected_deg = std::fabs(spec.view_angles_deg[b] - spec.view_angles_deg[a]);
    p.validation.push_back(vp);
  }
  return p;
}

}  // namespace carmba
