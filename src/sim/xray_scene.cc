#include "sim/xray_scene.h"

#include <cmath>
#include <cstdio>
#include <set>

#include "camera/camera_model.h"
#include "geometry/rotation.h"
#include "io/dicom_xray.h"
#include "util/file_util.h"
#include "util/plausible.h"
#include "util/format.h"

namespace carmba::sim {

namespace {


uint64_t SceneSeedMix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// A fixed-size vector key; records an error when the size is wrong.
bool GetVec(YamlMap& m, const std::string& key, int n, double* out, bool required = false) {
  std::vector<double> v;
  const bool had = m.Has(key);
  m.Get(key, &v, required);
  if (!had || !m.status().ok()) return false;
  if (static_cast<int>(v.size()) != n) {
    m.Fail(key,
           "expected a list of " + std::to_string(n) + " numbers, got " + std::to_string(v.size()));
    return false;
  }
  for (int i = 0; i < n; ++i) out[i] = v[i];
  return true;
}

bool ValidSceneName(const std::string& s) {
  if (s.empty()) return false;
  for (char c : s) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-')) return false;
  }
  return true;
}

Rigid3 ObjectPlacement(const Eigen::Vector3d& centroid,
                       const Eigen::Vector3d& rotation_deg,
                       const Eigen::Vector3d& center_mm) {
  // world_from_object = T(center) * R(rotation) * T(-centroid)
  const Rigid3 rot = Rigid3::FromRvec(rotation_deg * kDegToRad, Eigen::Vector3d::Zero());
  Rigid3 p;
  p.R = rot.R;
  p.t = center_mm - rot.R * centroid;
  return p;
}

nlohmann::json Vec3Json(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

}  // namespace

uint64_t ViewSeed(uint64_t seed, int index) {
  return SceneSeedMix(seed * 0x100000001B3ull + static_cast<uint64_t>(index)) >> 11;
}

void ReseedXrayScene(uint64_t seed, XrayScene* scene) {
  scene->seed = seed;
  for (size_t i = 0; i < scene->views.size(); ++i) {
    scene->views[i].seed = ViewSeed(seed, static_cast<int>(i));
  }
}

namespace {

// The scene's sections, each read into the scene (errors recorded in the YamlMap; Finish reports
// them).
void ParseSceneOutput(YamlMap& scene, XrayScene* s) {
  YamlMap& output = scene.Map("output");
  output.GetEnum("format", {"png", "pgm", "dcm"}, &s->format);
  output.Get("bit_depth", &s->bit_depth);
  output.Get("multiframe", &s->multiframe);
  if (s->multiframe && s->format != "dcm") output.Fail("multiframe", "only with format: dcm");
  if (output.Has("bit_depth") && s->bit_depth != 8 && s->bit_depth != 16) {
    output.Fail("bit_depth", "expected 8 or 16");
  }

}

// The C-arm (before the camera: the detector pitch needs the SID), with its flex.
CarmGeometry ParseSceneCarm(YamlMap& scene, XrayScene* s) {
  CarmGeometry carm;
  YamlMap& cm = scene.Map("carm");
  cm.GetInRange("sid_mm", &carm.sid_mm, plausible::kDistanceMm);
  cm.GetInRange("sod_mm", &carm.sod_mm, plausible::kDistanceMm);
  GetVec(cm, "isocenter_mm", 3, carm.isocenter_mm.data());
  GetVec(cm, "axis_offset_mm", 2, carm.axis_offset_mm.data());
  if (cm.Has("flex")) {
    YamlMap& fx = cm.Map("flex");
    const PlausibleRange kShiftPx{-200, 200, "px"}, kRelative{-0.1, 0.1, ""};
    fx.GetInRange("cx_primary_px", &s->flex.cx_primary_px, kShiftPx);
    fx.GetInRange("cx_secondary_px", &s->flex.cx_secondary_px, kShiftPx);
    fx.GetInRange("cy_primary_px", &s->flex.cy_primary_px, kShiftPx);
    fx.GetInRange("cy_secondary_px", &s->flex.cy_secondary_px, kShiftPx);
    fx.GetInRange("f_primary", &s->flex.f_primary, kRelative);
    fx.GetInRange("f_secondary", &s->flex.f_secondary, kRelative);
  }
  if (cm.status().ok() && !(carm.sod_mm < carm.sid_mm)) {
    cm.Fail("sod_mm",
            "expected the source-to-isocentre distance to be smaller than sid_mm (" +
                Fmt("%.1f", carm.sid_mm) + ")");
  }

  return carm;
}

// The camera: fx, fy, cx, cy or a detector pitch at the C-arm's SID; distortion.
void ParseSceneCamera(YamlMap& scene, const CarmGeometry& carm, XrayScene* s) {
  YamlMap& cam = scene.Map("camera", true);
  std::vector<int> size;
  cam.Get("image_size", &size, true);
  if (cam.status().ok() &&
      (size.size() != 2 || size[0] < 8 || size[1] < 8 || size[0] > 16384 || size[1] > 16384)) {
    cam.Fail("image_size", "expected [width, height] in px, each in 8..16384");
  }
  const bool has_f = cam.Has("fx") || cam.Has("fy") || cam.Has("cx") || cam.Has("cy");
  const bool has_pitch = cam.Has("pixel_pitch_mm");
  if (has_f && has_pitch) {
    cam.Fail("pixel_pitch_mm", "give either fx, fy, cx, cy or pixel_pitch_mm, not both");
  } else if (!has_f && !has_pitch) {
    cam.Fail("fx", "missing, expected fx, fy, cx, cy (px) or pixel_pitch_mm");
  }
  if (cam.status().ok() && size.size() == 2) {
    s->camera.width = size[0];
    s->camera.height = size[1];
    s->camera.params.fill(0.0);
    if (has_f) {
      cam.GetInRange("fx", &s->camera.params[kFx], plausible::kFocalPx, true);
      cam.GetInRange("fy", &s->camera.params[kFy], plausible::kFocalPx, true);
      cam.Get("cx", &s->camera.params[kCx], true);
      cam.Get("cy", &s->camera.params[kCy], true);
    } else {
      DetectorSpec det;
      det.width_px = size[0];
      det.height_px = size[1];
      std::vector<double> pitch;
      if (cam.Raw("pixel_pitch_mm").IsScalar()) {
        pitch.push_back(0.0);
        cam.Get("pixel_pitch_mm", &pitch[0]);
      } else {
        cam.Get("pixel_pitch_mm", &pitch);
      }
      if (cam.status().ok()) {
        if (pitch.size() == 1) pitch.push_back(pitch[0]);
        if (pitch.size() != 2 || !InRange(pitch[0], plausible::kPixelPitchMm) ||
            !InRange(pitch[1], plausible::kPixelPitchMm)) {
          cam.Fail("pixel_pitch_mm", "expected a number or [x, y], each " +
                                         FormatRange(plausible::kPixelPitchMm));
        } else {
          det.pitch_x_mm = pitch[0];
          det.pitch_y_mm = pitch[1];
        }
      }
      GetVec(cam, "principal_offset_px", 2, det.principal_offset_px.data());
      if (cam.status().ok()) s->camera = CameraFromDetector(det, carm.sid_mm);
    }
    GetVec(cam, "distortion", 5, &s->camera.params[kK1]);
  }

}

// An anatomy background laid over the images (imaging.background).
struct SceneBackground {
  std::string file;
  double strength = 0.3, crop = 1.0;
  double crop_center[2] = {0.5, 0.5};  // of the frame's width and height
};

// The imaging chain: supersampling, dose, noise, blur, vignetting, heel effect, glare, field of
// view, background.
void ParseSceneImaging(YamlMap& scene, XrayScene* s, SceneBackground* bg) {
  YamlMap& im = scene.Map("imaging");
  RenderOptions& r = s->render;
  im.Get("supersampling", &r.supersampling);
  im.GetPositive("white_level", &r.white_level);
  im.GetInRange("photons_per_pixel", &r.photons_per_pixel, plausible::kPhotonsPerPixel);
  im.GetInRange("read_noise_gray", &r.read_noise_gray, plausible::kGreyLevel);
  im.GetNonNegative("blur_sigma_px", &r.blur_sigma_px);
  im.GetNonNegative("vignetting", &r.vignetting);
  im.GetInRange("outside_fov_gray", &r.outside_fov_gray, plausible::kGreyLevel);
  if (im.status().ok() && (r.supersampling < 1 || r.supersampling > 16)) {
    im.Fail("supersampling", "expected an integer in 1..16");
  }
  if (im.status().ok() && r.vignetting >= 1) im.Fail("vignetting", "expected a value in [0, 1)");
  im.GetPositive("vignetting_power", &r.vignetting_power);
  if (im.status().ok() && !(r.vignetting_power >= 0.5 && r.vignetting_power <= 16)) {
    im.Fail("vignetting_power", "expected a value in [0.5, 16]");
  }
  YamlMap& heel = im.Map("heel");
  heel.GetNonNegative("gradient", &r.heel, im.Has("heel"));
  heel.Get("direction_deg", &r.heel_direction_deg);
  if (heel.status().ok() && r.heel > 0.5) heel.Fail("gradient", "expected a value in [0, 0.5]");
  YamlMap& glare = im.Map("glare");
  glare.GetNonNegative("fraction", &r.glare_fraction, im.Has("glare"));
  glare.GetPositive("sigma_px", &r.glare_sigma_px);
  if (glare.status().ok() && r.glare_fraction > 0.9) {
    glare.Fail("fraction", "expected a value in [0, 0.9]");
  }
  if (glare.status().ok() && !(r.glare_sigma_px >= 1 && r.glare_sigma_px <= 1000)) {
    glare.Fail("sigma_px", "expected 1..1000 px");
  }
  if (im.status().ok() && r.blur_sigma_px > 50) im.Fail("blur_sigma_px", "expected 0..50 px");
  if (im.status().ok() && r.white_level > 1e6) im.Fail("white_level", "expected at most 1e6");
  YamlMap& fov = im.Map("fov");
  fov.Get("circular", &r.circular_fov);
  fov.GetPositive("radius_px", &r.fov_radius_px);
  fov.GetNonNegative("edge_px", &r.fov_edge_px);
  double fov_c[2];
  if (GetVec(fov, "center_px", 2, fov_c)) {
    if (fov_c[0] < 0 || fov_c[1] < 0) {
      fov.Fail("center_px", "expected non-negative pixel coordinates");
    }
    r.fov_center_u_px = fov_c[0];
    r.fov_center_v_px = fov_c[1];
  }
  YamlMap& bgm = im.Map("background");
  bgm.Get("file", &bg->file, im.Has("background"));
  bgm.GetNonNegative("strength", &bg->strength);
  bgm.GetPositive("crop", &bg->crop);
  if (bgm.status().ok() && bg->strength > 1) bgm.Fail("strength", "expected a value in [0, 1]");
  if (bgm.status().ok() && bg->crop > 1) bgm.Fail("crop", "expected a fraction in (0, 1]");
  if (GetVec(bgm, "crop_center", 2, bg->crop_center) &&
      !(bg->crop_center[0] >= 0 && bg->crop_center[0] <= 1 && bg->crop_center[1] >= 0 &&
        bg->crop_center[1] <= 1)) {
    bgm.Fail("crop_center", "expected fractions of the frame's width and height in [0, 1]");
  }
}

// The anatomy key as read (sim/ct_anatomy.h); the CT is read after the keys are checked.
struct SceneAnatomy {
  bool given = false;
  CtAnatomy anatomy;
  Eigen::Vector3d center_mm = Eigen::Vector3d::Zero(), rotation_deg = Eigen::Vector3d::Zero();
};

void ParseSceneAnatomy(YamlMap& scene, SceneAnatomy* out) {
  out->given = scene.Has("anatomy");
  YamlMap& m = scene.Map("anatomy");
  CtAnatomy& a = out->anatomy;
  m.Get("ct", &a.file, out->given);
  GetVec(m, "center_mm", 3, out->center_mm.data());
  GetVec(m, "rotation_deg", 3, out->rotation_deg.data());
  m.GetPositive("mu_water_per_mm", &a.mu_water_per_mm);
  m.Get("subsample", &a.subsample);
  if (m.status().ok() && a.mu_water_per_mm > 1) {
    m.Fail("mu_water_per_mm", "expected a value in (0, 1] per mm (water is about 0.02)");
  }
  if (m.status().ok() && (a.subsample < 1 || a.subsample > 8)) {
    m.Fail("subsample", "expected an integer in 1..8");
  }
}

// The anatomy's CT read and placed in the object frame: object_from_ct = T(center) R(rotation)
// T(-the volume's centre).
Status LoadSceneAnatomy(const YamlMap& scene,
                        const std::string& dir,
                        const SceneAnatomy& in,
                        XrayScene* s) {
  if (!in.given) return Status::Ok();
  auto ct = ReadAnatomyCt(JoinPath(dir, in.anatomy.file));
  if (!ct.ok()) return ct.status().WithContext(scene.file() + ": key 'anatomy.ct'");
  CtAnatomy a = in.anatomy;
  a.volume = *ct;
  a.object_from_ct = ObjectPlacement(CtVolumeCentre(*a.volume), in.rotation_deg, in.center_mm);
  s->anatomy = a;
  return Status::Ok();
}

// The attenuation of each material: the defaults and the scene's own.
std::map<std::string, double> ParseSceneMaterials(YamlMap& scene) {
  std::map<std::string, double> materials = DefaultMaterials();
  if (scene.Has("materials")) {
    YAML::Node mats = scene.Raw("materials");
    if (!mats.IsMap()) {
      scene.Fail("materials", "expected a mapping of material name to mu (1/mm)");
    } else {
      YamlMap& mm = scene.Map("materials");
      mm.SetUserNamedKeys("<material>");
      for (const auto& kv : mats) {
        if (!kv.first.IsScalar()) {  // `? [a, b]`: as<std::string>() would throw
          scene.Fail("materials", "expected material names as keys");
          break;
        }
        const std::string name = kv.first.Scalar();
        double mu = 0;
        mm.GetNonNegative(name, &mu, true);
        materials[name] = mu;
      }
    }
  }

  return materials;
}

// The object: a calibration plate or a marker object (with its block), as a phantom.
void ParseSceneObject(YamlMap& scene, const std::string& dir,
                      const std::map<std::string, double>& materials, XrayScene* s) {
  const bool has_plate = scene.Has("plate"), has_markers = scene.Has("markers");
  if (has_plate == has_markers) {
    scene.Fail(has_plate ? "markers" : "plate",
               "expected exactly one of 'plate' (calibration plate) or 'markers' (marker object)");
  }
  if (has_plate) {
    s->object_kind = "plate";
    YamlMap& pl = scene.Map("plate");
    pl.Get("rows", &s->plate.rows);
    pl.Get("cols", &s->plate.cols);
    pl.GetPositive("pitch_mm", &s->plate.pitch_mm);
    pl.GetPositive("sphere_diameter_mm", &s->plate.sphere_diameter_mm);
    pl.GetInRange("thickness_mm", &s->plate.thickness_mm, plausible::kLengthMm);
    pl.GetInRange("margin_mm", &s->plate.margin_mm, plausible::kLengthMm);
    pl.Get("sphere_material", &s->plate.sphere_material);
    pl.Get("plate_material", &s->plate.plate_material);
    std::string error;
    if (pl.status().ok() && !s->plate.Check(&error)) {
      scene.Fail("plate", error.substr(error.find(": ") + 2));
    } else if (pl.status().ok()) {
      auto ph = MakePlatePhantom(s->plate, materials);
      if (!ph.ok()) {
        pl.Fail("sphere_material", ph.status().message());
      } else {
        s->phantom = *ph;
      }
    }
  }
  if (has_markers) {
    s->object_kind = "markers";
    YamlMap& mk = scene.Map("markers");
    std::string csv, id_col;
    std::vector<std::string> cols;
    mk.Get("csv", &csv, true);
    mk.Get("id_column", &id_col);
    mk.Get("columns", &cols, true);
    mk.GetPositive("diameter_mm", &s->markers.sphere_diameter_mm);
    mk.Get("material", &s->markers.sphere_material);
    if (mk.status().ok() && cols.size() != 3) {
      mk.Fail("columns", "expected three column names [x, y, z]");
    }
    YamlMap& bl = scene.Map("block");
    bl.Get("enabled", &s->markers.block);
    bl.GetNonNegative("padding_mm", &s->markers.block_margin_mm);
    bl.Get("material", &s->markers.block_material);
    if (mk.status().ok() && bl.status().ok()) {
      Status st = ReadMarkerCsv(JoinPath(dir, csv), id_col, cols[0], cols[1], cols[2], &s->markers);
      if (!st.ok()) {
        mk.Fail("csv", st.message());
      } else {
        auto ph = MakeMarkerPhantom(s->markers, materials);
        if (!ph.ok()) {
          mk.Fail("csv", ph.status().message());
        } else {
          s->phantom = *ph;
        }
      }
    }
  } else if (scene.Has("block")) {
    scene.Fail("block", "only valid with 'markers'");
  }
}

// Spheres and wires on the marker object that are not markers.
void ParseSceneClutter(YamlMap& scene,
                       const std::map<std::string, double>& materials,
                       XrayScene* s) {
  const bool has_markers = scene.Has("markers");
  if (scene.Has("clutter")) {
    YamlMap& cl = scene.Map("clutter");
    if (!has_markers) cl.Fail("spheres", "clutter is only valid with 'markers'");
    s->clutter.frame = "object";
    auto material = [&](YamlMap& m, double* mu) {
      std::string name = "steel";
      m.Get("material", &name);
      if (!materials.count(name)) {
        m.Fail("material", "unknown material '" + name + "'");
        return;
      }
      *mu = materials.at(name);
    };
    int k = 0;
    for (YamlMap* sm : cl.MapList("spheres")) {
      SpherePrimitive sp;
      GetVec(*sm, "center_mm", 3, sp.center_mm.data(), true);
      double d = 0;
      sm->GetPositive("diameter_mm", &d, true);
      sp.radius_mm = 0.5 * d;
      material(*sm, &sp.mu_per_mm);
      sp.id = --k;  // negative: not a marker
      s->clutter.spheres.push_back(sp);
    }
    for (YamlMap* wm : cl.MapList("wires")) {
      Eigen::Vector3d a = Eigen::Vector3d::Zero(), b = Eigen::Vector3d::Zero();
      GetVec(*wm, "from_mm", 3, a.data(), true);
      GetVec(*wm, "to_mm", 3, b.data(), true);
      double d = 0;
      wm->GetPositive("diameter_mm", &d, true);
      BoxPrimitive box;
      material(*wm, &box.mu_per_mm);
      const double len = (b - a).norm();
      if (!(len > 0)) {
        wm->Fail("to_mm", "expected a segment of non-zero length");
        continue;
      }
      // Box frame: z along the segment.
      const Eigen::Vector3d z = (b - a) / len;
      Eigen::Vector3d x = z.unitOrthogonal(), y = z.cross(x);
      box.phantom_from_box.R.col(0) = x;
      box.phantom_from_box.R.col(1) = y;
      box.phantom_from_box.R.col(2) = z;
      box.phantom_from_box.t = 0.5 * (a + b);
      box.half_size_mm = Eigen::Vector3d(0.5 * d, 0.5 * d, 0.5 * len);
      s->clutter.boxes.push_back(box);
    }
  }
}

// The views: C-arm angles and the object's placement in each.
void ParseSceneViews(YamlMap& scene, const CarmGeometry& carm, XrayScene* s) {
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& sp : s->phantom.spheres) centroid += sp.center_mm;
  if (!s->phantom.spheres.empty()) centroid /= static_cast<double>(s->phantom.spheres.size());
  Eigen::Vector3d rotation_deg = Eigen::Vector3d::Zero(), center_mm = Eigen::Vector3d::Zero();
  YamlMap& op = scene.Map("object_pose");
  GetVec(op, "rotation_deg", 3, rotation_deg.data());
  GetVec(op, "center_mm", 3, center_mm.data());

