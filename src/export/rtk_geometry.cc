// RTK ThreeDCircularGeometry export and reading (rtk_geometry.h).
#include "export/rtk_geometry.h"

#include <cmath>
#include <cstdio>
#include <map>
#include <regex>
#include <sstream>

#include "geometry/rotation.h"
#include "util/file_util.h"
#include "util/format.h"
#include "util/plausible.h"

namespace carmba {
namespace {

Eigen::Matrix3d Rx(double a) {
  Eigen::Matrix3d m;
  m << 1, 0, 0, 0, std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a);
  return m;
}
Eigen::Matrix3d Ry(double a) {
  Eigen::Matrix3d m;
  m << std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a);
  return m;
}
Eigen::Matrix3d Rz(double a) {
  Eigen::Matrix3d m;
  m << std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a), 0, 0, 0, 1;
  return m;
}

double Wrap360(double deg) {
  double d = std::fmod(deg, 360.0);
  if (d < 0) d += 360.0;
  if (d >= 360.0) d -= 360.0;
  return d;
}

// px -> detector mm (see the header comment).
Eigen::Matrix3d PixelToDetector(const RtkDetector& d) {
  Eigen::Matrix3d A = Eigen::Matrix3d::Identity();
  A(0, 0) = d.spacing_u_mm;
  A(0, 2) = -0.5 * (d.width - 1) * d.spacing_u_mm;
  A(1, 1) = -d.spacing_v_mm;
  A(1, 2) = 0.5 * (d.height - 1) * d.spacing_v_mm;
  return A;
}

}  // namespace

Matrix34 RtkMatrix(const RtkProjection& p) {
  const Eigen::Matrix3d R = Rz(-p.in_plane_deg * kDegToRad) * Rx(-p.out_of_plane_deg * kDegToRad) *
                            Ry(-p.gantry_deg * kDegToRad);
  Eigen::Matrix4d rot = Eigen::Matrix4d::Identity();
  rot.topLeftCorner<3, 3>() = R;
  Eigen::Matrix4d src = Eigen::Matrix4d::Identity();
  src(0, 3) = -p.source_offset_x_mm;
  src(1, 3) = -p.source_offset_y_mm;
  Matrix34 mag = Matrix34::Zero();
  mag(0, 0) = -p.sdd_mm;
  mag(1, 1) = -p.sdd_mm;
  mag(2, 2) = 1;
  mag(2, 3) = -p.sid_mm;
  Eigen::Matrix3d proj = Eigen::Matrix3d::Identity();
  proj(0, 2) = p.source_offset_x_mm - p.projection_offset_x_mm;
  proj(1, 2) = p.source_offset_y_mm - p.projection_offset_y_mm;
  return proj * mag * src * rot;
}

