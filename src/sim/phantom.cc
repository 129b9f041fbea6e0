#include "sim/phantom.h"

#include <cmath>
#include <set>

#include "util/csv.h"
#include "util/plausible.h"

namespace carmba::sim {

std::map<std::string, double> DefaultMaterials() {
  return {{"steel", 0.94},
          {"tungsten", 7.0},
          {"aluminium", 0.074},
          {"pmma", 0.023},
          {"water", 0.0206},
          {"bone", 0.057},
          {"wood", 0.010},
          {"air", 0.0}};
}

namespace {
StatusOr<double> MaterialMu(const std::map<std::string, double>& materials,
                            const std::string& name) {
  auto it = materials.find(name);
  if (it == materials.end()) {
    std::string known;
    for (const auto& kv : materials) known += (known.empty() ? "" : ", ") + kv.first;
    return Status::Error("unknown material '" + name + "' (known: " + known + ")");
  }
  return it->second;
}
}  // namespace

bool PlateSpec::Check(std::string* error) const {
  if (rows < 1 || cols < 1 || rows * cols < 2) {
    return *error = "plate: rows and cols must be >= 1 with at least 2 spheres", false;
  }
  if (rows > plausible::kGridRowsCols.hi || cols > plausible::kGridRowsCols.hi) {
    return *error = "plate: rows and cols must be <= " +
                    FormatCompact(plausible::kGridRowsCols.hi),
           false;
  }
  if (!CheckRange("plate: pitch_mm", pitch_mm, plausible::kGridSpacingMm, error)) return false;
  if (!(sphere_diameter_mm > 0) || !(sphere_diameter_mm < pitch_mm)) {
    return *error = "plate: sphere_diameter_mm must be > 0 and smaller than pitch_mm", false;
  }
  if (!CheckRange("plate: thickness_mm", thickness_mm, plausible::kLengthMm, error) ||
      !CheckRange("plate: margin_mm", margin_mm, plausible::kLengthMm, error)) {
    return false;
  }
  return true;
}

bool MarkerSpec::Check(std::string* error) const {
  if (centers_mm.empty()) return *error = "markers: no marker centres", false;
  if (ids.size() != centers_mm.size()) return *error = "markers: one id per centre expected", false;
  if (!(sphere_diameter_mm > 0) || !std::isfinite(sphere_diameter_mm)) {
    return *error = "markers: sphere_diameter_mm must be > 0", false;
  }
  std::set<int> seen;
  for (size_t i = 0; i < centers_mm.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      if (!CheckRange("markers: marker " + std::to_string(ids[i]) + ": " + "xyz"[k],
                      centers_mm[i][k], plausible::kCoordinateMm, error)) {
        return false;
      }
    }
    if (!seen.insert(ids[i]).second) {
      return *error = "markers: duplicate id " + std::to_string(ids[i]), false;
    }
    for (size_t j = 0; j < i; ++j) {
      if ((centers_mm[i] - centers_mm[j]).norm() < sphere_diameter_mm) {
        return *error = "markers " + std::to_string(ids[j]) + " and " + std::to_string(ids[i]) +
                        " overlap (centres closer than sphere_diameter_mm)",
               false;
      }
    }
  }
  if (!(block_margin_mm >= 0) || !std::isfinite(block_margin_mm)) {
    return *error = "markers: block margin must be >= 0", false;
  }
  return true;
}