  std::vector<YamlMap*> views = scene.MapList("views", true);
  if (scene.status().ok() && views.empty()) scene.Fail("views", "expected at least one view");
  std::set<std::string> names;
  for (size_t i = 0; i < views.size(); ++i) {
    YamlMap& vm = *views[i];
    XrayView v;
    char def[32];
    std::snprintf(def, sizeof(def), "view_%03zu", i);
    v.name = def;
    vm.Get("name", &v.name);
    if (vm.status().ok() && !ValidSceneName(v.name)) {
      vm.Fail("name", "expected letters, digits, '_' or '-', got '" + v.name + "'");
    }
    if (vm.status().ok() && !names.insert(v.name).second) {
      vm.Fail("name", "duplicate view name '" + v.name + "'");
    }
    v.carm = carm;
    vm.GetInRange("primary_deg", &v.carm.primary_angle_deg, plausible::kAngleDeg);
    vm.Get("secondary_deg", &v.carm.secondary_angle_deg);
    vm.GetInRange("detector_rotation_deg", &v.carm.detector_rotation_deg, plausible::kAngleDeg);
    if (vm.status().ok() && std::fabs(v.carm.secondary_angle_deg) > 90) {
      vm.Fail("secondary_deg", "expected an angle in [-90, 90] degrees");
    }
    Eigen::Vector3d rot = rotation_deg, ctr = center_mm;
    GetVec(vm, "object_rotation_deg", 3, rot.data());
    GetVec(vm, "object_center_mm", 3, ctr.data());
    v.world_from_object = ObjectPlacement(centroid, rot, ctr);
    v.seed = ViewSeed(s->seed, static_cast<int>(i));
    vm.Get("partial", &v.partial);
    s->views.push_back(v);
  }

}

// After the keys: the anatomy's CT and the background loaded, the camera, imaging and each
// view's C-arm checked, and every view inside the field of view.
Status CheckParsedScene(YamlMap& scene,
                        const std::string& dir,
                        const SceneBackground& bg,
                        const SceneAnatomy& anatomy,
                        XrayScene* s) {
  CARMBA_RETURN_IF_ERROR(scene.Finish());
  CARMBA_RETURN_IF_ERROR(LoadSceneAnatomy(scene, dir, anatomy, s));
  if (!bg.file.empty()) {
    auto gain = LoadBackgroundGain(JoinPath(dir, bg.file),
                                   s->camera.width,
                                   s->camera.height,
                                   bg.strength,
                                   bg.crop,
                                   cv::Point2d(bg.crop_center[0], bg.crop_center[1]));
    if (!gain.ok()) {
      return gain.status().WithContext(scene.file() + ": key 'imaging.background.file'");
    }
    s->render.background_gain = *gain;
  }
  Status cs = s->camera.Check();
  if (!cs.ok()) return cs.WithContext(scene.file() + ": key 'camera'");
  std::string error;
  if (!s->render.Check(&error)) return Status::Error(scene.file() + ": key 'imaging': " + error);
  for (const auto& v : s->views) {
    if (!v.carm.Check(&error)) {
      return Status::Error(scene.file() + ": view '" + v.name + "': " + error);
    }
  }
  CARMBA_RETURN_IF_ERROR(CheckViewsInsideFov(*s));
  return Status::Ok();
}

}  // namespace