StatusOr<std::vector<RtkProjection>> RtkFromGeometry(const GeometrySet& set,
                                                     double sdd_mm,
                                                     RtkDetector* detector) {
  if (set.views.empty()) return Status::Error("no views");
  if (!InRange(sdd_mm, plausible::kDistanceMm)) {
    return Status::Error("source-detector distance: expected " +
                         FormatRange(plausible::kDistanceMm) + ", got " + FormatCompact(sdd_mm));
  }
  const Camera& c0 = set.views[0].camera;
  RtkDetector det;
  det.width = c0.width;
  det.height = c0.height;
  det.spacing_u_mm = sdd_mm / c0.params[kFx];
  det.spacing_v_mm = sdd_mm / c0.params[kFy];
  const double aspect0 = c0.params[kFx] / c0.params[kFy];
  std::vector<RtkProjection> out;
  for (const auto& v : set.views) {
    if (v.ct_mirrored) {
      return Status::Error("view '" + v.id + "': the CT frame is mirrored (handedness: mirrored): "
                           "RTK's rotations cannot carry a reflection");
    }
    if (v.camera.width != det.width || v.camera.height != det.height) {
      return Status::Error("view '" + v.id + "': image size " + std::to_string(v.camera.width) +
                           "x" + std::to_string(v.camera.height) + " differs from view '" +
                           set.views[0].id + "' (" + std::to_string(det.width) + "x" +
                           std::to_string(det.height) + "): one RTK projection stack has one size");
    }
    const double fx = v.camera.params[kFx], fy = v.camera.params[kFy];
    if (std::abs(fx / fy / aspect0 - 1) > 1e-9) {
      return Status::Error("view '" + v.id + "': fx/fy " + FormatCompact(fx / fy) +
                           " differs from view '" + set.views[0].id + "' (" +
                           FormatCompact(aspect0) + "): RTK's projection stack has one pixel "
                           "spacing, which carries one fx/fy");
    }
    const Eigen::Matrix3d R = RotationOf(v.cam_from_ct.head<3>());
    const Eigen::Matrix3d Rr = Eigen::Vector3d(1, -1, -1).asDiagonal() * R;
    const Eigen::Vector3d s = Rr * SourceInCt(v);
    RtkProjection p;
    p.id = v.id;
    p.sdd_mm = det.spacing_u_mm * fx;
    p.sid_mm = s[2];
    p.source_offset_x_mm = s[0];
    p.source_offset_y_mm = s[1];
    const double ppx = det.spacing_u_mm * (v.camera.params[kCx] - 0.5 * (det.width - 1));
    const double ppy = det.spacing_v_mm * (0.5 * (det.height - 1) - v.camera.params[kCy]);
    p.projection_offset_x_mm = s[0] - ppx;
    p.projection_offset_y_mm = s[1] - ppy;
    // Rr = Rz(a) Rx(b) Ry(c) with a = -in_plane, b = -out_of_plane, c = -gantry:
    //   row 2 = (-cos b sin c, sin b, cos b cos c); column 1 = (-sin a cos b, cos a cos b, sin b).
    const double b = std::atan2(Rr(2, 1), std::hypot(Rr(2, 0), Rr(2, 2)));
    double a = 0, c = 0;
    if (std::cos(b) > 1e-12) {
      a = std::atan2(-Rr(0, 1), Rr(1, 1));
      c = std::atan2(-Rr(2, 0), Rr(2, 2));
    } else {
      // Gimbal lock (out-of-plane +-90 deg): only a + c (or a - c) is defined; put it all in c.
      a = 0;
      c = std::atan2(Rr(0, 2), Rr(0, 0));
    }
    p.in_plane_deg = Wrap360(-a * kRadToDeg);
    p.out_of_plane_deg = Wrap360(-b * kRadToDeg);
    p.gantry_deg = Wrap360(-c * kRadToDeg);
    p.matrix = RtkMatrix(p);
    // The parameters must reproduce the pixel projection exactly (a failure is a bug here, not
    // bad input; say so rather than write a wrong file).
    const double d =
        RelativeMatrixDifference(PixelMatrixFromRtk(p.matrix, det), ProjectionMatrix(v));
    if (!(d < 1e-9)) {
      return Status::Error("view '" + v.id + "': internal error: the RTK parameters do not "
                           "reproduce the projection matrix (relative difference " +
                           FormatCompact(d) + ")");
    }
    out.push_back(p);
  }
  *detector = det;
  return out;
}

Matrix34 PixelMatrixFromRtk(const Matrix34& m, const RtkDetector& detector) {
  return -(PixelToDetector(detector).inverse() * m);
}

std::string RtkGeometryXml(const std::vector<RtkProjection>& ps) {
  std::ostringstream o;
  o << "<?xml version=\"1.0\"?>\n<!DOCTYPE RTKGEOMETRY>\n"
    << "<RTKThreeDCircularGeometry version=\"3\">\n";
  bool same_sdd = true;
  for (const auto& p : ps) same_sdd = same_sdd && p.sdd_mm == ps[0].sdd_mm;
  if (same_sdd && !ps.empty()) {
    o << "  <SourceToDetectorDistance>" << FmtRoundTrip(ps[0].sdd_mm)
      << "</SourceToDetectorDistance>\n";
  }
  for (const auto& p : ps) {
    o << "  <Projection>\n";
    o << "    <!-- carmba view " << std::regex_replace(p.id, std::regex("--"), "- -") << " -->\n";
    auto el = [&](const char* name, double v) {
      o << "    <" << name << ">" << FmtRoundTrip(v) << "</" << name << ">\n";
    };
    el("GantryAngle", p.gantry_deg);
    el("SourceToIsocenterDistance", p.sid_mm);
    if (!same_sdd) el("SourceToDetectorDistance", p.sdd_mm);
    el("SourceOffsetX", p.source_offset_x_mm);
    el("SourceOffsetY", p.source_offset_y_mm);
    el("ProjectionOffsetX", p.projection_offset_x_mm);
    el("ProjectionOffsetY", p.projection_offset_y_mm);
    el("InPlaneAngle", p.in_plane_deg);
    el("OutOfPlaneAngle", p.out_of_plane_deg);
    o << "    <Matrix>\n";
    for (int r = 0; r < 3; ++r) {
      o << "     ";
      for (int c = 0; c < 4; ++c) o << " " << FmtRoundTrip(p.matrix(r, c));
      o << "\n";
    }
    o << "    </Matrix>\n  </Projection>\n";
  }
  o << "</RTKThreeDCircularGeometry>\n";
  return o.str();
}

