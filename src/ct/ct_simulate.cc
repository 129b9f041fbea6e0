#include "ct/ct_simulate.h"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>
#include <filesystem>

#include "util/csv.h"
#include "util/plausible.h"
#include "util/file_util.h"
#include "util/format.h"

namespace carmba {

namespace {

// "(x, y, z)" to the micrometre.
std::string Mm3(const Eigen::Vector3d& v) { return FmtTriple("%.3f", v.x(), v.y(), v.z()); }


uint64_t Fnv1a(const std::string& s) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : s) {
    h ^= c;
    h *= 1099511628211ull;
  }
  return h;
}

// Optional keys are read only when present: YamlMap::Get on an absent key (util/yaml_reader.cc at
// 71ab5fb) records "expected ..., got nothing" because a default YAML::Node is defined.
template <typename T>
void Opt(YamlMap& m, const std::string& key, T* out) {
  if (m.Has(key)) m.Get(key, out);
}
// CT noise: 0 (noise-free) up to the largest CT value.
constexpr PlausibleRange kNoiseHu{0, plausible::kHounsfield.hi, "HU"};

void OptIn(YamlMap& m, const std::string& key, double* out, const PlausibleRange& range) {
  if (m.Has(key)) m.GetInRange(key, out, range);
}
// Each of a list's numbers within `range`.
void CheckEach(YamlMap& m,
               const std::string& key,
               const std::vector<double>& v,
               const PlausibleRange& range) {
  for (size_t i = 0; i < v.size(); ++i) {
    if (!InRange(v[i], range)) {
      m.Fail(key, "element " + std::to_string(i) + ": expected " + FormatRange(range) +
                      ", got " + FormatCompact(v[i]));
      return;
    }
  }
}

Status ReadPhantomMarkersCsv(const std::string& path,
                      const std::string& id_column_in,
                      const std::vector<std::string>& columns,
                      const std::string& where,
                      std::vector<CtMarker>* markers) {
  auto table = ReadCsv(path);
  if (!table.ok()) return table.status().WithContext(where);
  std::string id_column = id_column_in;
  if (id_column.empty()) {
    id_column = table->Column("id").ok() ? "id" : "marker";
  }
  for (int r = 0; r < static_cast<int>(table->rows.size()); ++r) {
    CtMarker m;
    auto id = table->Integer(r, id_column);
    if (!id.ok()) return id.status().WithContext(where);
    m.id = *id;
    for (int a = 0; a < 3; ++a) {
      auto x = table->NumberIn(r, columns[a], plausible::kCoordinateMm);
      if (!x.ok()) return x.status().WithContext(where);
      m.centre_mm[a] = *x;
    }
    for (const auto& other : *markers) {
      if (other.id == m.id) {
        return Status::Error(path + ":" + std::to_string(table->line_numbers[r]) +
                             ": duplicate marker id " + std::to_string(m.id));
      }
    }
    markers->push_back(m);
  }
  if (markers->empty()) return Status::Error(path + ": no markers (expected at least one row)");
  return Status::Ok();
}

}  // namespace

CtVolume MakeCtGeometry(int columns,
                        int rows,
                        int slices,
                        double pixel_spacing_mm,
                        double slice_spacing_mm,
                        double slice_thickness_mm,
                        const Eigen::Vector3d& row_dir,
                        const Eigen::Vector3d& col_dir,
                        const Eigen::Vector3d& centre_mm) {
  CtVolume v;
  v.columns = columns;
  v.rows = rows;
  v.slices = slices;
  v.spacing_mm = Eigen::Vector3d(pixel_spacing_mm, pixel_spacing_mm, slice_spacing_mm);
  v.slice_thickness_mm = slice_thickness_mm > 0 ? slice_thickness_mm : slice_spacing_mm;
  v.axes.col(0) = row_dir.normalized();
  v.axes.col(1) = (col_dir - v.axes.col(0).dot(col_dir) * v.axes.col(0)).normalized();
  v.axes.col(2) = v.axes.col(0).cross(v.axes.col(1));
  const Eigen::Vector3d half_index(0.5 * (columns - 1), 0.5 * (rows - 1), 0.5 * (slices - 1));
  v.origin_mm = centre_mm - v.PatientFromIndexLinear() * half_index;
  return v;
}