Status ParseXrayScene(YamlMap& scene, XrayScene* out) {
  XrayScene s;
  s.path = scene.file();
  const std::string dir = DirName(scene.file());
  std::string kind;
  scene.GetEnum("kind", {"xray"}, &kind, true);
  scene.Get("description", &s.description);
  int seed = 1;
  scene.Get("seed", &seed);
  if (seed < 0) scene.Fail("seed", "expected a non-negative integer");
  s.seed = static_cast<uint64_t>(seed);
  ParseSceneOutput(scene, &s);
  const CarmGeometry carm = ParseSceneCarm(scene, &s);
  ParseSceneCamera(scene, carm, &s);
  SceneBackground bg;
  ParseSceneImaging(scene, &s, &bg);
  const std::map<std::string, double> materials = ParseSceneMaterials(scene);
  ParseSceneObject(scene, dir, materials, &s);
  ParseSceneClutter(scene, materials, &s);
  ParseSceneViews(scene, carm, &s);
  SceneAnatomy anatomy;
  ParseSceneAnatomy(scene, &anatomy);
  CARMBA_RETURN_IF_ERROR(CheckParsedScene(scene, dir, bg, anatomy, &s));
  *out = std::move(s);
  return Status::Ok();
}

StatusOr<XrayScene> LoadXrayScene(const std::string& path) {
  YamlMap m = YamlMap::Load(path);
  if (!m.status().ok()) return m.status();
  XrayScene s;
  CARMBA_RETURN_IF_ERROR(ParseXrayScene(m, &s));
  return s;
}

