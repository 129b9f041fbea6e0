// Reading joint problem files (format in joint_problem.h).
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <set>

#include "analysis/flex_models.h"
#include "detect/grid_detector.h"
#include "io/dicom_xray.h"
#include "joint/joint_problem.h"
#include "problem/pixel_csv.h"

#include "detect/marker_views.h"
#include "util/csv.h"
#include "util/file_util.h"
#include "util/plausible.h"
#include "util/yaml_reader.h"

namespace carmba {
namespace {

std::string Stem(const std::string& path) { return std::filesystem::path(path).stem().string(); }

Status ReadPlateViews(YamlMap& m, const std::string& base, JointProblem* p) {
  std::string observations, images, pattern = "circles";
  GridSpec grid;
  bool has_grid = m.Has("rows") || m.Has("cols") || m.Has("spacing_mm") || m.Has("pattern");
  m.Get("observations", &observations);
  m.Get("images", &images);
  m.GetEnum("pattern", {"circles", "acircles", "chessboard"}, &pattern);
  m.Get("rows", &grid.rows);
  m.Get("cols", &grid.cols);
  m.GetInRange("spacing_mm", &grid.spacing_mm, plausible::kGridSpacingMm);
  m.GetInRange("sigma_px", &p->plate_sigma_px, plausible::kPixelSigmaPx, true);
  YamlMap& plate = m.Map("plate");
  plate.Get("free", &p->plate_free);
  if (plate.Has("sigma_mm")) plate.GetInRange("sigma_mm", &p->plate_sigma_mm, plausible::kToleranceMm);
  if (!m.status().ok()) return m.status();
  if (observations.empty() == images.empty()) {
    m.Fail("observations", "give exactly one of observations (CSV) and images (DIR or GLOB)");
    return m.status();
  }
  auto pat = ParseGridPattern(pattern);
  if (!pat.ok()) return pat.status();
  grid.pattern = *pat;
  std::string err;
  if (has_grid && !grid.Check(&err)) {
    m.Fail("rows", err);
    return m.status();
  }
  if (!observations.empty()) {
    const std::string path = JoinPath(base, observations);
    auto obs = ReadObservationsCsv(path);
    if (!obs.ok()) return obs.status();
    if (has_grid && (obs->grid.pattern != grid.pattern || obs->grid.rows != grid.rows ||
                     obs->grid.cols != grid.cols ||
                     std::abs(obs->grid.spacing_mm - grid.spacing_mm) > 1e-9)) {
      return Status::Error(path + ": grid " + GridPatternName(obs->grid.pattern) + " " +
                           std::to_string(obs->grid.rows) + "x" + std::to_string(obs->grid.cols) +
                           " spacing " + std::to_string(obs->grid.spacing_mm) + " mm, but " +
                           m.KeyPath("rows") + "/cols/spacing_mm say " + pattern + " " +
                           std::to_string(grid.rows) + "x" + std::to_string(grid.cols) +
                           " spacing " + std::to_string(grid.spacing_mm) + " mm");
    }
    p->plate = *obs;
  } else {
    if (!has_grid) {
      m.Fail("rows", "plate images need the grid: pattern, rows, cols, spacing_mm");
      return m.status();
    }
    auto files = ListImageFiles(JoinPath(base, images));
    if (!files.ok()) return files.status().WithContext(m.KeyPath("images"));
    auto obs = DetectGridInFiles(*files, grid, DetectionOptions(), &p->skipped_images);
    if (!obs.ok()) return obs.status();
    p->plate = *obs;
  }
  std::set<std::string> ids;
  for (size_t v = 0; v < p->plate.views.size(); ++v) {
    std::string id = Stem(p->plate.views[v].image);
    if (id.empty() || !ids.insert(id).second) id = std::to_string(v);
    ids.insert(id);
    p->plate_view_ids.push_back(id);
  }
  if (p->plate.views.empty() && !images.empty()) {
    // Detection found the grid nowhere: most often rows / cols / pattern do not match the plate.
    return Status::Error(
        m.file() + ": " + m.KeyPath("images") + ": the grid (" + pattern + " " +
        std::to_string(grid.rows) + " x " + std::to_string(grid.cols) + ", keys " +
        m.KeyPath("pattern") + "/rows/cols) was found in none of the " +
        std::to_string(p->skipped_images.size()) + " images: check rows and cols" +
        (p->skipped_images.empty() ? "" : "; first: " + p->skipped_images.front()));
  }
  if (p->plate.views.empty()) {
    return Status::Error(m.file() + ": " + m.KeyPath("observations") + ": no plate views in " +
                         observations);
  }
  return Status::Ok();
}

// object_views: {images, detection}: the options read here, the views detected and labelled once
// the camera and the fiducials are read (DetectObjectViews).
struct ObjectImages {
  std::string images;
  ObjectViewsOptions options;
};

Status ReadObjectViews(YamlMap& m, const std::string& base, JointProblem* p, ObjectImages* from_images) {
  std::string observations, marker_column = "marker";
  if (m.Has("images")) {
    m.Get("images", &from_images->images, true);
    if (m.Has("observations")) m.Fail("observations", "give observations or images, not both");
    YamlMap& d = m.Map("detection", true);
    ReadObjectViewsOptions(d, &from_images->options);
    double unused = 0;
    m.GetInRange("sigma_px", &unused, plausible::kPixelSigmaPx);
    return m.status();
  }
  m.Get("observations", &observations, true);
  m.Get("marker_column", &marker_column);
  m.GetInRange("sigma_px", &p->object_sigma_px, plausible::kPixelSigmaPx, true);
  if (!m.status().ok()) return m.status();
  const std::string path = JoinPath(base, observations);
  PixelCsvColumns columns;
  columns.key = marker_column;
  auto rows = ReadPixelCsv(path, columns);
  if (!rows.ok()) return rows.status();
  std::map<std::string, size_t> index;
  for (const PixelCsvRow& row : *rows) {
    if (!index.count(row.view)) {
      index[row.view] = p->object_views.size();
      p->object_views.push_back({row.view, {}});
    }
    PoseView& ov = p->object_views[index[row.view]];
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
  if (p->object_views.empty()) return Status::Error(path + ": no object views");
  return Status::Ok();
}

Status ReadGroups(const std::string& path, JointProblem* p) {
  auto t = ReadCsv(path);
  if (!t.ok()) return t.status();
  auto vc = t->Column("view");
  if (!vc.ok()) return vc.status();
  auto gc = t->Column("group");
  if (!gc.ok()) return gc.status();
  for (size_t r = 0; r < t->rows.size(); ++r) {
    const std::string view = t->rows[r][*vc], group = t->rows[r][*gc];
    const std::string where = path + ":" + std::to_string(t->line_numbers[r]);
    if (view.empty() || group.empty()) return Status::Error(where + ": expected a view and a group");
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
Status ReadAngles(const std::string& path, JointProblem* p) {
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
    if (p->angles.count(view)) return Status::Error(where + ": view '" + view + "' is given twice");
    p->angles[view] = {*a, *b};
    p->angles_from[view] = where;
  }
  return Status::Ok();
}

// Plate views read from DICOM images: their positioner angles.
Status ReadDicomAngles(JointProblem* p) {
  for (size_t v = 0; v < p->plate.views.size(); ++v) {
    const std::string& file = p->plate.views[v].image;
    if (file.empty() || !IsDicomFileName(file) || !std::filesystem::is_regular_file(file)) continue;
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

Status ReadJointTruth(const std::string& path, JointTruth* truth) {
  auto text = ReadFile(path);
  if (!text.ok()) return text.status();
  try {
    const nlohmann::json j = nlohmann::json::parse(*text);
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
    if (j.contains("object_views")) {
      for (const auto& v : j.at("object_views")) {
        Pose6 pose;
        for (int k = 0; k < 3; ++k) pose[k] = v.at("rvec").at(k).get<double>();
        for (int k = 0; k < 3; ++k) pose[3 + k] = v.at("t_mm").at(k).get<double>();
        truth->object_poses[v.at("id").get<std::string>()] = pose;
      }
    }
  } catch (const std::exception& e) {
    return Status::Error(path + ": expected {\"camera\": {...}, \"object_views\": [{\"id\", "
                         "\"rvec\", \"t_mm\"}]}: " + e.what());
  }
  return Status::Ok();
}

}  // namespace

bool IsJointProblemFile(const std::string& yaml_path) {
  // yaml-cpp 0.7 leaks its 2 kB stream buffer when LoadFile fails on a directory (LeakSanitizer
  // in BadInput.DirectoryAsProblemOrConfig); the loader that follows reports the directory.
  if (IsDirectory(yaml_path)) return false;
  try {
    const YAML::Node n = YAML::LoadFile(yaml_path);
    return n.IsMap() && (n["plate_views"] || n["object_views"]);
  } catch (const std::exception&) {
    return false;
  }
}

Status DetectObjectViews(const ObjectImages& in, const std::string& base, const std::string& where,
                         JointProblem* p) {
  if (!p->camera) {
    return Status::Error(where + ": object_views.images needs the camera (camera.json) to label "
                                 "the markers");
  }
  auto files = ListImageFiles(JoinPath(base, in.images));
  if (!files.ok()) return files.status().WithContext(where + ": object_views.images");
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

namespace {

// The `fiducials` key: a CSV path, or {file, id_column, columns, sigma_mm}.
struct FiducialsKey {
  std::string file, id_column = "id", sigma_key;
  std::vector<std::string> columns = {"x_mm", "y_mm", "z_mm"};
  double sigma_mm = -1;
};

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
    YamlMap& m = root.Map("fiducials");
    m.Get("file", &f->file, true);
    m.Get("id_column", &f->id_column);
    m.Get("columns", &f->columns);
    m.GetInRange("sigma_mm", &f->sigma_mm, plausible::kCtSigmaMm);
    if (f->columns.size() != 3) m.Fail("columns", "expected three column names (x, y, z)");
  }
}

// The fiducials, and every object view's markers among them (at least 4 per view).
Status ReadFiducials(const FiducialsKey& key, const std::string& base, const std::string& observations_key,
                     const std::string& yaml_path, JointProblem* p) {
  auto markers = ReadMarkersCsv(JoinPath(base, key.file), key.id_column, key.columns, key.sigma_mm, key.sigma_key);
  if (!markers.ok()) return markers.status();
  p->fiducials = *markers;
  std::set<int> ids;
  for (const auto& m : p->fiducials) ids.insert(m.id);
  for (const auto& v : p->object_views) {
    for (const Observation& o : v.observations) {
      if (!ids.count(o.marker_id)) {
        return Status::Error(JoinPath(base, observations_key) + ": view '" + v.id +
                             "' observes marker " + std::to_string(o.marker_id) +
                             ", which is not in the fiducials " + JoinPath(base, key.file));
      }
    }
    if (v.observations.size() < 4) {
      return Status::Error(yaml_path + ": object view '" + v.id + "' has " +
                           std::to_string(v.observations.size()) + " markers; a pose needs at least 4");
    }
  }
  return Status::Ok();
}

// Every view an angle source names is a view of the problem; a plate view may be named by its
// number in views.csv.
Status ResolveAngleViews(JointProblem* p) {
  std::set<std::string> known(p->plate_view_ids.begin(), p->plate_view_ids.end());
  for (size_t v = 0; v < p->plate_view_ids.size(); ++v) known.insert(std::to_string(v));
  for (const auto& v : p->object_views) known.insert(v.id);
  for (const auto& [id, from] : p->angles_from) {
    if (!known.count(id)) return Status::Error(from + ": view '" + id + "' is not a view of the problem");
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
std::string FirstViewWithoutAngles(const JointProblem& p) {
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
void GroupsByOrientation(JointProblem* p) {
  std::vector<std::pair<double, double>> orientations;
  for (const auto& id : p->plate_view_ids) {
    const auto a = p->angles.at(id);
    if (std::find(orientations.begin(), orientations.end(), a) == orientations.end()) orientations.push_back(a);
  }
  auto nearest = [&](const std::pair<double, double>& a) {
    size_t best = 0;
    for (size_t k = 1; k < orientations.size(); ++k) {
      if (std::hypot(orientations[k].first - a.first, orientations[k].second - a.second) <
          std::hypot(orientations[best].first - a.first, orientations[best].second - a.second)) {
        best = k;
      }
    }
    return analysis::OrientationName(orientations[best].first, orientations[best].second);
  };
  for (const auto& id : p->plate_view_ids) p->group_of_view[id] = nearest(p->angles.at(id));
  for (const auto& v : p->object_views) p->group_of_view[v.id] = nearest(p->angles.at(v.id));
}

// model: per_group with a groups file: every view has a group (a plate view by id or number).
Status GroupsFromFile(const std::string& path, JointProblem* p) {
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

// The intrinsics model with its angle requirements, the model selection's default, the groups.
Status ApplyIntrinsicsModelKeys(const std::string& yaml_path, const std::string& base, const std::string& model,
                                const std::string& groups_file, bool has_select, JointProblem* p) {
  const std::string first_without = FirstViewWithoutAngles(*p);
  const bool all_angles = first_without.empty();
  p->smooth = model == "smooth";
  if ((p->smooth || (model == "per_group" && groups_file.empty())) && !all_angles) {
    return Status::Error(yaml_path + ": " + first_without + " has no C-arm angles; intrinsics model " +
                         model + (p->smooth ? "" : " without groups") +
                         " needs them (DICOM positioner angles, or angles: views.csv)");
  }
  if (has_select && p->select_model && !all_angles) {
    return Status::Error(yaml_path + ": intrinsics.select: " + first_without +
                         " has no C-arm angles; the model selection needs them for every view");
  }
  if (!has_select) p->select_model = all_angles;
  p->per_group = model == "per_group";
  if (p->per_group && groups_file.empty()) {
    GroupsByOrientation(p);
  } else if (p->per_group) {
    CARMBA_RETURN_IF_ERROR(GroupsFromFile(JoinPath(base, groups_file), p));
  } else if (!groups_file.empty()) {
    return Status::Error(yaml_path + ": intrinsics.groups is only for model: per_group");
  }
  return Status::Ok();
}

}  // namespace

StatusOr<JointProblem> LoadJointProblem(const std::string& yaml_path) {
  YamlMap root = YamlMap::Load(yaml_path);
  if (!root.status().ok()) return root.status();
  JointProblem p;
  p.path = yaml_path;
  const std::string base = DirName(yaml_path);
  std::string camera_file, truth_file, model = "shared", groups_file;
  root.Get("name", &p.name, true);
  root.Get("description", &p.description);
  root.Get("camera", &camera_file);
  root.Get("truth", &truth_file);
  YamlMap& intr = root.Map("intrinsics");
  intr.GetEnum("model", {"shared", "per_group", "smooth"}, &model);
  intr.Get("groups", &groups_file);
  intr.Get("prior", &p.camera_prior);
  intr.GetInRange("primary_order", &p.smooth_basis.primary_order, kSmoothOrder);
  intr.GetInRange("secondary_degree", &p.smooth_basis.secondary_degree, kSmoothOrder);
  p.secondary_degree_given = intr.Has("secondary_degree");
  const bool has_select = intr.Has("select");
  intr.Get("select", &p.select_model);
  std::string angles_file;
  root.Get("angles", &angles_file);
  if (root.Has("config")) {
    root.Raw("config");
    root.Fail("config", "a problem does not name its config: give --config to `carmba solve`");
  }
  ReadValidationPairs(root, &p.validation);
  const bool has_plate = root.Has("plate_views"), has_object = root.Has("object_views");
  YamlMap& plate = root.Map("plate_views");
  YamlMap& object = root.Map("object_views");
  if (!has_plate && !has_object) root.Fail("plate_views", "give plate_views, object_views or both");
  FiducialsKey fiducials;
  ReadFiducialsKey(root, has_object, &fiducials);
  if (!root.status().ok()) return root.status();
  if (has_plate) CARMBA_RETURN_IF_ERROR(ReadPlateViews(plate, base, &p));
  ObjectImages object_images;
  if (has_object) {
    CARMBA_RETURN_IF_ERROR(ReadObjectViews(object, base, &p, &object_images));
    CARMBA_RETURN_IF_ERROR(ReadFiducials(fiducials, base, object.KeyPath("observations"), yaml_path, &p));
  }
  CARMBA_RETURN_IF_ERROR(root.Finish());
  if (!camera_file.empty()) {
    auto cam = ReadCameraJson(JoinPath(base, camera_file));
    if (!cam.ok()) return cam.status();
    p.camera = *cam;
  }
  if (!object_images.images.empty()) {
    CARMBA_RETURN_IF_ERROR(DetectObjectViews(object_images, base, yaml_path, &p));
  }
  if (p.camera_prior && (!p.camera || p.camera->covariance.empty())) {
    return Status::Error(yaml_path + ": intrinsics.prior: true needs a camera with a covariance");
  }
  if (!has_plate && !p.camera) {
    return Status::Error(yaml_path + ": camera: a problem without plate views needs the camera "
                                     "(camera.json) for its intrinsics");
  }
  if (model != "smooth" && (intr.Has("primary_order") || intr.Has("secondary_degree"))) {
    return Status::Error(yaml_path + ": intrinsics.primary_order / secondary_degree are only for "
                                     "model: smooth");
  }
  // C-arm angles: views.csv, then the DICOM plate images.
  if (!angles_file.empty()) CARMBA_RETURN_IF_ERROR(ReadAngles(JoinPath(base, angles_file), &p));
  CARMBA_RETURN_IF_ERROR(ReadDicomAngles(&p));
  CARMBA_RETURN_IF_ERROR(ResolveAngleViews(&p));
  CARMBA_RETURN_IF_ERROR(ApplyIntrinsicsModelKeys(yaml_path, base, model, groups_file, has_select, &p));
  std::set<std::string> object_ids;
  for (const auto& v : p.object_views) object_ids.insert(v.id);
  for (const auto& vp : p.validation) {
    if (!object_ids.count(vp.a) || !object_ids.count(vp.b)) {
      return Status::Error(yaml_path + ": validation pair " + vp.a + "-" + vp.b +
                           " names a view that is not an object view");
    }
  }
  if (!truth_file.empty()) CARMBA_RETURN_IF_ERROR(ReadJointTruth(JoinPath(base, truth_file), &p.truth));
  return p;
}

}  // namespace carmba
