// The one problem reader (format in problem.h).
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <set>

#include "camera/carm_geometry.h"
#include "detect/grid_detector.h"
#include "detect/marker_views.h"
#include "io/dicom_xray.h"
#include "io/pixel_csv.h"
#include "problem/problem.h"
#include "util/csv.h"
#include "util/file_util.h"
#include "util/plausible.h"
#include "util/yaml_reader.h"

namespace carmba {
namespace {

std::string Stem(const std::string& path) { return std::filesystem::path(path).stem().string(); }

// ---- Plate views ---------------------------------------------------------------------------

// The grid the keys name, checked against an observations file's own.
Status CheckGridOfFile(const PlateViewsInput& in, const GridSpec& file_grid) {
  const GridSpec& grid = *in.grid;
  if (file_grid.pattern == grid.pattern && file_grid.rows == grid.rows &&
      file_grid.cols == grid.cols && std::abs(file_grid.spacing_mm - grid.spacing_mm) <= 1e-9) {
    return Status::Ok();
  }
  return Status::Error(in.observations + ": grid " + GridPatternName(file_grid.pattern) + " " +
                       std::to_string(file_grid.rows) + "x" + std::to_string(file_grid.cols) +
                       " spacing " + std::to_string(file_grid.spacing_mm) + " mm, but " +
                       in.key("rows") + "/cols/spacing_mm say " + GridPatternName(grid.pattern) +
                       " " + std::to_string(grid.rows) + "x" + std::to_string(grid.cols) +
                       " spacing " + std::to_string(grid.spacing_mm) + " mm");
}

// Plate view ids: image stems, or the view's number where a stem is missing or repeated.
void NamePlateViews(Problem* p) {
  std::set<std::string> ids;
  for (size_t v = 0; v < p->plate.views.size(); ++v) {
    std::string id = Stem(p->plate.views[v].image);
    if (id.empty() || !ids.insert(id).second) id = std::to_string(v);
    ids.insert(id);
    p->plate_view_ids.push_back(id);
  }
}

// Where a problem's plate views are: its `plate_views` map, or, in a calibration problem file
// written before the one schema, the file's top level (without sigma_px, plate and detection).
struct PlateViewsSource {
  bool older = false;
  std::string older_config;  // that older file's `config`, resolved
};

// The plate images' detection options: `plate_views.detection`, else the command's (calibrate
// --detection), else the defaults. (An older calibration file's config held them; that config is
// now refused, naming where they went.)
Status PlateDetectionOptions(YamlMap& m,
                             const PlateViewsSource& src,
                             const ProblemReadOptions& o,
                             DetectionOptions* d) {
  if (!src.older && m.Has("detection")) {
    YamlMap& dm = m.Map("detection");
    ReadDetectionOptions(dm, d);
    CARMBA_RETURN_IF_ERROR(dm.Finish());
  } else if (o.plate_detection) {
    *d = *o.plate_detection;
  }
  std::string err;
  if (m.status().ok() && !d->Check(&err)) m.Fail("detection", err);
  return m.status();
}

// The grid's observations from the CSV, or detected in the images.
Status ReadOrDetectPlate(const PlateViewsInput& in, Problem* p) {
  if (!in.observations.empty()) {
    auto obs = ReadObservationsCsv(in.observations);
    if (!obs.ok()) return obs.status();
    if (in.grid) CARMBA_RETURN_IF_ERROR(CheckGridOfFile(in, obs->grid));
    p->plate = *obs;
    if (in.spacing_mm_override > 0) p->plate.grid.spacing_mm = in.spacing_mm_override;
    return Status::Ok();
  }
  if (!in.grid) {
    return in.fail("rows", "plate images need the grid: pattern, rows, cols, spacing_mm");
  }
  auto files = ListImageFiles(in.images);
  if (!files.ok()) return files.status().WithContext(in.key("images"));
  const ProgressFn tick =
      in.detecting ? in.detecting(static_cast<int>(files->size())) : ProgressFn();
  auto obs = DetectGridInFiles(
      *files, *in.grid, in.detection, &p->skipped_images, nullptr, &p->plate_detections, tick);
  if (!obs.ok()) return obs.status();
  p->plate = *obs;
  return Status::Ok();
}

}  // namespace

void NameInputsAsFlags(PlateViewsInput* in) {
  in->key = [](const std::string& input) {
    std::string flag = "--" + input;
    std::replace(flag.begin(), flag.end(), '_', '-');
    return flag;
  };
  in->fail = [key = in->key](const std::string& input, const std::string& what) {
    return Status::Error(key(input) + ": " + what);
  };
}

Status LoadPlateViews(const PlateViewsInput& in, Problem* p) {
  if (in.observations.empty() == in.images.empty()) {
    return in.fail("observations",
                   "give exactly one of observations (CSV) and images (DIR or GLOB)");
  }
  std::string err;
  if (in.grid) {
    if (!in.grid->Check(&err)) return in.fail("rows", err);
    // Spheres wider than the pitch, said before any image is read (GridSpec::Check's rule).
    GridSpec with_spheres = *in.grid;
    with_spheres.sphere_diameter_mm = in.sphere_diameter_mm;
    if (!with_spheres.Check(&err)) return in.fail("sphere_diameter_mm", err);
  }
  CARMBA_RETURN_IF_ERROR(ReadOrDetectPlate(in, p));
  p->plate.grid.sphere_diameter_mm = in.sphere_diameter_mm;
  if (!p->plate.grid.Check(&err)) return in.fail("sphere_diameter_mm", err);
  NamePlateViews(p);
  if (p->plate.views.empty() && !in.images.empty()) {
    // Detection found the grid nowhere: most often rows / cols / pattern do not match the plate.
    const GridSpec& g = *in.grid;
    return in.fail(
        "images",
        "the grid (" + std::string(GridPatternName(g.pattern)) + " " + std::to_string(g.rows) +
            " x " + std::to_string(g.cols) + ": " + in.key("pattern") + ", " + in.key("rows") +
            ", " + in.key("cols") + ") was found in 0 of " +
            std::to_string(p->skipped_images.size()) + " images: check rows and cols" +
            (p->skipped_images.empty() ? "" : "; first skipped: " + p->skipped_images.front()));
  }
  if (p->plate.views.empty()) {
    return in.fail("observations", "no plate views in " + in.observations);
  }
  return Status::Ok();
}

namespace {

// A problem file's `plate_views` keys (or an older calibration file's top level) into the plate
// views, through LoadPlateViews.
Status ReadPlateViews(YamlMap& m,
                      const std::string& base,
                      const PlateViewsSource& src,
                      const ProblemReadOptions& options,
                      Problem* p) {
  PlateViewsInput in;
  in.key = [&m](const std::string& input) { return m.KeyPath(input); };
  in.fail = [&m](const std::string& input, const std::string& what) {
    m.Fail(input, what);
    return m.status();
  };
  std::string observations, images, pattern = "circles";
  GridSpec grid;
  const bool has_grid = m.Has("rows") || m.Has("cols") || m.Has("spacing_mm") || m.Has("pattern");
  m.Get("observations", &observations);
  m.Get("images", &images);
  m.GetEnum("pattern", {"circles", "acircles", "chessboard"}, &pattern);
  m.GetInRange("rows", &grid.rows, plausible::kGridRowsCols);
  m.GetInRange("cols", &grid.cols, plausible::kGridRowsCols);
  m.GetInRange("spacing_mm", &grid.spacing_mm, plausible::kGridSpacingMm);
  if (!src.older) {
    m.GetInRange("sigma_px", &p->plate_sigma_px, plausible::kPixelSigmaPx);
    m.GetInRange("sphere_diameter_mm", &in.sphere_diameter_mm, plausible::kMarkerDiameterMm);
    YamlMap& plate = m.Map("plate");
    plate.Get("free", &p->plate_free);
    if (plate.Has("sigma_mm")) {
      plate.GetInRange("sigma_mm", &p->plate_sigma_mm, plausible::kToleranceMm);
    }
  }
  if (!images.empty()) {
    CARMBA_RETURN_IF_ERROR(PlateDetectionOptions(m, src, options, &in.detection));
  } else if (!src.older && m.Has("detection")) {
    m.Raw("detection");
    m.Fail("detection", "detection options are for plate images; these plate views are a CSV");
  }
  if (!m.status().ok()) return m.status();
  auto pat = ParseGridPattern(pattern);
  if (!pat.ok()) return pat.status();
  grid.pattern = *pat;
  if (has_grid) in.grid = grid;
  if (!observations.empty()) in.observations = JoinPath(base, observations);
  if (!images.empty()) in.images = JoinPath(base, images);
  return LoadPlateViews(in, p);
}

// ---- Object views and fiducials: what the keys name, read before any file ---------------------

// `object_views` (or a pose problem's older top-level `observations`, `sigma_px`, `views`).
struct ObjectViewsKey {
  std::string observations, format = "long", marker_column = "marker";
  std::vector<std::string> views;  // the views used, in this order (empty: all, in file order)
  // From images: detected and labelled once the camera and the fiducials are read.
  std::string images;
  ObjectViewsOptions options;
  Status status;  // of the keys' mapping: a bad value there is reported before any file is read
};

// `fiducials`: a CSV path, or {file, id_column, columns, sigma_mm} (a pose problem's older
// `markers` is the same map).
struct FiducialsKey {
  std::string file, id_column = "id", sigma_key;
  std::vector<std::string> columns = {"x_mm", "y_mm", "z_mm"};
  double sigma_mm = -1;
  Status status;  // of the keys' mapping
};

// A view id: a number or a string.
std::string ViewIdFrom(const YAML::Node& n) { return n.IsScalar() ? n.Scalar() : std::string(); }

void ReadViewList(YamlMap& m, std::vector<std::string>* views) {
  if (!m.Has("views")) return;
  const YAML::Node vn = m.Raw("views");
  if (!vn.IsSequence()) {
    m.Fail("views", "expected a list of view ids");
    return;
  }
  for (const auto& v : vn) views->push_back(ViewIdFrom(v));
  if (views->empty()) {
    m.Fail("views", "expected a non-empty list of view ids (omit the key for all views)");
  }
}

void ReadObjectViewsKey(YamlMap& m, Problem* p, ObjectViewsKey* k) {
  if (m.Has("images")) {
    m.Get("images", &k->images, true);
    if (m.Has("observations")) m.Fail("observations", "give observations or images, not both");
    YamlMap& d = m.Map("detection", true);
    ReadObjectViewsOptions(d, &k->options);
    double unused = 0;
    m.GetInRange("sigma_px", &unused, plausible::kPixelSigmaPx);
    k->status = m.status();
    return;
  }
  m.Get("observations", &k->observations, true);
  m.GetEnum("format", {"wide", "long"}, &k->format);
  m.Get("marker_column", &k->marker_column);
  ReadViewList(m, &k->views);
  m.GetInRange("sigma_px", &p->object_sigma_px, plausible::kPixelSigmaPx, true);
  k->status = m.status();
}

void ReadFiducialsMap(YamlMap& m, FiducialsKey* f) {
  m.Get("file", &f->file, true);
  m.Get("id_column", &f->id_column);
  m.Get("columns", &f->columns);
  m.GetInRange("sigma_mm", &f->sigma_mm, plausible::kCtSigmaMm);
  f->sigma_key = m.KeyPath("sigma_mm");
  if (f->columns.size() != 3) m.Fail("columns", "expected three column names (x, y, z)");
  f->status = m.status();
}

void ReadFiducialsKey(YamlMap& root, bool has_object, FiducialsKey* f) {
  f->sigma_key = root.KeyPath("fiducials") + ".sigma_mm";
  if (!has_object) {
    if (root.Has("fiducials")) root.Raw("fiducials");
    return;
  }
  if (!root.Has("fiducials")) {
    root.Fail("fiducials", "object views need the fiducials (CSV from `carmba ct-fiducials`)");
  } else if (root.Raw("fiducials").IsScalar()) {
    f->file = root.Raw("fiducials").Scalar();
  } else {
    ReadFiducialsMap(root.Map("fiducials"), f);
  }
}

// A pose problem in the spelling before the one schema: `markers` for `fiducials`,
// `observations: {file, format, marker_column}`, `sigma_px` and `views` for `object_views`.
bool HasOlderPoseKeys(const YamlMap& root) {
  return root.Has("markers") || root.Has("observations");
}

// A calibration problem in the spelling before the one schema: top-level `images` or
// `observations` (a CSV path), `pattern`, `rows`, `cols`, `spacing_mm` for `plate_views`, and its
// `config`.
bool HasOlderCalibrationKeys(YamlMap& root) {
  for (const char* key : {"images", "pattern", "rows", "cols", "spacing_mm"}) {
    if (root.Has(key)) return true;
  }
  return root.Has("observations") && !root.Has("markers") && root.Raw("observations").IsScalar();
}

void ReadOlderCalibrationKeys(YamlMap& root, const std::string& base, PlateViewsSource* src) {
  src->older = true;
  if (root.Has("plate_views")) {
    root.Raw("plate_views");
    root.Fail("plate_views",
              "give plate_views, or the older top-level images (or observations), pattern, rows, "
              "cols, spacing_mm, not both");
  }
  std::string config;
  root.Get("config", &config);
  if (!config.empty()) src->older_config = JoinPath(base, config);
}

void ReadOlderPoseKeys(YamlMap& root, Problem* p, FiducialsKey* f, ObjectViewsKey* k) {
  for (const char* key : {"fiducials", "object_views"}) {
    if (root.Has(key)) {
      root.Raw(key);
      root.Fail(key,
                "give fiducials and object_views, or the older markers and observations, "
                "not both");
    }
  }
  ReadFiducialsMap(root.Map("markers", true), f);
  YamlMap& o = root.Map("observations", true);
  o.Get("file", &k->observations, true);
  o.GetEnum("format", {"wide", "long"}, &k->format);
  o.Get("marker_column", &k->marker_column);
  k->status = o.status();
  root.GetInRange("sigma_px", &p->object_sigma_px, plausible::kPixelSigmaPx, true);
  ReadViewList(root, &k->views);
}

// ---- Object views and fiducials: the files ----------------------------------------------------

// Columns u_<id>, v_<id> per view, a row per marker (the thesis's tables).
Status ReadWideObservations(const std::string& path,
                            const std::string& id_column,
                            std::vector<PoseView>* views) {
  auto t = ReadCsv(path);
  if (!t.ok()) return t.status();
  std::vector<std::string> ids;
  for (const auto& h : t->header) {
    if (h.rfind("u_", 0) == 0) ids.push_back(h.substr(2));
  }
  for (const auto& id : ids) {
    auto vc = t->Column("v_" + id);
    if (!vc.ok()) return vc.status();
  }
  for (const auto& id : ids) {
    PoseView v;
    v.id = id;
    for (size_t r = 0; r < t->rows.size(); ++r) {
      Observation o;
      auto mid = t->Integer(r, id_column);
      if (!mid.ok()) return mid.status();
      o.marker_id = *mid;
      auto u = t->NumberIn(r, "u_" + id, plausible::kPixelCoordinatePx);
      if (!u.ok()) return u.status();
      auto vv = t->NumberIn(r, "v_" + id, plausible::kPixelCoordinatePx);
      if (!vv.ok()) return vv.status();
      o.uv_px = Eigen::Vector2d(*u, *vv);
      v.observations.push_back(o);
    }
    views->push_back(std::move(v));
  }
  return Status::Ok();
}

// view, <marker_column>, u_px, v_px[, cov_uu, cov_uv, cov_vv] (io/pixel_csv.h).
Status ReadLongObservations(const std::string& path,
                            const std::string& marker_column,
                            std::vector<PoseView>* views) {
  PixelCsvColumns columns;
  columns.key = marker_column;
  auto rows = ReadPixelCsv(path, columns);
  if (!rows.ok()) return rows.status();
  std::map<std::string, size_t> index;
  for (const PixelCsvRow& row : *rows) {
    if (!index.count(row.view)) {
      index[row.view] = views->size();
      views->push_back({row.view, {}});
    }
    PoseView& ov = (*views)[index[row.view]];
    for (const Observation& o : ov.observations) {
      if (o.marker_id == row.id) {
        return Status::Error(row.where + ": marker " + std::to_string(row.id) + " twice in view '" +
                             row.view + "'");
      }
    }
    Observation o;
    o.marker_id = row.id;
    o.uv_px = row.uv_px;
    o.covariance_px2 = row.covariance_px2;
    ov.observations.push_back(o);
  }
  return Status::Ok();
}

// The observations file's views, those `views` names in its order.
Status ReadObjectObservations(const ObjectViewsKey& k, const std::string& base, Problem* p) {
  const std::string path = JoinPath(base, k.observations);
  std::vector<PoseView> all;
  CARMBA_RETURN_IF_ERROR(k.format == "wide" ? ReadWideObservations(path, k.marker_column, &all)
                                            : ReadLongObservations(path, k.marker_column, &all));
  if (k.views.empty()) {
    p->object_views = std::move(all);
  } else {
    for (const auto& id : k.views) {
      auto it = std::find_if(all.begin(), all.end(), [&](const PoseView& v) { return v.id == id; });
      if (it == all.end()) {
        return Status::Error(p->path + ": view '" + id + "' has no observations in " + path);
      }
      p->object_views.push_back(*it);
    }
  }
  if (p->object_views.empty()) return Status::Error(path + ": no object views");
  return Status::Ok();
}

Status ReadFiducials(const FiducialsKey& key, const std::string& base, Problem* p) {
  auto markers = ReadMarkersCsv(
      JoinPath(base, key.file), key.id_column, key.columns, key.sigma_mm, key.sigma_key);
  if (!markers.ok()) return markers.status();
  p->fiducials = std::move(*markers);
  return Status::Ok();
}

Status DetectObjectViews(const ObjectViewsKey& in, const std::string& base, Problem* p) {
  if (!p->camera) {
    return Status::Error(p->path +
                         ": object_views.images needs the camera (camera.json) to label "
                         "the markers");
  }
  auto files = ListImageFiles(JoinPath(base, in.images));
  if (!files.ok()) return files.status().WithContext(p->path + ": object_views.images");
  auto views = DetectAndLabelObjectViews(*files, *p->camera, p->fiducials, in.options);
  if (!views.ok()) return views.status();
  p->marker_diameter_mm = in.options.blobs.diameter_mm;
  std::vector<double> all;
  for (PoseView& pv : ToPoseViews(*views, in.options.sigma_floor_px)) {
    for (const Observation& o : pv.observations) all.push_back(o.sigma_px);
    p->object_views.push_back(std::move(pv));
  }
  for (const ObjectView& v : *views) {
    if (!v.labelled) p->skipped_object_views.push_back(v.name + ": " + v.skipped);
  }
  std::nth_element(all.begin(), all.begin() + all.size() / 2, all.end());
  p->object_sigma_px = all[all.size() / 2];
  return Status::Ok();
}

// ---- Intrinsics groups and C-arm angles ------------------------------------------------------

Status ReadGroups(const std::string& path, Problem* p) {
  auto t = ReadCsv(path);
  if (!t.ok()) return t.status();
  auto vc = t->Column("view");
  if (!vc.ok()) return vc.status();
  auto gc = t->Column("group");
  if (!gc.ok()) return gc.status();
  for (size_t r = 0; r < t->rows.size(); ++r) {
    const std::string view = t->rows[r][*vc], group = t->rows[r][*gc];
    const std::string where = path + ":" + std::to_string(t->line_numbers[r]);
    if (view.empty() || group.empty()) {
      return Status::Error(where + ": expected a view and a group");
    }
    auto it = p->group_of_view.find(view);
    if (it != p->group_of_view.end() && it->second != group) {
      return Status::Error(where + ": view '" + view + "' is in two groups ('" + it->second +
                           "' and '" + group + "')");
    }
    p->group_of_view[view] = group;
  }
  return Status::Ok();
}

constexpr PlausibleRange kSmoothOrder{0, 4, ""};
constexpr PlausibleRange kSecondaryDeg{-90, 90, "deg"};

// angles: views.csv (view, primary_deg, secondary_deg).
Status ReadAngles(const std::string& path, Problem* p) {
  auto t = ReadCsv(path);
  if (!t.ok()) return t.status();
  auto vc = t->Column("view");
  if (!vc.ok()) return vc.status();
  for (size_t r = 0; r < t->rows.size(); ++r) {
    const std::string view = t->rows[r][*vc];
    const std::string where = path + ":" + std::to_string(t->line_numbers[r]);
    if (view.empty()) return Status::Error(where + ": column 'view': expected a view id");
    auto a = t->NumberIn(r, "primary_deg", plausible::kAngleDeg);
    if (!a.ok()) return a.status();
    auto b = t->NumberIn(r, "secondary_deg", kSecondaryDeg);
    if (!b.ok()) return b.status();
    if (p->angles.count(view)) {
      return Status::Error(where + ": view '" + view + "' is given twice");
    }
    p->angles[view] = {*a, *b};
    p->angles_from[view] = where;
  }
  return Status::Ok();
}

// Plate views read from DICOM images: their positioner angles.
Status ReadDicomAngles(Problem* p) {
  for (size_t v = 0; v < p->plate.views.size(); ++v) {
    const std::string& file = p->plate.views[v].image;
    if (file.empty() || !IsDicomFileName(file) || !std::filesystem::is_regular_file(file)) {
      continue;
    }
    auto img = ReadDicomXray(file);
    if (!img.ok()) return img.status();
    if (img->geometry.empty()) continue;
    const auto& g = img->geometry[0];
    if (!g.primary_angle_deg || !g.secondary_angle_deg) continue;
    const std::string& id = p->plate_view_ids[v];
    if (p->angles.count(id)) {
      return Status::Error(p->angles_from[id] + ": view '" + id +
                           "' has angles in its DICOM tags (" + file + "); give them once");
    }
    p->angles[id] = {*g.primary_angle_deg, *g.secondary_angle_deg};
    p->angles_from[id] = "DICOM " + file;
  }
  return Status::Ok();
}

// Every view an angle source names is a view of the problem; a plate view may be named by its
// number in views.csv.
Status ResolveAngleViews(Problem* p) {
  std::set<std::string> known(p->plate_view_ids.begin(), p->plate_view_ids.end());
  for (size_t v = 0; v < p->plate_view_ids.size(); ++v) known.insert(std::to_string(v));
  for (const auto& v : p->object_views) known.insert(v.id);
  for (const auto& [id, from] : p->angles_from) {
    if (!known.count(id)) {
      return Status::Error(from + ": view '" + id + "' is not a view of the problem");
    }
  }
  for (size_t v = 0; v < p->plate_view_ids.size(); ++v) {
    auto it = p->angles.find(std::to_string(v));
    if (!p->angles.count(p->plate_view_ids[v]) && it != p->angles.end()) {
      p->angles[p->plate_view_ids[v]] = it->second;
      p->angles_from[p->plate_view_ids[v]] = p->angles_from[it->first];
    }
  }
  return Status::Ok();
}

// The first view without C-arm angles ("plate view 'x'"), or "" when every view has them.
std::string FirstViewWithoutAngles(const Problem& p) {
  for (const auto& id : p.plate_view_ids) {
    if (!p.angles.count(id)) return "plate view '" + id + "'";
  }
  for (const auto& v : p.object_views) {
    if (!p.angles.count(v.id)) return "object view '" + v.id + "'";
  }
  return "";
}

// model: per_group without a groups file: one group per plate orientation; an object view joins
// the nearest.
void GroupsByOrientation(Problem* p) {
  std::vector<std::pair<double, double>> orientations;
  for (const auto& id : p->plate_view_ids) {
    const auto a = p->angles.at(id);
    if (std::find(orientations.begin(), orientations.end(), a) == orientations.end()) {
      orientations.push_back(a);
    }
  }
  auto nearest = [&](const std::pair<double, double>& a) {
    size_t best = 0;
    for (size_t k = 1; k < orientations.size(); ++k) {
      if (std::hypot(orientations[k].first - a.first, orientations[k].second - a.second) <
          std::hypot(orientations[best].first - a.first, orientations[best].second - a.second)) {
        best = k;
      }
    }
    return OrientationName(orientations[best].first, orientations[best].second);
  };
  for (const auto& id : p->plate_view_ids) p->group_of_view[id] = nearest(p->angles.at(id));
  for (const auto& v : p->object_views) p->group_of_view[v.id] = nearest(p->angles.at(v.id));
}

// model: per_group with a groups file: every view has a group (a plate view by id or number).
Status GroupsFromFile(const std::string& path, Problem* p) {
  CARMBA_RETURN_IF_ERROR(ReadGroups(path, p));
  auto check = [&](const std::string& id, const std::string& number) -> Status {
    if (p->group_of_view.count(id) || (!number.empty() && p->group_of_view.count(number))) {
      return Status::Ok();
    }
    return Status::Error(path + ": view '" + id + "' has no group");
  };
  for (size_t v = 0; v < p->plate_view_ids.size(); ++v) {
    CARMBA_RETURN_IF_ERROR(check(p->plate_view_ids[v], std::to_string(v)));
  }
  for (const auto& v : p->object_views) CARMBA_RETURN_IF_ERROR(check(v.id, ""));
  return Status::Ok();
}

// The `intrinsics` keys, read before any file.
struct IntrinsicsKey {
  std::string model = "shared", groups_file;
  bool has_select = false, has_smooth_keys = false;
};

void ReadIntrinsicsKey(YamlMap& root, Problem* p, IntrinsicsKey* k) {
  YamlMap& intr = root.Map("intrinsics");
  intr.GetEnum("model", {"shared", "per_group", "smooth"}, &k->model);
  intr.Get("groups", &k->groups_file);
  intr.Get("prior", &p->camera_prior);
  intr.GetInRange("primary_order", &p->smooth_basis.primary_order, kSmoothOrder);
  intr.GetInRange("secondary_degree", &p->smooth_basis.secondary_degree, kSmoothOrder);
  p->secondary_degree_given = intr.Has("secondary_degree");
  k->has_smooth_keys = intr.Has("primary_order") || intr.Has("secondary_degree");
  k->has_select = intr.Has("select");
  intr.Get("select", &p->select_model);
}

// The intrinsics model with its angle requirements, the model selection's default, the groups.
Status ApplyIntrinsicsKey(const std::string& base, const IntrinsicsKey& k, Problem* p) {
  const std::string& yaml_path = p->path;
  if (k.model != "smooth" && k.has_smooth_keys) {
    return Status::Error(yaml_path +
                         ": intrinsics.primary_order / secondary_degree are only for "
                         "model: smooth");
  }
  const std::string first_without = FirstViewWithoutAngles(*p);
  const bool all_angles = first_without.empty();
  p->smooth = k.model == "smooth";
  if ((p->smooth || (k.model == "per_group" && k.groups_file.empty())) && !all_angles) {
    return Status::Error(yaml_path + ": " + first_without + " has no C-arm angles; intrinsics " +
                         "model " + k.model + (p->smooth ? "" : " without groups") +
                         " needs them (DICOM positioner angles, or angles: views.csv)");
  }
  if (k.has_select && p->select_model && !all_angles) {
    return Status::Error(yaml_path + ": intrinsics.select: " + first_without +
                         " has no C-arm angles; the model selection needs them for every view");
  }
  if (!k.has_select) p->select_model = all_angles;
  p->per_group = k.model == "per_group";
  if (p->per_group && k.groups_file.empty()) {
    GroupsByOrientation(p);
  } else if (p->per_group) {
    CARMBA_RETURN_IF_ERROR(GroupsFromFile(JoinPath(base, k.groups_file), p));
  } else if (!k.groups_file.empty()) {
    return Status::Error(yaml_path + ": intrinsics.groups is only for model: per_group");
  }
  return Status::Ok();
}

// ---- Validation pairs, references, truth -----------------------------------------------------

void ReadValidationPairs(YamlMap& root, std::vector<ValidationPair>* out) {
  for (YamlMap* pm : root.MapList("validation")) {
    ValidationPair vp;
    YAML::Node a = pm->Raw("a"), b = pm->Raw("b");
    if (!a.IsScalar() || !b.IsScalar()) {
      pm->Fail("a", "expected view ids a and b");
    } else {
      vp.a = a.Scalar();
      vp.b = b.Scalar();
    }
    double e = NAN;
    pm->GetInRange("expected_deg", &e, plausible::kAngleDeg);
    if (std::isfinite(e)) vp.expected_deg = e;
    out->push_back(vp);
  }
}

// `reference`: the legacy POSIT camera (read here) and the files of reference rotations and
// angles (their names into `files`, read by ReadReferenceFiles).
void ReadReferenceKey(YamlMap& m, Problem* p, std::pair<std::string, std::string>* files) {
  if (m.Has("legacy_posit")) {
    YamlMap& l = m.Map("legacy_posit");
    LegacyPositReference r;
    l.GetInRange("focal_px", &r.focal_px, plausible::kFocalPx, true);
    l.GetInRange("cx_px", &r.cx_px, plausible::kPixelCoordinatePx, true);
    l.GetInRange("cy_px", &r.cy_px, plausible::kPixelCoordinatePx, true);
    l.Get("y_up", &r.y_up);
    p->legacy_reference = r;
  } else {
    m.Map("legacy_posit");
  }
  m.Get("rotations", &files->first);
  m.Get("validation", &files->second);
}

Status ReadReferenceRotations(const std::string& path, Problem* p) {
  auto t = ReadCsv(path);
  if (!t.ok()) return t.status();
  const char* names[9] = {"r11", "r12", "r13", "r21", "r22", "r23", "r31", "r32", "r33"};
  for (size_t r = 0; r < t->rows.size(); ++r) {
    Eigen::Matrix3d R;
    for (int k = 0; k < 9; ++k) {
      auto v = t->Number(r, names[k]);
      if (!v.ok()) return v.status();
      R(k / 3, k % 3) = *v;
    }
    auto c = t->Column("orientation_deg");
    if (!c.ok()) return c.status();
    p->reference_rotations[t->rows[r][*c]] = R;
  }
  return Status::Ok();
}

Status ReadReferenceAngles(const std::string& path, Problem* p) {
  auto t = ReadCsv(path);
  if (!t.ok()) return t.status();
  for (size_t r = 0; r < t->rows.size(); ++r) {
    auto a = t->Column("orientation_a_deg");
    auto b = t->Column("orientation_b_deg");
    if (!a.ok()) return a.status();
    if (!b.ok()) return b.status();
    auto v = t->Number(r, "achieved_deg");
    if (!v.ok()) return v.status();
    p->reference_angles_deg[{t->rows[r][*a], t->rows[r][*b]}] = *v;
  }
  return Status::Ok();
}

std::string FormatId(double v) {
  if (v == std::floor(v)) return std::to_string(static_cast<long long>(v));
  return std::to_string(v);
}

// One view's cam_from_object: {"id", "rvec", "t_mm"} or {"id", "cam_from_object": {...}}; the id
// a string or a number.
void ReadTruthPose(const nlohmann::json& v, ProblemTruth* truth) {
  Pose6 pose;
  const auto& cfo = v.contains("cam_from_object") ? v.at("cam_from_object") : v;
  for (int k = 0; k < 3; ++k) pose[k] = cfo.at("rvec").at(k).get<double>();
  for (int k = 0; k < 3; ++k) pose[3 + k] = cfo.at("t_mm").at(k).get<double>();
  const std::string id =
      v.at("id").is_string() ? v.at("id").get<std::string>() : FormatId(v.at("id").get<double>());
  truth->object_poses[id] = pose;
}

// The simulator's truth: the camera, per-view intrinsics of a flexing C-arm, the object poses
// ("object_views", or a pose scene's "views"); or a camera.json, the true camera alone.
Status ReadTruth(const std::string& path, ProblemTruth* truth) {
  auto text = ReadFile(path);
  if (!text.ok()) return text.status();
  const char* expected =
      ": expected {\"camera\": {...}, \"object_views\" (or \"views\"): "
      "[{\"id\", \"rvec\", \"t_mm\"}]}";
  try {
    const nlohmann::json j = nlohmann::json::parse(*text);
    if (!j.contains("camera") && !j.contains("object_views") && !j.contains("views")) {
      // A camera.json (`carmba calibrate` output) is the true camera alone.
      auto cam = CameraFromJson(j, path);
      if (!cam.ok()) return Status::Error(path + expected + " or a camera.json");
      truth->camera = *cam;
      return Status::Ok();
    }
    if (j.contains("camera")) {
      auto cam = CameraFromJson(j.at("camera"), path + ": camera");
      if (!cam.ok()) return cam.status();
      truth->camera = *cam;
    }
    if (j.contains("view_intrinsics")) {
      for (const auto& v : j.at("view_intrinsics")) {
        auto cam = CameraFromJson(v.at("camera"), path + ": view_intrinsics");
        if (!cam.ok()) return cam.status();
        truth->view_intrinsics[v.at("id").get<std::string>()] = cam->params;
      }
    }
    for (const char* list : {"object_views", "views"}) {
      if (!j.contains(list)) continue;
      for (const auto& v : j.at(list)) {
        if (v.contains("cam_from_plate")) continue;  // a plate scene's view: no object pose
        ReadTruthPose(v, truth);
      }
    }
  } catch (const std::exception& e) {
    return Status::Error(path + expected + ": " + e.what());
  }
  return Status::Ok();
}

// ---- The problem -----------------------------------------------------------------------------

// Every key of the file, read before any file it names (so that an unknown key is reported
// first).
struct ProblemKeys {
  std::string camera_file, truth_file, angles_file, handedness = "as_given";
  bool has_plate = false, has_object = false;
  PlateViewsSource plate;
  IntrinsicsKey intrinsics;
  FiducialsKey fiducials;
  ObjectViewsKey object;
  std::pair<std::string, std::string> reference_files;
};

Status ReadKeys(YamlMap& root, const std::string& base, Problem* p, ProblemKeys* k) {
  root.Get("name", &p->name, true);
  root.Get("description", &p->description);
  root.Get("camera", &k->camera_file);
  root.Get("truth", &k->truth_file);
  root.GetEnum("handedness", {"as_given", "mirrored"}, &k->handedness);
  ReadIntrinsicsKey(root, p, &k->intrinsics);
  root.Get("angles", &k->angles_file);
  if (HasOlderCalibrationKeys(root)) {
    ReadOlderCalibrationKeys(root, base, &k->plate);
  } else if (root.Has("config")) {
    root.Raw("config");
    root.Fail("config", "a problem does not name its config: give --config to the command");
  }
  ReadValidationPairs(root, &p->validation);
  ReadReferenceKey(root.Map("reference"), p, &k->reference_files);
  const bool older = !k->plate.older && HasOlderPoseKeys(root);
  k->has_plate = k->plate.older || root.Has("plate_views");
  k->has_object = older || root.Has("object_views");
  if (!k->has_plate && !k->has_object) {
    root.Fail("plate_views", "give plate_views, object_views or both");
  }
  if (older) {
    ReadOlderPoseKeys(root, p, &k->fiducials, &k->object);
  } else {
    if (k->has_object) ReadObjectViewsKey(root.Map("object_views"), p, &k->object);
    ReadFiducialsKey(root, k->has_object, &k->fiducials);
  }
  p->handedness = k->handedness == "mirrored" ? Handedness::kMirrored : Handedness::kAsGiven;
  return root.status();
}

// The files the keys name: views, fiducials, camera, references; the detection of object views
// in images last (it needs the camera and the fiducials).
Status ReadFiles(YamlMap& root,
                 const std::string& base,
                 const ProblemKeys& k,
                 const ProblemReadOptions& options,
                 Problem* p) {
  if (k.has_plate) {
    YamlMap& m = k.plate.older ? root : root.Map("plate_views");
    CARMBA_RETURN_IF_ERROR(ReadPlateViews(m, base, k.plate, options, p));
    p->older_config_file = k.plate.older_config;
  }
  if (k.has_object) {
    CARMBA_RETURN_IF_ERROR(k.fiducials.status);
    CARMBA_RETURN_IF_ERROR(k.object.status);
    if (!k.object.observations.empty()) {
      CARMBA_RETURN_IF_ERROR(ReadObjectObservations(k.object, base, p));
    }
    CARMBA_RETURN_IF_ERROR(ReadFiducials(k.fiducials, base, p));
  }
  CARMBA_RETURN_IF_ERROR(root.Finish());
  if (!k.camera_file.empty()) {
    auto cam = ReadCameraJson(JoinPath(base, k.camera_file));
    if (!cam.ok()) return cam.status();
    p->camera = *cam;
  }
  if (!k.reference_files.first.empty()) {
    CARMBA_RETURN_IF_ERROR(ReadReferenceRotations(JoinPath(base, k.reference_files.first), p));
  }
  if (!k.reference_files.second.empty()) {
    CARMBA_RETURN_IF_ERROR(ReadReferenceAngles(JoinPath(base, k.reference_files.second), p));
  }
  if (!k.object.images.empty()) CARMBA_RETURN_IF_ERROR(DetectObjectViews(k.object, base, p));
  return Status::Ok();
}

// What the camera must be for the problem's kind.
Status CheckCamera(const Problem& p) {
  if (p.camera_prior && (!p.camera || p.camera->covariance.empty())) {
    return Status::Error(p.path + ": intrinsics.prior: true needs a camera with a covariance");
  }
  if (p.plate.views.empty() && !p.camera) {
    return Status::Error(p.path +
                         ": camera: a problem without plate views needs the camera "
                         "(camera.json) for its intrinsics");
  }
  return Status::Ok();
}

}  // namespace

Eigen::Vector3d MarkerInProblemFrame(const Problem& problem, const Marker& m) {
  Eigen::Vector3d p = m.p_in_object;
  if (problem.handedness == Handedness::kMirrored) p.y() = -p.y();
  return p;
}

Eigen::Matrix3d MarkerCovarianceInProblemFrame(const Problem& problem, const Marker& m) {
  if (problem.handedness == Handedness::kAsGiven) return m.covariance;
  const Eigen::Matrix3d F = Eigen::Vector3d(1, -1, 1).asDiagonal();
  return F * m.covariance * F;
}

Status Problem::Check() const {
  std::string e;
  if (IsPoseProblem() &&
      !CheckRange("key 'object_views.sigma_px'", object_sigma_px, plausible::kPixelSigmaPx, &e)) {
    return Status::Error(path + ": " + e);
  }
  for (const auto& m : fiducials) {
    for (int c = 0; c < 3; ++c) {
      if (!CheckRange("marker " + std::to_string(m.id) + ": coordinate " + "xyz"[c],
                      m.p_in_object[c],
                      plausible::kCoordinateMm,
                      &e)) {
        return Status::Error(path + ": " + e);
      }
    }
  }
  std::set<int> ids;
  for (const auto& m : fiducials) ids.insert(m.id);
  std::set<std::string> vids;
  for (const auto& v : object_views) {
    if (!vids.insert(v.id).second) return Status::Error(path + ": view '" + v.id + "' twice");
    std::set<int> seen;
    for (const auto& o : v.observations) {
      const std::string what =
          "object view '" + v.id + "' observes marker " + std::to_string(o.marker_id);
      if (!ids.count(o.marker_id)) {
        return Status::Error(path + ": " + what + ", which is not among the fiducials");
      }
      if (!seen.insert(o.marker_id).second) return Status::Error(path + ": " + what + " twice");
      for (int c = 0; c < 2; ++c) {
        if (!CheckRange("view '" + v.id + "': marker " + std::to_string(o.marker_id) + ": " +
                            (c == 0 ? "u" : "v"),
                        o.uv_px[c],
                        plausible::kPixelCoordinatePx,
                        &e)) {
          return Status::Error(path + ": " + e);
        }
      }
    }
    if (v.observations.size() < 4) {
      return Status::Error(path + ": object view '" + v.id + "' has " +
                           std::to_string(v.observations.size()) +
                           " observed markers; a pose needs at least 4");
    }
  }
  for (const auto& pr : validation) {
    if (!vids.count(pr.a) || !vids.count(pr.b)) {
      return Status::Error(path + ": validation pair " + pr.a + "-" + pr.b +
                           " names a view that is not an object view");
    }
  }
  return Status::Ok();
}

StatusOr<Problem> LoadProblem(const std::string& yaml_path, const ProblemReadOptions& options) {
  YamlMap root = YamlMap::Load(yaml_path);
  if (!root.status().ok()) return root.status();
  Problem p;
  p.path = yaml_path;
  const std::string base = DirName(yaml_path);
  ProblemKeys keys;
  CARMBA_RETURN_IF_ERROR(ReadKeys(root, base, &p, &keys));
  CARMBA_RETURN_IF_ERROR(ReadFiles(root, base, keys, options, &p));
  CARMBA_RETURN_IF_ERROR(CheckCamera(p));
  // C-arm angles: views.csv, then the DICOM plate images.
  if (!keys.angles_file.empty()) {
    CARMBA_RETURN_IF_ERROR(ReadAngles(JoinPath(base, keys.angles_file), &p));
  }
  CARMBA_RETURN_IF_ERROR(ReadDicomAngles(&p));
  CARMBA_RETURN_IF_ERROR(ResolveAngleViews(&p));
  CARMBA_RETURN_IF_ERROR(ApplyIntrinsicsKey(base, keys.intrinsics, &p));
  CARMBA_RETURN_IF_ERROR(p.Check());
  if (!keys.truth_file.empty()) {
    CARMBA_RETURN_IF_ERROR(ReadTruth(JoinPath(base, keys.truth_file), &p.truth));
  }
  return p;
}

}  // namespace carmba