Status CheckViewsInsideFov(const XrayScene& s) {
  const double W = s.camera.width, H = s.camera.height;
  const FovCircle fov = FovOf(s.camera, s.render);
  const double fu = fov.u, fv = fov.v, fr = fov.r;
  for (int i = 0; i < static_cast<int>(s.views.size()); ++i) {
    const Rigid3 cam_from_object = s.CamFromObject(i);
    const Camera camera = s.ViewCamera(i);
    const std::string where = s.path + ": view '" + s.views[i].name + "'";
    if (s.views[i].partial) continue;
    for (const auto& sp : s.phantom.spheres) {
      const Eigen::Vector3d c = cam_from_object * sp.center_mm;
      double uv[2];
      if (!(c.z() > sp.radius_mm) || !ProjectCamPoint(camera.params.data(), c.data(), uv)) {
        return Status::Error(where + ": sphere " + std::to_string(sp.id) +
                             " is not in front of the X-ray source");
      }
      const double r = SphereImageRadius(camera, c, sp.radius_mm, {uv[0], uv[1]});
      const std::string at = "sphere " + std::to_string(sp.id) + " projects to (" +
                             Fmt("%.1f", uv[0]) + ", " + Fmt("%.1f", uv[1]) + ") px with radius " +
                             Fmt("%.1f", r) + " px, ";
      if (!(uv[0] - r >= 0 && uv[0] + r <= W - 1 && uv[1] - r >= 0 && uv[1] + r <= H - 1)) {
        return Status::Error(where + ": " + at + "outside the " + std::to_string(s.camera.width) +
                             "x" + std::to_string(s.camera.height) +
                             " image (the pattern is larger than the field of view?)");
      }
      // The whole silhouette must lie in the fully exposed disc, inside the fall-off edge.
      const double usable = fr - s.render.fov_edge_px - 1.0;
      if (s.render.circular_fov && !(std::hypot(uv[0] - fu, uv[1] - fv) + r <= usable)) {
        return Status::Error(where + ": " + at + "outside the circular field of view (centre (" +
                             Fmt("%.1f", fu) + ", " + Fmt("%.1f", fv) + "), radius " +
                             Fmt("%.1f", fr) + " px, edge " + Fmt("%.1f", s.render.fov_edge_px) +
                             " px; the pattern is larger than the field of view?)");
      }
    }
  }
  return Status::Ok();
}

