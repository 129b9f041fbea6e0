// Detection accuracy on the simulator's X-ray scenes against their ground truth (the projected
// sphere centres): the systematic error (noise-free render) and the total error (the scene's
// noise), per scene.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>

#include "detect/grid_detector.h"
#include "figures.h"
#include "sim/phantom.h"
#include "sim/xray_scene.h"

namespace carmba {
namespace {

struct ErrorStats {
  int n = 0;
  double rms_px = 0;       // per coordinate
  double max_px = 0;       // largest error vector length
  Eigen::Vector2d mean_px{0, 0};
  double radial_slope = 0;  // radial error per px of distance from the image centre
};

// Detects every view of `scene` (rendered with `render`) and compares each detected centre with
// the nearest true one.
ErrorStats DetectionError(sim::XrayScene scene, const sim::RenderOptions& render,
                          bool print_worst = false) {
  scene.render = render;
  auto grid = sim::RayGrid::Build(scene.camera, scene.render);
  EXPECT_TRUE(grid.ok());
  GridSpec g;
  g.rows = scene.plate.rows;
  g.cols = scene.plate.cols;
  g.spacing_mm = scene.plate.pitch_mm;
  ErrorStats s;
  double sum2 = 0, srr = 0, sre = 0;
  const Eigen::Vector2d c(0.5 * (scene.camera.width - 1), 0.5 * (scene.camera.height - 1));
  for (int i = 0; i < static_cast<int>(scene.views.size()); ++i) {
    auto v = sim::RenderXrayView(scene, i, grid->get());
    EXPECT_TRUE(v.ok());
    GridDetection d = DetectGrid(v->image, g, DetectionOptions());
    EXPECT_TRUE(d.found) << scene.views[i].name << ": " << d.reason;
    for (const auto& uv : d.view.uv_px) {
      Eigen::Vector2d best(1e9, 1e9), truth(0, 0);
      for (const auto& t : v->centers_px) {
        if ((uv - t).norm() < best.norm()) best = uv - t, truth = t;
      }
      ++s.n;
      sum2 += best.squaredNorm();
      s.mean_px += best;
      s.max_px = std::max(s.max_px, best.norm());
      const Eigen::Vector2d rel = truth - c;
      if (rel.norm() > 1) {
        srr += rel.norm() * rel.norm();
        sre += rel.norm() * best.dot(rel.normalized());
      }
      if (print_worst && best.norm() > 0.02) {
        std::cout << "  " << scene.views[i].name << " at (" << truth.x() << ", " << truth.y()
                  << "): error (" << best.x() << ", " << best.y() << ")\n";
      }
    }
  }
  s.rms_px = std::sqrt(sum2 / (2.0 * s.n));
  s.mean_px /= s.n;
  s.radial_slope = sre / srr;
  return s;
}

std::ostream& operator<<(std::ostream& o, const ErrorStats& s) {
  return o << s.n << " points, RMS " << s.rms_px << " px, max " << s.max_px << " px, mean ("
           << s.mean_px.x() << ", " << s.mean_px.y() << "), radial " << 100 * s.radial_slope
           << " px per 100 px";
}

sim::XrayScene Scene(const std::string& name) {
  auto s = sim::LoadXrayScene(std::string(CARMBA_SOURCE_DIR) + "/configs/scenes/" + name + ".yaml");
  EXPECT_TRUE(s.ok()) << s.status().message();
  return *s;
}

// Systematic error: the scene rendered without noise. Before the flat-field / ring-background
// centroid (plane fitted to the whole window border, weights bg - I) this was 0.012 / 0.015 px RMS,
// max 0.19 / 0.32 px at the intensifier rim, radial -0.009 px per 100 px (vignetting); now
// ~0.004 px RMS, ~0.015 px max, ~0.002 px per 100 px (the remaining radial part follows the sign
// of k1: the centroid of a distorted blob is not the distorted centre).
constexpr double kSceneSystematicRmsPx = 0.006;
constexpr double kSystematicMaxPx = 0.03;
constexpr double kRadialPer100Px = 0.005;
// The noise-driven scatter must dominate: its RMS at least this many times the systematic RMS
// (variance ratio 7.8: the systematic part adds at most ~6 % to the total RMS). It was 3.0 until
// the plate's centroid floor went from 5 % to 15 % (detect_steps.h kPlateCentroidFloor): that
// cut the noise-driven scatter by 17-18 % (thesis 0.0284 -> 0.0236 px, pincushion 0.0164 ->
// 0.0135 px) and left the systematic part as it was (0.0036, 0.0045 px), so the pincushion scene's
// ratio went from 3.75 to 2.99.
constexpr double kNoiseOverSystematic = 2.8;

TEST(SimulatedSceneDetection, SystematicErrorWellBelowTheNoise) {
  for (const std::string name : {"thesis_calibration", "calib_7x6_pincushion"}) {
    const sim::XrayScene scene = Scene(name);
    sim::RenderOptions clean = scene.render;
    clean.photons_per_pixel = 0;
    clean.read_noise_gray = 0;
    const ErrorStats sys = DetectionError(scene, clean, true);
    const ErrorStats all = DetectionError(scene, scene.render);
    const double noise_rms =
        std::sqrt(std::max(0.0, all.rms_px * all.rms_px - sys.rms_px * sys.rms_px));
    std::cout << name << " noise-free: " << sys << "\n" << name << " as rendered: " << all
              << "\n" << name << " noise-driven RMS " << noise_rms << " px = "
              << noise_rms / sys.rms_px << " x the systematic RMS\n";
    // src/docs/results.md's detection error against the truth, per scene.
    testing::RecordFigure("plate." + name + ".systematic_rms", "%.4f px", sys.rms_px);
    testing::RecordFigure("plate." + name + ".noise_rms", "%.3f px", noise_rms);
    const int spheres = static_cast<int>(scene.phantom.spheres.size() * scene.views.size());
    EXPECT_GE(sys.n, spheres - 2) << name;  // at most 2 points dropped at the rim
    EXPECT_LT(sys.rms_px, kSceneSystematicRmsPx) << name;
    EXPECT_LT(sys.max_px, kSystematicMaxPx) << name;
    EXPECT_LT(std::abs(sys.radial_slope) * 100, kRadialPer100Px) << name;
    EXPECT_GT(noise_rms, kNoiseOverSystematic * sys.rms_px) << name;
  }
}

// The shipped scenes' plates with spheres 0.6 x the pitch in diameter, noise-free. Before the
// window and background ring followed the blob's size: 0.098 / 0.128 px RMS per coordinate, up to
// 0.49 / 0.67 px, a thesis view not found; now ~0.03 px, max < 0.09 px. Views where a sphere comes
// within 1.5 of its radii + 3 px of the field's rim are left out (the scenes' views were checked
// for their own small spheres). The remaining error (~0.03 px per coordinate) includes the large
// sphere's own geometry: its silhouette's centre is not its projected centre under perspective and
// lens distortion (the anti-aliased discs of grid_detector_test.cc LargeCirclesSubPixel: < 0.035
// px).
TEST(SimulatedSceneDetection, LargeSpheres) {
  for (const std::string name : {"thesis_calibration", "calib_7x6_pincushion"}) {
    sim::XrayScene scene = Scene(name);
    scene.plate.sphere_diameter_mm = 0.6 * scene.plate.pitch_mm;
    auto phantom = sim::MakePlatePhantom(scene.plate, sim::DefaultMaterials());
    ASSERT_TRUE(phantom.ok()) << phantom.status().message();
    scene.phantom = *phantom;
    scene.render.photons_per_pixel = 0;
    scene.render.read_noise_gray = 0;
    auto grid = sim::RayGrid::Build(scene.camera, scene.render);
    ASSERT_TRUE(grid.ok());
    GridSpec g;
    g.rows = scene.plate.rows;
    g.cols = scene.plate.cols;
    g.spacing_mm = scene.plate.pitch_mm;
    const sim::RenderOptions& ro = scene.render;
    const double fov_r = ro.fov_radius_px > 0
                             ? ro.fov_radius_px
                             : 0.5 * std::min(scene.camera.width, scene.camera.height);
    const Eigen::Vector2d fov_c(
        ro.fov_center_u_px >= 0 ? ro.fov_center_u_px : 0.5 * (scene.camera.width - 1),
        ro.fov_center_v_px >= 0 ? ro.fov_center_v_px : 0.5 * (scene.camera.height - 1));
    int views = 0, n = 0;
    double sum2 = 0, worst = 0;
    for (int i = 0; i < static_cast<int>(scene.views.size()); ++i) {
      auto v = sim::RenderXrayView(scene, i, grid->get());
      ASSERT_TRUE(v.ok());
      bool inside = true;
      for (size_t k = 0; k < v->centers_px.size(); ++k) {
        const double z = (v->cam_from_object * scene.phantom.spheres[k].center_mm).z();
        const double r_px = scene.camera.params[0] * 0.5 * scene.plate.sphere_diameter_mm / z;
        inside =
            inside && (v->centers_px[k] - fov_c).norm() + 1.5 * r_px + 3 < fov_r - ro.fov_edge_px;
      }
      if (!inside) continue;
      ++views;
      GridDetection d = DetectGrid(v->image, g, DetectionOptions());
      EXPECT_TRUE(d.found) << name << " " << scene.views[i].name << ": " << d.reason;
      EXPECT_GE(d.view.uv_px.size() + 2, v->centers_px.size())
          << name << " " << scene.views[i].name;
      for (const auto& uv : d.view.uv_px) {
        double best = 1e9;
        for (const auto& t : v->centers_px) best = std::min(best, (uv - t).norm());
        ++n;
        sum2 += best * best;
        worst = std::max(worst, best);
      }
    }
    const double rms = std::sqrt(sum2 / (2.0 * std::max(n, 1)));
    std::cout << name << ", spheres 0.6 x the pitch, noise-free: " << views << " views, " << n
              << " points, RMS " << rms << " px per coordinate, max " << worst << " px\n";
    EXPECT_GE(views, 10) << name;
    EXPECT_LT(rms, 0.05) << name;
    EXPECT_LT(worst, 0.12) << name;
  }
}

}  // namespace
}  // namespace carmba