StatusOr<Phantom> MakePlatePhantom(const PlateSpec& spec,
                                   const std::map<std::string, double>& materials) {
  std::string error;
  if (!spec.Check(&error)) return Status::Error(error);
  auto mu_sphere = MaterialMu(materials, spec.sphere_material);
  if (!mu_sphere.ok()) return mu_sphere.status();
  auto mu_plate = MaterialMu(materials, spec.plate_material);
  if (!mu_plate.ok()) return mu_plate.status();
  Phantom p;
  p.frame = "plate";
  int host = -1;
  if (spec.thickness_mm > 0) {
    BoxPrimitive box;
    box.phantom_from_box.t = Eigen::Vector3d(
        0.5 * (spec.cols - 1) * spec.pitch_mm, 0.5 * (spec.rows - 1) * spec.pitch_mm, 0.0);
    box.half_size_mm = Eigen::Vector3d(0.5 * (spec.cols - 1) * spec.pitch_mm + spec.margin_mm,
                                       0.5 * (spec.rows - 1) * spec.pitch_mm + spec.margin_mm,
                                       0.5 * spec.thickness_mm);
    box.mu_per_mm = *mu_plate;
    p.boxes.push_back(box);
    host = 0;
  }
  for (int r = 0; r < spec.rows; ++r) {
    for (int c = 0; c < spec.cols; ++c) {
      SpherePrimitive s;
      s.center_mm = Eigen::Vector3d(c * spec.pitch_mm, r * spec.pitch_mm, 0.0);
      s.radius_mm = 0.5 * spec.sphere_diameter_mm;
      s.mu_per_mm = *mu_sphere;
      s.host_box = host;
      s.id = r * spec.cols + c;
      p.spheres.push_back(s);
    }
  }
  return p;
}

StatusOr<Phantom> MakeMarkerPhantom(const MarkerSpec& spec,
                                    const std::map<std::string, double>& materials) {
  std::string error;
  if (!spec.Check(&error)) return Status::Error(error);
  auto mu_sphere = MaterialMu(materials, spec.sphere_material);
  if (!mu_sphere.ok()) return mu_sphere.status();
  Phantom p;
  p.frame = "object";
  int host = -1;
  if (spec.block) {
    auto mu_block = MaterialMu(materials, spec.block_material);
    if (!mu_block.ok()) return mu_block.status();
    Eigen::Vector3d lo = spec.centers_mm[0], hi = spec.centers_mm[0];
    for (const auto& c : spec.centers_mm) {
      lo = lo.cwiseMin(c);
      hi = hi.cwiseMax(c);
    }
    const double pad = 0.5 * spec.sphere_diameter_mm + spec.block_margin_mm;
    BoxPrimitive box;
    box.phantom_from_box.t = 0.5 * (lo + hi);
    box.half_size_mm = 0.5 * (hi - lo) + Eigen::Vector3d::Constant(pad);
    box.mu_per_mm = *mu_block;
    p.boxes.push_back(box);
    host = 0;
  }
  for (size_t i = 0; i < spec.centers_mm.size(); ++i) {
    SpherePrimitive s;
    s.center_mm = spec.centers_mm[i];
    s.radius_mm = 0.5 * spec.sphere_diameter_mm;
    s.mu_per_mm = *mu_sphere;
    s.host_box = host;
    s.id = spec.ids[i];
    p.spheres.push_back(s);
  }
  return p;
}

Status ReadMarkerCsv(const std::string& path,
                     const std::string& id_col,
                     const std::string& x_col,
                     const std::string& y_col,
                     const std::string& z_col,
                     MarkerSpec* spec) {
  auto table = ReadCsv(path);
  if (!table.ok()) return table.status();
  if (table->rows.empty()) return Status::Error(path + ": no marker rows");
  spec->centers_mm.clear();
  spec->ids.clear();
  for (int r = 0; r < static_cast<int>(table->rows.size()); ++r) {
    Eigen::Vector3d c;
    const std::string cols[3] = {x_col, y_col, z_col};
    for (int k = 0; k < 3; ++k) {
      auto v = table->NumberIn(r, cols[k], plausible::kCoordinateMm);
      if (!v.ok()) return v.status();
      c[k] = *v;
    }
    int id = r + 1;
    if (!id_col.empty()) {
      auto v = table->Integer(r, id_col);
      if (!v.ok()) return v.status();
      id = *v;
    }
    spec->centers_mm.push_back(c);
    spec->ids.push_back(id);
  }
  return Status::Ok();
}

}  // namespace carmba::sim