StatusOr<RenderedView> RenderXrayView(const XrayScene& scene, int index, const RayGrid* grid) {
  if (index < 0 || index >= static_cast<int>(scene.views.size())) {
    return Status::Error("view index " + std::to_string(index) + " out of range");
  }
  const XrayView& v = scene.views[index];
  RenderedView out;
  out.cam_from_object = scene.CamFromObject(index);
  RenderOptions options = scene.render;
  options.seed = v.seed;
  const PlacedPhantom placed{&scene.phantom, out.cam_from_object};
  const Camera camera = scene.ViewCamera(index);
  if (!scene.flex.Rigid()) grid = nullptr;  // the ray grid is the rigid camera's
  std::vector<PlacedPhantom> phantoms = {placed};
  const bool clutter = !scene.clutter.spheres.empty() || !scene.clutter.boxes.empty();
  if (clutter) phantoms.push_back({&scene.clutter, out.cam_from_object});
  if (scene.anatomy) {
    const FovCircle fov = FovOf(camera, options);
    const cv::Mat gain =
        CtAnatomyGain(*scene.anatomy, camera, out.cam_from_object, fov.circular ? &fov : nullptr);
    options.background_gain =
        options.background_gain.empty() ? gain : cv::Mat(options.background_gain.mul(gain));
  }
  auto gray = RenderXray(camera, phantoms, options, grid);
  if (!gray.ok()) return gray.status().WithContext("view '" + v.name + "'");
  out.gray = *gray;
  out.image = ToOutputImage(out.gray, scene.bit_depth);
  auto uv = ProjectSphereCenters(camera, placed);
  if (!uv.ok()) return uv.status().WithContext("view '" + v.name + "'");
  out.centers_px = *uv;

  nlohmann::json& j = out.truth;
  j["name"] = v.name;
  j["file"] = v.name + "." + scene.format;
  j["primary_deg"] = v.carm.primary_angle_deg;
  j["secondary_deg"] = v.carm.secondary_angle_deg;
  j["detector_rotation_deg"] = v.carm.detector_rotation_deg;
  j["seed"] = v.seed;
  j["cam_from_world"] = RigidToJson(CamFromWorld(v.carm));
  j["world_from_object"] = RigidToJson(v.world_from_object);
  j[scene.phantom.frame == "plate" ? "cam_from_plate" : "cam_from_object"] =
      RigidToJson(out.cam_from_object);
  nlohmann::json px = nlohmann::json::array(), cam = nlohmann::json::array();
  for (size_t k = 0; k < out.centers_px.size(); ++k) {
    px.push_back({out.centers_px[k].x(), out.centers_px[k].y()});
    cam.push_back(Vec3Json(out.cam_from_object * scene.phantom.spheres[k].center_mm));
  }
  j["centers_px"] = px;
  j["centers_in_cam_mm"] = cam;
  j["intrinsics"] = CameraToJson(camera);
  if (!scene.clutter.spheres.empty()) {
    auto cuv = ProjectSphereCenters(camera, {&scene.clutter, out.cam_from_object});
    if (!cuv.ok()) return cuv.status().WithContext("view '" + v.name + "' (clutter)");
    nlohmann::json cpx = nlohmann::json::array();
    for (const auto& q : *cuv) cpx.push_back({q.x(), q.y()});
    j["clutter_centers_px"] = cpx;
  }
  return out;
}

