// Scene files: the shipped scenes load, the ground truth agrees with the camera model, bad scene
// files are rejected one corruption at a time with a one-line error naming file, line and key.
#include "sim/xray_scene.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "camera/camera_model.h"
#include "scratch.h"

namespace carmba::sim {
namespace {

// Projection of a JSON pose re-done with camera_model.h: agreement to rounding of ~1000 mm.
constexpr double kSceneTolPx = 1e-9;

const std::string kSource = CARMBA_SOURCE_DIR;

// A small valid scene; corruptions replace one substring of it.
const char* kBase = R"(kind: xray
description: test
seed: 4
output: {format: png, bit_depth: 8}
camera:
  image_size: [128, 128]
  fx: 600
  fy: 620
  cx: 63.5
  cy: 64.0
  distortion: [-1.0, 0.0, 0.0, 0.0, 0.0]
carm:
  sid_mm: 900
  sod_mm: 500
imaging:
  supersampling: 2
  photons_per_pixel: 1000
  fov: {circular: true}
plate:
  rows: 3
  cols: 3
  pitch_mm: 10
  sphere_diameter_mm: 2.5
object_pose: {rotation_deg: [90, 0, 0]}
views:
  - {name: a, primary_deg: 10, secondary_deg: -5}
  - {name: b, primary_deg: -15, secondary_deg: 12, detector_rotation_deg: 30}
)";

// Writes `text` as <name>.yaml in this process's scratch directory (removed at exit).
std::string WriteScene(const std::string& text, const std::string& name) {
  static const test::ScratchDir dir("sim_scenes");
  const std::string path = dir.File(name + ".yaml");
  std::ofstream(path) << text;
  return path;
}

std::string Corrupt(const std::string& from, const std::string& to) {
  std::string s = kBase;
  const auto pos = s.find(from);
  EXPECT_NE(pos, std::string::npos) << from;
  if (pos != std::string::npos) s.replace(pos, from.size(), to);
  return s;
}

TEST(XrayScene, BaseSceneParsesAndTruthMatchesCameraModel) {
  auto scene = LoadXrayScene(WriteScene(kBase, "base"));
  ASSERT_TRUE(scene.ok()) << scene.status().message();
  ASSERT_EQ(scene->views.size(), 2u);
  ASSERT_EQ(scene->phantom.spheres.size(), 9u);
  for (int i = 0; i < 2; ++i) {
    auto view = RenderXrayView(*scene, i);
    ASSERT_TRUE(view.ok()) << view.status().message();
    EXPECT_EQ(view->image.type(), CV_8U);
    // Re-project every sphere with the pose as written to truth.json.
    const auto& j = view->truth["cam_from_plate"];
    const double pose[6] = {
        j["rvec"][0], j["rvec"][1], j["rvec"][2], j["t_mm"][0], j["t_mm"][1], j["t_mm"][2]};
    for (size_t k = 0; k < scene->phantom.spheres.size(); ++k) {
      double uv[2];
      ASSERT_TRUE(ProjectPoint(
          scene->camera.params.data(), pose, scene->phantom.spheres[k].center_mm.data(), uv));
      EXPECT_NEAR(uv[0], view->truth["centers_px"][k][0].get<double>(), kSceneTolPx);
      EXPECT_NEAR(uv[1], view->truth["centers_px"][k][1].get<double>(), kSceneTolPx);
    }
    // cam_from_plate = cam_from_world * world_from_object.
    const Rigid3 composed = CamFromWorld(scene->views[i].carm) * scene->views[i].world_from_object;
    EXPECT_NEAR((composed.R - view->cam_from_object.R).norm(), 0, 1e-12);
  }
  // Deterministic per seed, different views get different noise.
  auto a = RenderXrayView(*scene, 0), b = RenderXrayView(*scene, 0);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(cv::norm(a->image, b->image, cv::NORM_INF), 0.0);
  EXPECT_NE(scene->views[0].seed, scene->views[1].seed);
  // Reseeding changes the noise, not the geometry.
  XrayScene other = *scene;
  ReseedXrayScene(99, &other);
  auto c = RenderXrayView(other, 0);
  ASSERT_TRUE(c.ok());
  EXPECT_GT(cv::norm(a->image, c->image, cv::NORM_INF), 0.0);
  EXPECT_EQ(c->truth["centers_px"], a->truth["centers_px"]);
}

TEST(XrayScene, ShippedScenesLoadWithEveryViewInsideTheFieldOfView) {
  struct Expect {
    const char* name;
    size_t views, spheres;
  };
  for (const Expect& e : {Expect{"thesis_calibration", 20, 25},
                          Expect{"calib_7x6_pincushion", 24, 42},
                          Expect{"thesis_pose", 7, 9}}) {
    auto scene = LoadXrayScene(kSource + "/configs/scenes/" + e.name + ".yaml");
    ASSERT_TRUE(scene.ok()) << scene.status().message();
    EXPECT_EQ(scene->views.size(), e.views) << e.name;
    EXPECT_EQ(scene->phantom.spheres.size(), e.spheres) << e.name;
    EXPECT_TRUE(CheckViewsInsideFov(*scene).ok());
  }
  auto thesis = LoadXrayScene(kSource + "/configs/scenes/thesis_calibration.yaml");
  ASSERT_TRUE(thesis.ok());
  EXPECT_DOUBLE_EQ(thesis->camera.params[kFx], 2061.389);
  EXPECT_DOUBLE_EQ(thesis->camera.params[kFy], 2254.646);
  EXPECT_DOUBLE_EQ(thesis->camera.params[kCx], 203.655);
  EXPECT_DOUBLE_EQ(thesis->camera.params[kCy], 205.117);
  EXPECT_LT(thesis->camera.params[kK1], 0);  // barrel
  auto pin = LoadXrayScene(kSource + "/configs/scenes/calib_7x6_pincushion.yaml");
  ASSERT_TRUE(pin.ok());
  EXPECT_GT(pin->camera.params[kK1], 0);  // pincushion
  EXPECT_DOUBLE_EQ(pin->camera.params[kFx], 1100 / 0.4);
  auto pose = LoadXrayScene(kSource + "/configs/scenes/thesis_pose.yaml");
  ASSERT_TRUE(pose.ok());
  // Marker 3 of Table 5.1 in the object frame.
  EXPECT_EQ(pose->phantom.spheres[2].id, 3);
  EXPECT_DOUBLE_EQ(pose->phantom.spheres[2].center_mm.x(), 13.35);
}

TEST(XrayScene, BadScenesAreRejectedWithOneLineErrors) {
  struct Case {
    std::string from, to, expected;
  };
  const std::vector<Case> cases = {
      {"  sod_mm: 500", "  sod_mm: 500\n  focus: 1", "unknown key 'carm.focus'"},
      {"seed: 4", "seed: 4\ncolour: red", "unknown key 'colour'"},
      {"sid_mm: 900", "sid_mm: -900", "key 'carm.sid_mm': expected 1 .. 10000 mm, got -900"},
      {"sod_mm: 500", "sod_mm: -5", "key 'carm.sod_mm': expected 1 .. 10000 mm, got -5"},
      {"sod_mm: 500", "sod_mm: 950", "smaller than sid_mm"},
      {"sid_mm: 900", "sid_mm: .nan", "key 'carm.sid_mm': expected a finite number"},
      {"rows: 3", "rows: 12", "larger than the field of view"},
      {"fov: {circular: true}",
       "fov: {circular: true, radius_px: 12}",
       "outside the circular field of view"},
      {"fov: {circular: true}", "fov: {circular: false}\nplate_x: 1", "unknown key 'plate_x'"},
      {"  rows: 3\n  cols: 3", "  rows: 3\n  cols: 14", "larger than the field of view"},
      {"pitch_mm: 10", "pitch_mm: -10", "key 'plate.pitch_mm': expected a positive number"},
      {"sphere_diameter_mm: 2.5",
       "sphere_diameter_mm: 12",
       "key 'plate': sphere_diameter_mm must be > 0 and smaller than pitch_mm"},
      {"  rows: 3\n  cols: 3", "  rows: 1\n  cols: 1", "key 'plate': rows and cols must be"},
      {"distortion: [-1.0, 0.0, 0.0, 0.0, 0.0]",
       "distortion: [-1.0, 0.0]",
       "key 'camera.distortion': expected a list of 5 numbers"},
      {"image_size: [128, 128]", "image_size: [128]", "key 'camera.image_size'"},
      {"  fx: 600\n", "", "give either|missing"},
      {"format: png", "format: jpg", "key 'output.format': expected one of png|pgm"},
      {"bit_depth: 8", "bit_depth: 12", "key 'output.bit_depth': expected 8 or 16"},
      {"kind: xray\n", "", "key 'kind': missing"},
      {"secondary_deg: -5", "secondary_deg: -120", "secondary_deg': expected an angle"},
      {"name: b,", "name: a,", "duplicate view name 'a'"},
      {"name: b,", "name: 'b/../x',", "expected letters, digits"},
      {"supersampling: 2", "supersampling: 0", "key 'imaging.supersampling'"},
      {"seed: 4", "seed: 4\nanatomy: {ct: absent.inv3}", "key 'anatomy.ct'"},
      {"seed: 4", "seed: 4\nanatomy: {ct: .}", "key 'anatomy.ct'"},
      {"seed: 4", "seed: 4\nanatomy: {center_mm: [0, 0, 0]}", "key 'anatomy.ct': missing"},
      {"seed: 4",
       "seed: 4\nanatomy: {ct: x.inv3, mu_water_per_mm: 5}",
       "key 'anatomy.mu_water_per_mm': expected a value in (0, 1]"},
      {"seed: 4",
       "seed: 4\nanatomy: {ct: x.inv3, subsample: 0}",
       "key 'anatomy.subsample': expected an integer in 1..8"},
      {"seed: 4",
       "seed: 4\nanatomy: {ct: x.inv3, centre_mm: [0, 0, 0]}",
       "unknown key 'anatomy.centre_mm'"},
      {"supersampling: 2",
       "supersampling: 2\n  blur_sigma_px: 1e6",
       "key 'imaging.blur_sigma_px': expected 0..50 px"},
      {"plate:\n", "markers: {csv: nothing.csv, columns: [x, y, z]}\nplate:\n", "exactly one of"},
      {"plate:\n  rows: 3",
       "plate:\n  sphere_material: unobtainium\n  rows: 3",
       "unknown material 'unobtainium'"},
      {"views:\n  - {name: a, primary_deg: 10, secondary_deg: -5}\n  - {name: b, primary_deg: "
       "-15, secondary_deg: 12, detector_rotation_deg: 30}\n",
       "views: []\n",
       "expected at least one view"},
      {"object_pose: {rotation_deg: [90, 0, 0]}",
       "object_pose: {rotation_deg: [90, 0]}",
       "key 'object_pose.rotation_deg': expected a list of 3 numbers"},
      {"object_pose: {rotation_deg: [90, 0, 0]}",
       "object_pose: {rotation_deg: [90, 0, 0], center_mm: [0, 600, 0]}",
       "not in front of the X-ray source"},
      {"photons_per_pixel: 1000", "photons_per_pixel: -3", "key 'imaging.photons_per_pixel'"},
      {"fov: {circular: true}",
       "fov: {circular: true}\n  background: {file: /no/such.png}",
       "/no/such.png: no such file"},
      {"fov: {circular: true}",
       "fov: {circular: true}\n  background: {file: x.png, crop_center: [0.5, 1.5]}",
       "key 'imaging.background.crop_center': expected fractions of the frame's width and height "
       "in [0, 1]"},
      {"fov: {circular: true}",
       "fov: {circular: true}\n  vignetting_power: 0.1",
       "key 'imaging.vignetting_power': expected a value in [0.5, 16]"},
      {"fov: {circular: true}",
       "fov: {circular: true}\n  heel: {gradient: 0.7}",
       "key 'imaging.heel.gradient': expected a value in [0, 0.5]"},
      {"fov: {circular: true}",
       "fov: {circular: true}\n  heel: {direction_deg: 30}",
       "key 'imaging.heel.gradient': missing"},
      {"fov: {circular: true}",
       "fov: {circular: true}\n  heel: {gradient: 0.1, side: 3}",
       "unknown key 'imaging.heel.side'"},
      {"fov: {circular: true}",
       "fov: {circular: true}\n  heel: {gradient: 0.1, direction_deg: x}",
       "key 'imaging.heel.direction_deg'"},
      {"fov: {circular: true}",
       "fov: {circular: true}\n  glare: {fraction: -0.1}",
       "key 'imaging.glare.fraction': expected a non-negative number"},
      {"fov: {circular: true}",
       "fov: {circular: true}\n  glare: {fraction: 0.95}",
       "key 'imaging.glare.fraction': expected a value in [0, 0.9]"},
      {"fov: {circular: true}",
       "fov: {circular: true}\n  glare: {fraction: 0.1, sigma_px: 0.5}",
       "key 'imaging.glare.sigma_px': expected 1..1000 px"},
      {"fov: {circular: true}",
       "fov: {circular: true}\n  glare: {sigma_px: 20}",
       "key 'imaging.glare.fraction': missing"},
      // Found by fuzz_xray_scene: a complex key threw YAML::TypedBadConversion (std::terminate).
      {"seed: 4", "seed: 4\nmaterials: {? [a, b] : 1}", "key 'materials': expected material names"},
  };
  int i = 0;
  for (const auto& c : cases) {
    const std::string path = WriteScene(Corrupt(c.from, c.to), "bad" + std::to_string(i++));
    auto scene = LoadXrayScene(path);
    ASSERT_FALSE(scene.ok()) << "accepted: " << c.to;
    const std::string& msg = scene.status().message();
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
    EXPECT_EQ(msg.rfind(path, 0), 0u) << "does not start with the file: " << msg;
    bool found = false;
    std::string alternatives = c.expected;
    size_t start = 0;
    while (true) {
      const size_t bar = alternatives.find('|', start);
      const std::string alt = alternatives.substr(start, bar - start);
      if (msg.find(alt) != std::string::npos) found = true;
      if (bar == std::string::npos) break;
      start = bar + 1;
    }
    EXPECT_TRUE(found) << "expected '" << c.expected << "' in: " << msg;
  }
}

TEST(XrayScene, IntensifierEffectsParse) {
  const std::string text = Corrupt("fov: {circular: true}",
                                   "fov: {circular: true}\n  vignetting: 0.22\n"
                                   "  vignetting_power: 3\n"
                                   "  heel: {gradient: 0.08, direction_deg: -30}\n"
                                   "  glare: {fraction: 0.12, sigma_px: 40}");
  auto scene = LoadXrayScene(WriteScene(text, "effects"));
  ASSERT_TRUE(scene.ok()) << scene.status().message();
  EXPECT_EQ(scene->render.vignetting, 0.22);
  EXPECT_EQ(scene->render.vignetting_power, 3.0);
  EXPECT_EQ(scene->render.heel, 0.08);
  EXPECT_EQ(scene->render.heel_direction_deg, -30.0);
  EXPECT_EQ(scene->render.glare_fraction, 0.12);
  EXPECT_EQ(scene->render.glare_sigma_px, 40.0);
  // Defaults: quadratic fall-off, no heel, no glare.
  auto base = LoadXrayScene(WriteScene(kBase, "effects_default"));
  ASSERT_TRUE(base.ok());
  EXPECT_EQ(base->render.vignetting_power, 2.0);
  EXPECT_EQ(base->render.heel, 0.0);
  EXPECT_EQ(base->render.glare_fraction, 0.0);
}

TEST(XrayScene, MissingFileAndSyntaxError) {
  auto missing = LoadXrayScene("/nonexistent/scene.yaml");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.status().message().find("cannot open"), std::string::npos);
  auto bad = LoadXrayScene(WriteScene("kind: [xray\n", "syntax"));
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("YAML syntax error"), std::string::npos);
}

}  // namespace
}  // namespace carmba::sim
