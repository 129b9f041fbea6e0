#include "analysis/calibrated_range.h"

#include <algorithm>
#include <cstdio>
#include <limits>

#include "geometry/rotation.h"

namespace carmba {
namespace analysis {
namespace {

struct Range {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
  void Add(double x) { lo = std::min(lo, x), hi = std::max(hi, x); }
  bool Empty() const { return lo > hi; }
};

// Depth (mm) of point p (the view's object or plate frame) in view v's camera.
double Depth(const ba::BaResult& r, int v, const Eigen::Vector3d& p) {
  const Pose6 pose = r.ViewPose(v);
  const Eigen::Matrix3d R = RotationOf(pose.head<3>());
  return (R * p)[2] + pose[5];
}

Eigen::Vector3d Centroid(const std::vector<Eigen::Vector3d>& pts) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& p : pts) c += p;
  return pts.empty() ? c : Eigen::Vector3d(c / static_cast<double>(pts.size()));
}

void DepthWarnings(const ba::BaProblem& p, const ba::BaResult& r, std::vector<std::string>* out) {
  if (p.plate.points.empty() || p.markers.empty()) return;
  const Eigen::Vector3d plate_c = Centroid(p.plate.points);
  std::vector<Eigen::Vector3d> m;
  for (const auto& mk : p.markers) m.push_back(mk.p_ct);
  const Eigen::Vector3d object_c = Centroid(m);
  Range plate;
  for (size_t v = 0; v < p.views.size(); ++v) {
    if (p.views[v].kind == ba::ViewKind::kPlate) plate.Add(Depth(r, static_cast<int>(v), plate_c));
  }
  if (plate.Empty()) return;
  for (size_t v = 0; v < p.views.size(); ++v) {
    if (p.views[v].kind != ba::ViewKind::kObject) continue;
    const double d = Depth(r, static_cast<int>(v), object_c);
    if (d >= kDepthRangeLow * plate.lo && d <= kDepthRangeHigh * plate.hi) continue;
    char buf[400];
    std::snprintf(buf, sizeof buf,
                  "object view '%s': the markers are %.0f mm from the source, %s than the plate "
                  "views that calibrated it (%.0f-%.0f mm): outside the calibrated depth range",
                  p.views[v].id.c_str(), d, d < plate.lo ? "much nearer" : "much farther",
                  plate.lo, plate.hi);
    out->push_back(buf);
  }
}

void AngleWarnings(const ba::BaProblem& p, std::vector<std::string>* out) {
  for (size_t g = 0; g < p.groups.size(); ++g) {
    if (!p.groups[g].smooth) continue;
    Range primary, secondary;
    for (const auto& v : p.views) {
      if (v.group != static_cast<int>(g) || v.kind != ba::ViewKind::kPlate || !v.has_angles)
        continue;
      primary.Add(v.primary_deg);
      secondary.Add(v.secondary_deg);
    }
    if (primary.Empty()) continue;
    for (const auto& v : p.views) {
      if (v.group != static_cast<int>(g) || v.kind != ba::ViewKind::kObject || !v.has_angles)
        continue;
      const bool in = v.primary_deg >= primary.lo - kAngleToleranceDeg &&
                      v.primary_deg <= primary.hi + kAngleToleranceDeg &&
                      v.secondary_deg >= secondary.lo - kAngleToleranceDeg &&
                      v.secondary_deg <= secondary.hi + kAngleToleranceDeg;
      if (in) continue;
      char buf[400];
      std::snprintf(buf, sizeof buf,
                    "object view '%s' (primary %g deg, secondary %g deg) is outside the calibrated "
                    "angles of the smooth intrinsics model (plate views at primary %g..%g deg, "
                    "secondary %g..%g deg): its intrinsics are extrapolated",
                    v.id.c_str(), v.primary_deg, v.secondary_deg, primary.lo, primary.hi,
                    secondary.lo, secondary.hi);
      out->push_back(buf);
    }
  }
}

}  // namespace

std::vector<std::string> CalibratedRangeWarnings(const ba::BaProblem& problem,
                                                 const ba::BaResult& result) {
  std::vector<std::string> out;
  DepthWarnings(problem, result, &out);
  AngleWarnings(problem, &out);
  return out;
}

}  // namespace analysis
}  // namespace carmba