namespace {

// The scene's `markers` key: the CSV, its id and position columns.
struct CtMarkersKey {
  std::string csv, id_column;
  std::vector<std::string> columns = {"x_mm", "y_mm", "z_mm"};
};

void ParseCtMarkersKey(YamlMap& scene, CtScene* s, CtMarkersKey* k) {
  YamlMap& mk = scene.Map("markers", true);
  mk.Get("csv", &k->csv, true);
  Opt(mk, "id_column", &k->id_column);
  Opt(mk, "columns", &k->columns);
  if (k->columns.size() != 3) mk.Fail("columns", "expected 3 column names (x, y, z)");
  OptIn(mk, "diameter_mm", &s->phantom.marker_diameter_mm, plausible::kMarkerDiameterMm);
  OptIn(mk, "hu", &s->phantom.marker_hu, plausible::kHounsfield);
}

// The scene's `block` key: the plastic block, given (centre, size) or around the markers.
struct CtBlockKey {
  double padding_mm = 5;
  std::vector<double> centre, size;
};

void ParseCtBlockKey(YamlMap& scene, CtScene* s, CtBlockKey* k) {
  YamlMap& bl = scene.Map("block");
  Opt(bl, "enabled", &s->phantom.has_block);
  OptIn(bl, "padding_mm", &k->padding_mm, plausible::kLengthMm);
  Opt(bl, "centre_mm", &k->centre);
  Opt(bl, "size_mm", &k->size);
  OptIn(bl, "hu", &s->phantom.block_hu, plausible::kHounsfield);
  CheckEach(bl, "centre_mm", k->centre, plausible::kCoordinateMm);
  CheckEach(bl, "size_mm", k->size, plausible::kLengthMm);
  if (!k->centre.empty() && k->centre.size() != 3) bl.Fail("centre_mm", "expected 3 numbers");
  if (!k->size.empty() && k->size.size() != 3) bl.Fail("size_mm", "expected 3 numbers");
  if (k->centre.empty() != k->size.empty()) {
    bl.Fail(k->centre.empty() ? "size_mm" : "centre_mm",
            "centre_mm and size_mm must be given together");
  }
  for (double v : k->size) {
    if (!(v > 0)) bl.Fail("size_mm", "expected 3 positive sizes");
  }
}

// The scene's `ct` key: the grid and the reconstruction's effects.
struct CtGridKey {
  int columns_px = 512, rows_px = 512, slices = 120;
  double pixel_mm = 0.3515625, spacing_mm = 0.6, thickness_mm = 0, tilt_deg = 0;
  std::vector<double> centre, orientation = {1, 0, 0, 0, 1, 0};
  Eigen::Vector3d row_dir, col_dir;
};

void ParseCtGridKey(YamlMap& scene, CtScene* s, CtGridKey* k) {
  YamlMap& ct = scene.Map("ct");
  Opt(ct, "columns", &k->columns_px);
  Opt(ct, "rows", &k->rows_px);
  Opt(ct, "slices", &k->slices);
  OptIn(ct, "pixel_spacing_mm", &k->pixel_mm, plausible::kPixelPitchMm);
  OptIn(ct, "slice_spacing_mm", &k->spacing_mm, plausible::kPixelPitchMm);
  OptIn(ct, "slice_thickness_mm", &k->thickness_mm, plausible::kPixelPitchMm);
  Opt(ct, "centre_mm", &k->centre);
  Opt(ct, "orientation", &k->orientation);
  Opt(ct, "tilt_deg", &k->tilt_deg);
  OptIn(ct, "noise_hu", &s->voxelise.noise_hu, kNoiseHu);
  Opt(ct, "metal_streak_hu", &s->voxelise.metal_streak_hu);
  if (!(s->voxelise.metal_streak_hu >= 0 && s->voxelise.metal_streak_hu <= 10000)) {
    ct.Fail("metal_streak_hu", "expected 0 .. 10000 HU");
  }
  Opt(ct, "psf_sigma_mm", &s->voxelise.psf_sigma_mm);
  if (!(s->voxelise.psf_sigma_mm >= 0 && s->voxelise.psf_sigma_mm <= 10)) {
    ct.Fail("psf_sigma_mm", "expected 0 .. 10 mm");
  }
  Opt(ct, "clip_hu", &s->voxelise.clip_hu);
  if (!(s->voxelise.clip_hu >= 0 && s->voxelise.clip_hu <= 32767)) {
    ct.Fail("clip_hu", "expected 0 (none) .. 32767 HU");
  }
  Opt(ct, "supersampling", &s->voxelise.marker_supersampling);
  Opt(ct, "block_supersampling", &s->voxelise.block_supersampling);
  Opt(ct, "rescale_slope", &s->write.rescale_slope);
  Opt(ct, "rescale_intercept", &s->write.rescale_intercept);
  if (k->columns_px < 1 || k->columns_px > 4096) ct.Fail("columns", "expected 1 .. 4096");
  if (k->rows_px < 1 || k->rows_px > 4096) ct.Fail("rows", "expected 1 .. 4096");
  if (k->slices < 1 || k->slices > 4096) ct.Fail("slices", "expected 1 .. 4096");
  if (!k->centre.empty() && k->centre.size() != 3) ct.Fail("centre_mm", "expected 3 numbers");
  CheckEach(ct, "centre_mm", k->centre, plausible::kCoordinateMm);
  if (k->orientation.size() != 6) ct.Fail("orientation", "expected 6 numbers");
  if (!(std::abs(k->tilt_deg) < 80)) ct.Fail("tilt_deg", "expected an angle within (-80, 80)");
  if (s->voxelise.marker_supersampling < 1 || s->voxelise.marker_supersampling > 32) {
    ct.Fail("supersampling", "expected 1 .. 32");
  }
  if (s->voxelise.block_supersampling < 1 || s->voxelise.block_supersampling > 32) {
    ct.Fail("block_supersampling", "expected 1 .. 32");
  }
  if (!(s->write.rescale_slope > 0)) ct.Fail("rescale_slope", "expected a number > 0");

  if (k->orientation.size() == 6) {
    k->row_dir = Eigen::Vector3d(k->orientation[0], k->orientation[1], k->orientation[2]);
    k->col_dir = Eigen::Vector3d(k->orientation[3], k->orientation[4], k->orientation[5]);
    if (std::abs(k->row_dir.norm() - 1) > 1e-6 || std::abs(k->col_dir.norm() - 1) > 1e-6 ||
        std::abs(k->row_dir.dot(k->col_dir)) > 1e-6) {
      ct.Fail("orientation", "expected two orthogonal unit vectors");
    }
  }
}

// The markers from the CSV (at least two diameters apart) and the block: given, or the markers'
// bounding box grown by the padding and a radius; *lo_out, *hi_out the markers' bounding box.
Status PlaceCtMarkersAndBlock(YamlMap& scene,
                              const CtMarkersKey& markers,
                              const CtBlockKey& block,
                              CtScene* s,
                              Eigen::Vector3d* lo_out,
                              Eigen::Vector3d* hi_out) {
  const std::string csv_path = JoinPath(DirName(scene.file()), markers.csv);
  CARMBA_RETURN_IF_ERROR(ReadPhantomMarkersCsv(csv_path, markers.id_column, markers.columns,
                                        scene.file() + ": key 'markers.csv'",
                                        &s->phantom.markers));
  Eigen::Vector3d& lo = *lo_out;
  Eigen::Vector3d& hi = *hi_out;
  lo = s->phantom.markers[0].centre_mm, hi = lo;
  for (const auto& m : s->phantom.markers) {
    lo = lo.cwiseMin(m.centre_mm);
    hi = hi.cwiseMax(m.centre_mm);
  }
  const double radius = 0.5 * s->phantom.marker_diameter_mm;
  for (size_t a = 0; a < s->phantom.markers.size(); ++a) {
    for (size_t b = a + 1; b < s->phantom.markers.size(); ++b) {
      const double d =
          (s->phantom.markers[a].centre_mm - s->phantom.markers[b].centre_mm).norm();
      if (d < 2 * s->phantom.marker_diameter_mm) {
        return Status::Error(csv_path + ": markers " + std::to_string(s->phantom.markers[a].id) +
                             " and " + std::to_string(s->phantom.markers[b].id) + " are " +
                             std::to_string(d) + " mm apart, expected at least two diameters (" +
                             std::to_string(2 * s->phantom.marker_diameter_mm) + " mm)");
      }
    }
  }
  if (block.size.size() == 3) {
    const Eigen::Vector3d c(block.centre[0], block.centre[1], block.centre[2]);
    const Eigen::Vector3d h = 0.5 * Eigen::Vector3d(block.size[0], block.size[1], block.size[2]);
    s->phantom.block_min_mm = c - h;
    s->phantom.block_max_mm = c + h;
  } else {
    const double pad = block.padding_mm + radius;
    s->phantom.block_min_mm = lo - Eigen::Vector3d::Constant(pad);
    s->phantom.block_max_mm = hi + Eigen::Vector3d::Constant(pad);
  }
  return Status::Ok();
}

// The CT's geometry (centred on the markers unless given), every marker wholly inside it.
Status PlaceCtVolume(YamlMap& scene,
                     const CtGridKey& k,
                     const Eigen::Vector3d& lo,
                     const Eigen::Vector3d& hi,
                     CtScene* s) {
  const double radius = 0.5 * s->phantom.marker_diameter_mm;
  const double t = k.tilt_deg * M_PI / 180.0;
  const Eigen::Matrix3d tilt = Eigen::AngleAxisd(t, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const Eigen::Vector3d centre_mm = k.centre.size() == 3
                                        ? Eigen::Vector3d(k.centre[0], k.centre[1], k.centre[2])
                                        : 0.5 * (lo + hi);
  s->geometry = MakeCtGeometry(k.columns_px,
                               k.rows_px,
                               k.slices,
                               k.pixel_mm,
                               k.spacing_mm,
                               k.thickness_mm,
                               tilt * k.row_dir,
                               tilt * k.col_dir,
                               centre_mm);
  const Eigen::Matrix3d A_inv = s->geometry.PatientFromIndexLinear().inverse();
  const Eigen::Vector3d size(k.columns_px, k.rows_px, k.slices);
  for (const auto& m : s->phantom.markers) {
    const Eigen::Vector3d idx = A_inv * (m.centre_mm - s->geometry.origin_mm);
    for (int a = 0; a < 3; ++a) {
      const double r = radius / s->geometry.spacing_mm[a] + 1;
      if (idx[a] - r < 0 || idx[a] + r > size[a] - 1) {
        return Status::Error(scene.file() + ": key 'ct': marker " + std::to_string(m.id) +
                             " at " + Mm3(m.centre_mm) +
                             " mm does not lie wholly inside the CT volume (grow 'ct.slices', "
                             "'ct.rows'/'ct.columns' or move 'ct.centre_mm')");
      }
    }
  }
  return Status::Ok();
}

// Deterministic UIDs from the scene's content and seed (2.25.<64-bit hash>.<n>), the series
// description.
void SetCtUids(int seed, const CtGridKey& k, const std::string& description, CtScene* s) {
  std::string key = std::to_string(seed) + "|" + Mm3(s->geometry.origin_mm) + "|" +
                    std::to_string(k.columns_px) + "x" + std::to_string(k.rows_px) + "x" +
                    std::to_string(k.slices) + "|" + std::to_string(k.tilt_deg);
  for (const auto& m : s->phantom.markers) key += "|" + Mm3(m.centre_mm);
  const std::string root = "2.25." + std::to_string(Fnv1a(key));
  s->write.study_uid = root + ".1";
  s->write.series_uid = root + ".2";
  s->write.frame_of_reference_uid = root + ".3";
  s->write.series_description = description.empty() ? "carmba simulated CT" : description;
  if (s->write.series_description.size() > 64) s->write.series_description.resize(64);
}

}  // namespace

Status ParseCtScene(YamlMap& scene, CtScene* out) {
  CtScene s;
  std::string kind, description;
  scene.Get("kind", &kind, true);
  Opt(scene, "description", &description);
  if (scene.status().ok() && kind != "ct") scene.Fail("kind", "expected 'ct', got '" + kind + "'");
  int seed = 1;
  Opt(scene, "seed", &seed);
  if (seed < 0) scene.Fail("seed", "expected a non-negative integer");
  s.voxelise.seed = static_cast<uint64_t>(seed);
  CtMarkersKey markers;
  ParseCtMarkersKey(scene, &s, &markers);
  CtBlockKey block;
  ParseCtBlockKey(scene, &s, &block);
  OptIn(scene, "air_hu", &s.phantom.air_hu, plausible::kHounsfield);
  CtGridKey grid;
  ParseCtGridKey(scene, &s, &grid);
  CARMBA_RETURN_IF_ERROR(scene.Finish());
  Eigen::Vector3d lo, hi;
  CARMBA_RETURN_IF_ERROR(PlaceCtMarkersAndBlock(scene, markers, block, &s, &lo, &hi));
  CARMBA_RETURN_IF_ERROR(PlaceCtVolume(scene, grid, lo, hi, &s));
  SetCtUids(seed, grid, description, &s);
  *out = std::move(s);
  return Status::Ok();
}

nlohmann::json CtTruthJson(const CtScene& scene, const std::string& series_dir_name) {
  nlohmann::json t;
  t["markers"] = nlohmann::json::array();
  for (const auto& m : scene.phantom.markers) {
    t["markers"].push_back(
        {{"id", m.id}, {"x_mm", m.centre_mm.x()}, {"y_mm", m.centre_mm.y()},
         {"z_mm", m.centre_mm.z()}});
  }
  const CtVolume& g = scene.geometry;
  nlohmann::json ct;
  ct["dir"] = series_dir_name;
  ct["frame"] = "DICOM patient coordinates (LPS), mm";
  ct["columns"] = g.columns;
  ct["rows"] = g.rows;
  ct["slices"] = g.slices;
  ct["pixel_spacing_mm"] = g.spacing_mm.x();
  ct["slice_spacing_mm"] = g.spacing_mm.z();
  ct["slice_thickness_mm"] = g.slice_thickness_mm;
  ct["orientation"] = {g.axes(0, 0), g.axes(1, 0), g.axes(2, 0),
                       g.axes(0, 1), g.axes(1, 1), g.axes(2, 1)};
  ct["first_position_mm"] = {g.origin_mm.x(), g.origin_mm.y(), g.origin_mm.z()};
  ct["marker_diameter_mm"] = scene.phantom.marker_diameter_mm;
  ct["marker_hu"] = scene.phantom.marker_hu;
  ct["block_hu"] = scene.phantom.block_hu;
  ct["air_hu"] = scene.phantom.air_hu;
  if (scene.phantom.has_block) {
    ct["block_min_mm"] = {scene.phantom.block_min_mm.x(), scene.phantom.block_min_mm.y(),
                          scene.phantom.block_min_mm.z()};
    ct["block_max_mm"] = {scene.phantom.block_max_mm.x(), scene.phantom.block_max_mm.y(),
                          scene.phantom.block_max_mm.z()};
  }
  ct["noise_hu"] = scene.voxelise.noise_hu;
  ct["metal_streak_hu"] = scene.voxelise.metal_streak_hu;
  ct["psf_sigma_mm"] = scene.voxelise.psf_sigma_mm;
  ct["clip_hu"] = scene.voxelise.clip_hu;
  ct["seed"] = scene.voxelise.seed;
  ct["rescale_slope"] = scene.write.rescale_slope;
  ct["rescale_intercept"] = scene.write.rescale_intercept;
  ct["series_uid"] = scene.write.series_uid;
  ct["study_uid"] = scene.write.study_uid;
  t["ct"] = ct;
  return t;
}

Status SimulateCtScene(YamlMap& scene, const std::string& out_dir, nlohmann::json* truth) {
  CtScene s;
  CARMBA_RETURN_IF_ERROR(ParseCtScene(scene, &s));
  CtVolume volume = s.geometry;
  CARMBA_RETURN_IF_ERROR(VoxelisePhantom(s.phantom, s.voxelise, &volume));
  CARMBA_RETURN_IF_ERROR(MakeDirs(out_dir));
  int64_t clamped = 0;
  CARMBA_RETURN_IF_ERROR(WriteCtSeries(volume, JoinPath(out_dir, "ct"), s.write, &clamped));
  nlohmann::json t = CtTruthJson(s, "ct");
  t["ct"]["clamped_voxels"] = clamped;
  for (auto it = t.begin(); it != t.end(); ++it) (*truth)[it.key()] = it.value();
  return Status::Ok();
}

}  // namespace carmba