namespace {

// The XA geometry tags of a view (xray_scene.h, output dcm): angles, SID, SOD, and the pixel
// spacing SID / fy \ SID / fx that gives back fx, fy through io/dicom_view.h.
DicomXrayWriteOptions DicomOptionsOfView(const XrayScene& scene, int view) {
  const CarmGeometry& carm = scene.views[view].carm;
  const Camera camera = scene.ViewCamera(view);  // the view's own (flexing C-arm)
  DicomXrayWriteOptions o;
  o.geometry.primary_angle_deg = carm.primary_angle_deg;
  o.geometry.secondary_angle_deg = carm.secondary_angle_deg;
  o.geometry.sid_mm = carm.sid_mm;
  o.geometry.sod_mm = carm.sod_mm;
  o.geometry.pixel_spacing_row_mm = carm.sid_mm / camera.params[kFy];
  o.geometry.pixel_spacing_col_mm = carm.sid_mm / camera.params[kFx];
  return o;
}

}  // namespace

Status SimulateXrayScene(const XrayScene& scene,
                         const std::string& out_dir,
                         nlohmann::json* truth) {
  auto grid = RayGrid::Build(scene.camera, scene.render);
  if (!grid.ok()) return grid.status().WithContext(scene.path);
  nlohmann::json& t = *truth;
  t["kind"] = "xray";
  t["description"] = scene.description;
  t["seed"] = scene.seed;
  t["camera"] = CameraToJson(scene.camera);
  const CarmGeometry& c = scene.views[0].carm;
  t["carm"] = {{"sid_mm", c.sid_mm},
               {"sod_mm", c.sod_mm},
               {"isocenter_mm", Vec3Json(c.isocenter_mm)},
               {"axis_offset_mm", {c.axis_offset_mm.x(), c.axis_offset_mm.y()}}};
  nlohmann::json obj;
  obj["kind"] = scene.object_kind;
  obj["frame"] = scene.phantom.frame;
  nlohmann::json ids = nlohmann::json::array(), centers = nlohmann::json::array();
  for (const auto& sp : scene.phantom.spheres) {
    ids.push_back(sp.id);
    centers.push_back(Vec3Json(sp.center_mm));
  }
  obj["sphere_ids"] = ids;
  obj["centers_mm"] = centers;
  if (scene.object_kind == "plate") {
    obj["rows"] = scene.plate.rows;
    obj["cols"] = scene.plate.cols;
    obj["pitch_mm"] = scene.plate.pitch_mm;
    obj["thickness_mm"] = scene.plate.thickness_mm;
    obj["sphere_diameter_mm"] = scene.plate.sphere_diameter_mm;
  } else {
    obj["sphere_diameter_mm"] = scene.markers.sphere_diameter_mm;
  }
  t["object"] = obj;
  if (scene.anatomy) {
    t["anatomy"] = {{"ct", scene.anatomy->file},
                    {"object_from_ct", RigidToJson(scene.anatomy->object_from_ct)},
                    {"mu_water_per_mm", scene.anatomy->mu_water_per_mm}};
  }
  t["views"] = nlohmann::json::array();
  std::vector<cv::Mat> frames;
  const int num_views = static_cast<int>(scene.views.size());
  for (int i = 0; i < num_views; ++i) {
    auto view = RenderXrayView(scene, i, grid->get());
    if (!view.ok()) return view.status().WithContext(scene.path);
    if (scene.multiframe) {
      view->truth["file"] = DicomFrameName("views.dcm", i, num_views);
      frames.push_back(view->image);
      t["views"].push_back(view->truth);
      continue;
    }
    const std::string file = JoinPath(out_dir, view->truth["file"].get<std::string>());
    if (scene.format == "dcm") {
      DicomXrayWriteOptions o = DicomOptionsOfView(scene, i);
      o.sop_instance_uid = o.series_uid + "." + std::to_string(i + 1);
      CARMBA_RETURN_IF_ERROR(WriteDicomXray(file, {view->image}, o));
    } else {
      CARMBA_RETURN_IF_ERROR(WriteImage(file, view->image));
    }
    t["views"].push_back(view->truth);
  }
  if (scene.multiframe) {
    const CarmGeometry& first = scene.views[0].carm;
    DicomXrayWriteOptions o = DicomOptionsOfView(scene, 0);
    for (const XrayView& v : scene.views) {
      if (v.carm.sid_mm != first.sid_mm || v.carm.sod_mm != first.sod_mm) {
        return Status::Error(scene.path + ": view '" + v.name +
                             "': multiframe output needs one SID and SOD for all views");
      }
      // One offset per frame from the first frame's angles (PS3.3 C.8.7.5.1.3).
      o.primary_increment_deg.push_back(v.carm.primary_angle_deg - first.primary_angle_deg);
      o.secondary_increment_deg.push_back(v.carm.secondary_angle_deg - first.secondary_angle_deg);
    }
    if (num_views == 1) o.primary_increment_deg.clear(), o.secondary_increment_deg.clear();
    CARMBA_RETURN_IF_ERROR(WriteDicomXray(JoinPath(out_dir, "views.dcm"), frames, o));
  }
  return Status::Ok();
}

}  // namespace carmba::sim
