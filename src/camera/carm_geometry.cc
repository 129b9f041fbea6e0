#include "camera/carm_geometry.h"

#include <cmath>
#include <cstdio>

#include "geometry/rotation.h"
#include "util/plausible.h"

namespace carmba {

std::string OrientationName(double primary_deg, double secondary_deg) {
  char s[48];
  std::snprintf(s, sizeof s, "p%+04.0f s%+04.0f", primary_deg, secondary_deg);
  return s;
}

nlohmann::json RigidToJson(const Rigid3& pose) {
  nlohmann::json R = nlohmann::json::array();
  for (int i = 0; i < 3; ++i) R.push_back({pose.R(i, 0), pose.R(i, 1), pose.R(i, 2)});
  const Eigen::Vector3d r = pose.Rvec();
  return {
      {"R", R}, {"rvec", {r.x(), r.y(), r.z()}}, {"t_mm", {pose.t.x(), pose.t.y(), pose.t.z()}}};
}

bool CarmGeometry::Check(std::string* error) const {
  const double v[] = {sid_mm,
                      sod_mm,
                      primary_angle_deg,
                      secondary_angle_deg,
                      detector_rotation_deg,
                      isocenter_mm.x(),
                      isocenter_mm.y(),
                      isocenter_mm.z(),
                      axis_offset_mm.x(),
                      axis_offset_mm.y()};
  for (double x : v) {
    if (!std::isfinite(x)) return *error = "C-arm geometry: non-finite value", false;
  }
  namespace pl = plausible;
  if (!CheckRange("sid_mm", sid_mm, pl::kDistanceMm, error) ||
      !CheckRange("sod_mm", sod_mm, pl::kDistanceMm, error) ||
      !CheckRange("primary_deg", primary_angle_deg, pl::kAngleDeg, error) ||
      !CheckRange("detector_rotation_deg", detector_rotation_deg, pl::kAngleDeg, error)) {
    return false;
  }
  for (int i = 0; i < 3; ++i) {
    if (!CheckRange(
            std::string("isocenter_mm ") + "xyz"[i], isocenter_mm[i], pl::kCoordinateMm, error) ||
        (i < 2 && !CheckRange(std::string("axis_offset_mm ") + "xy"[i],
                              axis_offset_mm[i],
                              pl::kCoordinateMm,
                              error))) {
      return false;
    }
  }
  if (!(sod_mm > 0 && sod_mm < sid_mm)) {
    return *error = "sod_mm must be positive and smaller than sid_mm", false;
  }
  if (std::fabs(secondary_angle_deg) > 90.0) {
    return *error = "secondary angle must lie in [-90, 90] degrees", false;
  }
  return true;
}

Rigid3 CamFromWorld(const CarmGeometry& g) {
  const double a = g.primary_angle_deg * kDegToRad;
  const double b = g.secondary_angle_deg * kDegToRad;
  const double gamma = g.detector_rotation_deg * kDegToRad;
  Eigen::Matrix3d R0;
  R0.col(0) << -1, 0, 0;  // camera x = patient right
  R0.col(1) << 0, 0, -1;  // camera y = feet
  R0.col(2) << 0, -1, 0;  // beam = anterior
  const Eigen::Matrix3d world_from_cam_R =
      Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ()).toRotationMatrix() * R0 *
      Eigen::AngleAxisd(b, Eigen::Vector3d::UnitX()).toRotationMatrix() *
      Eigen::AngleAxisd(gamma, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Vector3d source_in_world =
      g.isocenter_mm +
      world_from_cam_R * Eigen::Vector3d(g.axis_offset_mm.x(), g.axis_offset_mm.y(), -g.sod_mm);
  Rigid3 cam_from_world;
  cam_from_world.R = world_from_cam_R.transpose();
  cam_from_world.t = -(cam_from_world.R * source_in_world);
  return cam_from_world;
}

bool DetectorSpec::Check(std::string* error) const {
  namespace pl = plausible;
  return CheckRange("detector width", width_px, pl::kImageSizePx, error) &&
         CheckRange("detector height", height_px, pl::kImageSizePx, error) &&
         CheckRange("pixel_pitch_mm x", pitch_x_mm, pl::kPixelPitchMm, error) &&
         CheckRange("pixel_pitch_mm y", pitch_y_mm, pl::kPixelPitchMm, error) &&
         CheckRange("principal offset x", principal_offset_px.x(), pl::kPixelCoordinatePx, error) &&
         CheckRange("principal offset y", principal_offset_px.y(), pl::kPixelCoordinatePx, error);
  return true;
}

Camera CameraFromDetector(const DetectorSpec& d, double sid_mm) {
  Camera c;
  c.width = d.width_px;
  c.height = d.height_px;
  c.params.fill(0.0);
  c.params[kFx] = sid_mm / d.pitch_x_mm;
  c.params[kFy] = sid_mm / d.pitch_y_mm;
  c.params[kCx] = 0.5 * (d.width_px - 1) + d.principal_offset_px.x();
  c.params[kCy] = 0.5 * (d.height_px - 1) + d.principal_offset_px.y();
  return c;
}

}  // namespace carmba
