#include "detect/observations.h"

#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>

#include "util/csv.h"
#include "util/file_util.h"
#include "util/plausible.h"
#include "util/format.h"

namespace carmba {

const char* GridPatternName(GridPattern pattern) {
  switch (pattern) {
    case GridPattern::kCircles:
      return "circles";
    case GridPattern::kAsymmetricCircles:
      return "acircles";
    case GridPattern::kChessboard:
      return "chessboard";
  }
  return "?";
}

StatusOr<GridPattern> ParseGridPattern(const std::string& name) {
  if (name == "circles") return GridPattern::kCircles;
  if (name == "acircles") return GridPattern::kAsymmetricCircles;
  if (name == "chessboard") return GridPattern::kChessboard;
  return Status::Error("pattern '" + name + "': expected circles, acircles or chessboard");
}

bool GridSpec::Check(std::string* error) const {
  if (!(CheckRange("grid: rows", rows, plausible::kGridRowsCols, error) &&
        CheckRange("grid: cols", cols, plausible::kGridRowsCols, error) &&
        CheckRange("grid: spacing_mm", spacing_mm, plausible::kGridSpacingMm, error))) {
    return false;
  }
  if (sphere_diameter_mm != 0 &&
      !CheckRange(
          "grid: sphere_diameter_mm", sphere_diameter_mm, plausible::kMarkerDiameterMm, error)) {
    return false;
  }
  if (!(sphere_diameter_mm < spacing_mm)) {
    *error = "grid: sphere_diameter_mm " + FormatCompact(sphere_diameter_mm) +
             " is not below the spacing " + FormatCompact(spacing_mm) + " mm (spheres would touch)";
    return false;
  }
  // OpenCV's chessboard finder throws below 3 x 3 inner corners.
  if (pattern == GridPattern::kChessboard && (rows < 3 || cols < 3)) {
    *error = "grid: a chessboard needs at least 3 x 3 inner corners (rows " + std::to_string(rows) +
             ", cols " + std::to_string(cols) + ")";
    return false;
  }
  return true;
}

Eigen::Vector3d GridSpec::PointInPlate(int id) const {
  const int r = id / cols, c = id % cols;
  if (pattern == GridPattern::kAsymmetricCircles) {
    return Eigen::Vector3d((2 * c + r % 2) * spacing_mm, r * spacing_mm, 0.0);
  }
  return Eigen::Vector3d(c * spacing_mm, r * spacing_mm, 0.0);
}

std::vector<Eigen::Vector3d> GridSpec::PointsInPlate() const {
  std::vector<Eigen::Vector3d> points;
  for (int id = 0; id < NumPoints(); ++id) points.push_back(PointInPlate(id));
  return points;
}

ba::BaView ToBaPlateView(const ViewObservations& view,
                         std::string id,
                         int group,
                         const Pose6& cam_from_plate,
                         double sigma_px) {
  ba::BaView out;
  out.id = std::move(id);
  out.kind = ba::ViewKind::kPlate;
  out.group = group;
  out.initial = cam_from_plate;
  out.point_ids = view.point_ids;
  out.uv_px = view.uv_px;
  out.sigma_px = sigma_px;
  return out;
}

ba::BaProblem ToBaPlateProblem(const std::string& name,
                               const ObservationSet& plate,
                               std::vector<ba::IntrinsicsGroup> groups,
                               std::vector<ba::BaView> plate_views) {
  ba::BaProblem bp;
  bp.name = name;
  bp.groups = std::move(groups);
  if (!plate.views.empty()) bp.plate.points = plate.grid.PointsInPlate();
  bp.plate.sphere_radius_mm = plate.grid.sphere_diameter_mm / 2;
  bp.views = std::move(plate_views);
  return bp;
}

int ObservationSet::NumPoints() const {
  int n = 0;
  for (const auto& v : views) n += static_cast<int>(v.uv_px.size());
  return n;
}

Status WriteObservationsCsv(const ObservationSet& obs, const std::string& path) {
  std::ostringstream o;
  o << "# carmba observations\n";
  o << "# grid: " << GridPatternName(obs.grid.pattern) << " " << obs.grid.rows << " "
    << obs.grid.cols << " " << FmtRoundTrip(obs.grid.spacing_mm) << "\n";
  o << "# image_size: " << obs.width << " " << obs.height << "\n";
  o << "view,image,point,u_px,v_px\n";
  for (size_t v = 0; v < obs.views.size(); ++v) {
    const auto& view = obs.views[v];
    for (size_t i = 0; i < view.uv_px.size(); ++i) {
      o << v << "," << view.image << "," << view.point_ids[i] << ","
        << FmtRoundTrip(view.uv_px[i].x()) << "," << FmtRoundTrip(view.uv_px[i].y()) << "\n";
    }
  }
  return WriteFileAtomic(path, o.str());
}

StatusOr<ObservationSet> ReadObservationsCsv(const std::string& path) {
  auto table_or = ReadCsv(path);
  if (!table_or.ok()) return table_or.status();
  const CsvTable& t = *table_or;
  ObservationSet obs;
  bool have_grid = false, have_size = false;
  for (const auto& c : t.comments) {
    std::istringstream is(c);
    std::string key;
    is >> key;
    if (key == "grid:") {
      std::string pattern;
      if (!(is >> pattern >> obs.grid.rows >> obs.grid.cols >> obs.grid.spacing_mm)) {
        return Status::Error(path + ": comment '# grid:': expected 'pattern rows cols spacing_mm'");
      }
      auto p = ParseGridPattern(pattern);
      if (!p.ok()) return p.status().WithContext(path + ": '# grid:'");
      obs.grid.pattern = *p;
      have_grid = true;
    } else if (key == "image_size:") {
      double w = 0, h = 0;
      if (!(is >> w >> h) || w != std::floor(w) || h != std::floor(h) ||
          !InRange(w, plausible::kImageSizePx) || !InRange(h, plausible::kImageSizePx)) {
        return Status::Error(path + ": comment '# image_size:': expected 'width height', each an "
                             "integer " + FormatRange(plausible::kImageSizePx) + ", got '" +
                             c.substr(c.find(':') + 1) + "'");
      }
      obs.width = static_cast<int>(w);
      obs.height = static_cast<int>(h);
      have_size = true;
    }
  }
  if (!have_grid)
    return Status::Error(path + ": missing comment '# grid: pattern rows cols spacing_mm'");
  if (!have_size) return Status::Error(path + ": missing comment '# image_size: width height'");
  std::string err;
  if (!obs.grid.Check(&err)) return Status::Error(path + ": " + err);
  auto image_col = t.Column("image");
  if (!image_col.ok()) return image_col.status();
  std::map<int, int> view_index;  // file view number -> index
  std::vector<std::vector<bool>> seen;
  for (size_t r = 0; r < t.rows.size(); ++r) {
    const std::string where = path + ":" + std::to_string(t.line_numbers[r]);
    auto view = t.Integer(r, "view");
    if (!view.ok()) return view.status();
    auto point = t.Integer(r, "point");
    if (!point.ok()) return point.status();
    auto u = t.NumberIn(r, "u_px", plausible::kPixelCoordinatePx);
    if (!u.ok()) return u.status();
    auto v = t.NumberIn(r, "v_px", plausible::kPixelCoordinatePx);
    if (!v.ok()) return v.status();
    if (*point < 0 || *point >= obs.grid.NumPoints()) {
      return Status::Error(where + ": column 'point': expected 0.." +
                           std::to_string(obs.grid.NumPoints() - 1) + ", got " +
                           std::to_string(*point));
    }
    auto it = view_index.find(*view);
    if (it == view_index.end()) {
      it = view_index.emplace(*view, static_cast<int>(obs.views.size())).first;
      obs.views.emplace_back();
      obs.views.back().image = t.rows[r][*image_col];
      seen.emplace_back(obs.grid.NumPoints(), false);
    }
    auto& vo = obs.views[it->second];
    if (seen[it->second][*point]) {
      return Status::Error(where + ": point " + std::to_string(*point) + " of view " +
                           std::to_string(*view) + " appears twice");
    }
    seen[it->second][*point] = true;
    vo.point_ids.push_back(*point);
    vo.uv_px.emplace_back(*u, *v);
  }
  if (obs.views.empty()) return Status::Error(path + ": no observations");
  return obs;
}

StatusOr<ObservationSet> ObservationsFromArray(const double* uv,
                                               int views,
                                               const GridSpec& grid,
                                               double width,
                                               double height,
                                               const std::string& name) {
  if (views <= 0) return Status::Error(name + ": no views");
  if (!InRange(width, plausible::kImageSizePx) || !InRange(height, plausible::kImageSizePx) ||
      width != std::floor(width) || height != std::floor(height)) {
    return Status::Error("image_size: expected (width, height), each an integer " +
                         FormatRange(plausible::kImageSizePx));
  }
  ObservationSet obs;
  obs.grid = grid;
  obs.width = static_cast<int>(width);
  obs.height = static_cast<int>(height);
  const int n = grid.NumPoints();
  for (int v = 0; v < views; ++v) {
    ViewObservations view;
    view.image = "view " + std::to_string(v);
    for (int k = 0; k < n; ++k) {
      const double u = uv[2 * (v * n + k)], w = uv[2 * (v * n + k) + 1];
      if (std::isnan(u) && std::isnan(w)) continue;
      if (!InRange(u, plausible::kPixelCoordinatePx) ||
          !InRange(w, plausible::kPixelCoordinatePx)) {
        return Status::Error(name + "[" + std::to_string(v) + ", " + std::to_string(k) +
                             "]: expected a pixel (u, v), each " +
                             FormatRange(plausible::kPixelCoordinatePx) +
                             ", or (NaN, NaN) for a point not seen; got (" + FmtRoundTrip(u) +
                             ", " + FmtRoundTrip(w) + ")");
      }
      view.point_ids.push_back(k);
      view.uv_px.emplace_back(u, w);
    }
    obs.views.push_back(std::move(view));
  }
  return obs;
}

std::string CornersVnl(const ObservationSet& obs) {
  std::ostringstream o;
  o << "# filename x y level\n";
  const int n = obs.grid.NumPoints();
  for (const auto& view : obs.views) {
    std::vector<int> where(n, -1);
    for (size_t i = 0; i < view.point_ids.size(); ++i) where[view.point_ids[i]] = i;
    std::string name = view.image;
    for (char& ch : name) {
      if (ch == ' ') ch = '_';
    }
    for (int id = 0; id < n; ++id) {
      if (where[id] < 0) {
        o << name << " nan nan -\n";
      } else {
        o << name << " " << FmtRoundTrip(view.uv_px[where[id]].x()) << " "
          << FmtRoundTrip(view.uv_px[where[id]].y()) << " 0\n";
      }
    }
  }
  return o.str();
}

}  // namespace carmba