StatusOr<std::vector<RtkProjection>> ReadRtkGeometryXml(const std::string& path) {
  auto text = ReadFile(path);
  if (!text.ok()) return text.status();
  // Comments, the declaration and the DOCTYPE go first; what is left is elements with numbers.
  const std::string s = std::regex_replace(
      *text, std::regex("<!--[\\s\\S]*?-->|<\\?[\\s\\S]*?\\?>|<!DOCTYPE[^>]*>"), " ");
  std::smatch root;
  if (!std::regex_search(
          s, root, std::regex("<RTKThreeDCircularGeometry(\\s+version=\"([0-9]+)\")?\\s*>"))) {
    return Status::Error(path + ": expected the element <RTKThreeDCircularGeometry version=\"3\">");
  }
  if (root[2].str() != "2" && root[2].str() != "3") {
    return Status::Error(path + ": RTKThreeDCircularGeometry version '" + root[2].str() +
                         "': expected 2 or 3");
  }
  static const std::map<std::string, int> kIndex = {
      {"SourceToIsocenterDistance", 0}, {"SourceToDetectorDistance", 1}, {"GantryAngle", 2},
      {"Angle", 2}, {"OutOfPlaneAngle", 3}, {"InPlaneAngle", 4}, {"SourceOffsetX", 5},
      {"SourceOffsetY", 6}, {"ProjectionOffsetX", 7}, {"ProjectionOffsetY", 8}};
  double cur[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
  std::vector<RtkProjection> out;
  Matrix34 matrix = Matrix34::Zero();
  bool have_matrix = false;
  const std::regex tag("<(/?)([A-Za-z]+)[^>]*>");
  std::string::const_iterator pos = s.cbegin() + root.position(0) + root.length(0);
  std::smatch m;
  while (std::regex_search(pos, s.cend(), m, tag)) {
    const std::string name = m[2].str();
    const bool closing = !m[1].str().empty();
    const auto after = m[0].second;
    if (!closing && name != "Projection") {
      const std::string end = "</" + name + ">";
      const size_t from = static_cast<size_t>(after - s.cbegin());
      const size_t close = s.find(end, from);
      if (close == std::string::npos) return Status::Error(path + ": <" + name + "> is not closed");
      std::istringstream body(s.substr(from, close - from));
      if (name == "Matrix") {
        for (int k = 0; k < 12; ++k) {
          if (!(body >> matrix(k / 4, k % 4)) || !std::isfinite(matrix(k / 4, k % 4))) {
            return Status::Error(path + ": projection " + std::to_string(out.size() + 1) +
                                 ": <Matrix>: expected 12 numbers");
          }
        }
        have_matrix = true;
      } else {
        double v = 0;
        std::string rest;
        if (!(body >> v) || (body >> rest) || !std::isfinite(v)) {
          return Status::Error(path + ": <" + name + ">: expected one number");
        }
        auto it = kIndex.find(name);
        if (it != kIndex.end()) cur[it->second] = v;  // others (collimation, radius) are ignored
      }
      pos = s.cbegin() + static_cast<std::ptrdiff_t>(close + end.size());
      continue;
    }
    if (closing && name == "Projection") {
      RtkProjection p;
      p.sid_mm = cur[0];
      p.sdd_mm = cur[1];
      p.gantry_deg = cur[2];
      p.out_of_plane_deg = cur[3];
      p.in_plane_deg = cur[4];
      p.source_offset_x_mm = cur[5];
      p.source_offset_y_mm = cur[6];
      p.projection_offset_x_mm = cur[7];
      p.projection_offset_y_mm = cur[8];
      p.matrix = RtkMatrix(p);
      if (have_matrix) {
        const double d = (p.matrix - matrix).cwiseAbs().maxCoeff();
        if (d > 0.001) {
          return Status::Error(path + ": projection " + std::to_string(out.size() + 1) +
                               ": <Matrix> differs from the matrix of its parameters by " +
                               FormatCompact(d) + " (RTK's reader allows 0.001)");
        }
        p.matrix = matrix;
      }
      have_matrix = false;
      out.push_back(p);
    }
    pos = after;
  }
  if (out.empty()) return Status::Error(path + ": no <Projection>");
  return out;
}

nlohmann::json RtkDetectorJson(const RtkDetector& d, const std::vector<RtkProjection>& ps) {
  nlohmann::json ids = nlohmann::json::array();
  for (const auto& p : ps) ids.push_back(p.id);
  return {{"size_px", {d.width, d.height}},
          {"spacing_mm", {d.spacing_u_mm, d.spacing_v_mm}},
          {"origin_mm", {d.origin_u_mm(), d.origin_v_mm()}},
          {"direction", {{1, 0}, {0, 1}}},
          {"rows", "flipped: RTK projection row j is row H-1-j of carmba's undistorted image "
                   "(RTK's detector v axis points up, carmba's image rows go down)"},
          {"anisotropy_fx_over_fy", d.spacing_v_mm / d.spacing_u_mm},
          {"projections_in_order", ids}};
}

}  // namespace carmba
