// Detection recall on seeded, randomised X-ray views with the image intensifier's effects (issue
// 12): a smooth quadratic fall-off towards the rim, a heel-effect gradient, veiling glare and a
// real anatomical background (the XA frame of GDCM's examples), 16-bit 512 x 512 images, plates
// 550-790 mm from the source (fx ~1850 px), tilted. Every view keeps all spheres inside the fully
// exposed field of view (as the simulator's scene check demands), so every sphere counts:
//   recall = spheres found (with the right id) / spheres whose disc lies inside the field of view.
// A found grid is wrong when a point is not near its true centre or the ids do not map to the
// plate by one of the grid's symmetries (the ordering is defined up to them; observations.h).
// Accuracy against the simulator's truth: the whole set as rendered (noise), and a noise-free,
// 5 x 5 supersampled re-render of some views (the systematic part), with and without the anatomy.
// By hand: CARMBA_RECALL_VIEWS=N views per plate (default 10), CARMBA_RECALL_SEED=S other scenes,
// CARMBA_RECALL_DUMP=DIR writes each view (shown 8-bit, raw 16-bit, true centres) into DIR.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <random>

#include <opencv2/imgcodecs.hpp>

#include "camera/camera_model.h"
#include "detect/grid_detector.h"
#include "sim/phantom.h"
#include "sim/xray_render.h"

namespace carmba {
namespace {

const char* kXaFrame = "/usr/share/doc/libgdcm3.0/examples/00191113.dcm";

// The target.
constexpr double kMinRecall = 0.995;
// A found point further than this from its true centre is a wrong blob (the scatter is ~0.02 px).
constexpr double kWrongPointPx = 1.0;
// Accuracy bounds. Without the anatomy (fall-off, heel, glare only) the systematic error is the
// shipped scenes' (README: ~0.004 px RMS; measured here 0.0034): bound 0.006 as in
// simulated_scene_test.cc. The anatomy adds structure inside the background ring that its plane
// does not follow: measured 0.012 px RMS, max 0.056 px (before and after the recall changes;
// 0.015 px, max 0.18 px on the scenes of CARMBA_RECALL_SEED=50000), bound 0.02. With noise (600-2000 quanta per pixel) measured 0.027 px RMS.
constexpr double kSystematicRmsPx = 0.006;
constexpr double kSystematicAnatomyRmsPx = 0.02;
constexpr double kSystematicMeanPx = 0.003;
constexpr double kNoisyRmsPx = 0.035;

struct Plate {
  int rows, cols;
  double pitch_mm, diameter_mm;
};

struct Tally {
  int views = 0, views_found = 0, wrong_grids = 0;
  long spheres = 0, found = 0;
  int n = 0;
  double sum2 = 0;
  Eigen::Vector2d sum{0, 0};
  double worst = 0;
  void Add(const Eigen::Vector2d& e) {
    ++n;
    sum2 += e.squaredNorm();
    sum += e;
    worst = std::max(worst, e.norm());
  }
  double Rms() const { return std::sqrt(sum2 / (2.0 * std::max(n, 1))); }
};

// The grid's symmetries (rows x cols kept; transposes only for square grids): the detected ids
// are defined up to one of them.
std::vector<std::function<int(int, int)>> Symmetries(int rows, int cols) {
  std::vector<std::function<int(int, int)>> s;
  for (int k = 0; k < 8; ++k) {
    const bool transpose = k >= 4;
    if (transpose && rows != cols) continue;
    const bool flip_r = k & 1, flip_c = k & 2;
    s.push_back([=](int r, int c) {
      int rr = flip_r ? rows - 1 - r : r, cc = flip_c ? cols - 1 - c : c;
      if (transpose) std::swap(rr, cc);
      return rr * cols + cc;
    });
  }
  return s;
}

class RecallScenes {
 public:
  explicit RecallScenes(const cv::Mat& gain_1024) : gain_(gain_1024) {}

  // Renders view `index` of plate `plate` (everything drawn from `seed`); fills the truth.
  // `clean`: no noise, 5 x 5 supersampling (the systematic error); `anatomy`: the background.
  bool Render(const Plate& plate, uint64_t seed, bool clean, bool anatomy, cv::Mat* image,
              std::vector<Eigen::Vector2d>* truth_px, std::string* what) {
    std::mt19937_64 rng(seed);
    auto uni = [&rng](double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng); };
    Camera cam;
    cam.width = cam.height = 512;
    const double fx = uni(1800, 1900);
    cam.params = {fx, fx * uni(0.98, 1.02), 255.5 + uni(-6, 6), 255.5 + uni(-6, 6),
                  uni(-1.5, 1.5), 0, 0, 0, 0};
    sim::RenderOptions o;
    o.supersampling = clean ? 5 : 3;
    o.white_level = 50000;
    const double photons = uni(600, 2000);  // drawn either way: same scene with and without noise
    o.photons_per_pixel = clean ? 0 : photons;
    o.read_noise_gray = clean ? 0 : 150;
    o.blur_sigma_px = uni(0.6, 1.0);
    o.circular_fov = true;
    o.fov_radius_px = 250;
    o.fov_edge_px = 8;
    o.vignetting = uni(0.18, 0.26);
    o.heel = uni(0.06, 0.10);
    o.heel_direction_deg = uni(-180, 180);
    o.glare_fraction = uni(0.08, 0.18);
    o.glare_sigma_px = uni(40, 90);
    o.seed = seed;
    // The anatomy: a random 512 x 512 window of the frame at twice the size, random flips,
    // strength 0.35-0.6.
    const int x0 = static_cast<int>(uni(0, 512)), y0 = static_cast<int>(uni(0, 512));
    cv::Mat window = gain_(cv::Rect(x0, y0, 512, 512)).clone();
    const int flip = static_cast<int>(uni(0, 4));
    if (flip < 3) cv::flip(window, window, flip - 1);
    const double strength = anatomy ? uni(0.5, 0.9) : 0.0;
    o.background_gain = 1.0 - strength + strength * window;
    auto phantom = sim::MakePlatePhantom(
        sim::PlateSpec{plate.rows, plate.cols, plate.pitch_mm, plate.diameter_mm, 4.0, 8.0, "steel", "pmma"},
        sim::DefaultMaterials());
    if (!phantom.ok()) return *what = phantom.status().message(), false;
    // Pose: depth 550-790 mm, in-plane rotation any, tilt up to 35 degrees about a random axis,
    // either side of the plate towards the source; offsets redrawn until every sphere's disc is
    // inside the fully exposed field (radius - edge - 2 px).
    const Eigen::Vector3d centroid(0.5 * (plate.cols - 1) * plate.pitch_mm,
                                   0.5 * (plate.rows - 1) * plate.pitch_mm, 0);
    for (int attempt = 0; attempt < 200; ++attempt) {
      const double z = uni(550, 790);
      const double tilt = uni(0, 35) * M_PI / 180, axis = uni(0, 2 * M_PI);
      const Eigen::Matrix3d R =
          (Eigen::AngleAxisd(uni(0, 2 * M_PI), Eigen::Vector3d::UnitZ()) *
           Eigen::AngleAxisd(tilt, Eigen::Vector3d(std::cos(axis), std::sin(axis), 0)) *
           Eigen::AngleAxisd(uni(0, 1) < 0.5 ? 0.0 : M_PI, Eigen::Vector3d::UnitX()))
              .toRotationMatrix();
      const Eigen::Vector3d t(uni(-25, 25) * z / fx, uni(-25, 25) * z / fx, z);
      sim::PlacedPhantom placed{&*phantom, sim::Rigid3{R, t - R * centroid}};
      bool inside = true;
      std::vector<Eigen::Vector2d> uv;
      for (const auto& s : phantom->spheres) {
        const Eigen::Vector3d c = placed.cam_from_phantom * s.center_mm;
        double p[2] = {0, 0};
        if (!ProjectCamPoint(cam.params.data(), c.data(), p)) inside = false;
        const double r = sim::SphereImageRadius(cam, c, s.radius_mm, {p[0], p[1]});
        inside = inside && std::hypot(p[0] - 255.5, p[1] - 255.5) + r <= 250 - 8 - 2;
        uv.emplace_back(p[0], p[1]);
      }
      if (!inside) continue;
      auto gray = sim::RenderXray(cam, {placed}, o);
      if (!gray.ok()) return *what = gray.status().message(), false;
      *image = sim::ToOutputImage(*gray, 16);
      *truth_px = uv;
      return true;
    }
    return *what = "no pose with the plate inside the field of view", false;
  }

 private:
  cv::Mat gain_;
};

// Detects the view and adds it to the tally. Returns false on a wrong grid.
bool Score(const Plate& plate, const cv::Mat& image, const std::vector<Eigen::Vector2d>& truth,
           const std::string& label, Tally* t) {
  GridSpec g;
  g.rows = plate.rows;
  g.cols = plate.cols;
  g.spacing_mm = plate.pitch_mm;
  const GridDetection d = DetectGrid(image, g, DetectionOptions());
  ++t->views;
  t->spheres += static_cast<long>(truth.size());
  if (!d.found) {
    std::cout << "  " << label << ": not found: " << d.reason << "\n";
    return true;
  }
  ++t->views_found;
  // Nearest true centre of each point, then one symmetry explaining all ids.
  std::vector<int> truth_id(d.view.point_ids.size(), -1);
  bool wrong = false;
  for (size_t i = 0; i < d.view.uv_px.size(); ++i) {
    double best = 1e300;
    for (size_t k = 0; k < truth.size(); ++k) {
      const double e = (d.view.uv_px[i] - truth[k]).norm();
      if (e < best) best = e, truth_id[i] = static_cast<int>(k);
    }
    if (best > kWrongPointPx) wrong = true;
  }
  bool consistent = false;
  for (const auto& sym : Symmetries(plate.rows, plate.cols)) {
    bool all = true;
    for (size_t i = 0; i < truth_id.size() && all; ++i) {
      const int id = d.view.point_ids[i];
      all = sym(id / plate.cols, id % plate.cols) == truth_id[i];
    }
    consistent = consistent || all;
  }
  if (wrong || !consistent) {
    ++t->wrong_grids;
    std::cout << "  " << label << ": WRONG GRID (" << (wrong ? "a point off its sphere" : "ids")
              << ")\n";
    return false;
  }
  t->found += static_cast<long>(d.view.uv_px.size());
  if (d.view.uv_px.size() < truth.size()) {
    std::cout << "  " << label << ": " << d.view.uv_px.size() << " of " << truth.size()
              << " points\n";
  }
  for (size_t i = 0; i < d.view.uv_px.size(); ++i) t->Add(d.view.uv_px[i] - truth[truth_id[i]]);
  return true;
}

TEST(DetectionRecall, IntensifierEffectsAndAnatomy) {
  if (!std::filesystem::exists(kXaFrame)) GTEST_SKIP() << kXaFrame << " not installed";
  // The frame at twice the image size, strength 1 (gain = the frame's normalised level); each
  // view takes a window and its own strength.
  auto gain = sim::LoadBackgroundGain(kXaFrame, 1024, 1024, 1.0, 0.6);
  ASSERT_TRUE(gain.ok()) << gain.status().message();
  RecallScenes scenes(*gain);
  const std::vector<Plate> plates = {{6, 8, 15, 2.5}, {5, 5, 20, 3.06}, {6, 7, 15, 2.5}};
  // CARMBA_RECALL_VIEWS=N: N views per plate instead (a longer run by hand).
  const int kViewsPerPlate = std::getenv("CARMBA_RECALL_VIEWS") ? std::atoi(std::getenv("CARMBA_RECALL_VIEWS")) : 10;
  constexpr int kCleanViewsPerPlate = 3;
  // CARMBA_RECALL_SEED=S: other scenes (seeds S + 1000 p + v instead of 1000 p + v).
  const uint64_t seed_base = std::getenv("CARMBA_RECALL_SEED") ? std::atoll(std::getenv("CARMBA_RECALL_SEED")) : 0;
  Tally noisy, clean, flat;
  for (size_t p = 0; p < plates.size(); ++p) {
    const Plate& plate = plates[p];
    for (int v = 0; v < kViewsPerPlate; ++v) {
      const uint64_t seed = seed_base + 1000 * (p + 1) + v;
      const std::string label = std::to_string(plate.rows) + "x" + std::to_string(plate.cols) +
                                " seed " + std::to_string(seed);
      cv::Mat image;
      std::vector<Eigen::Vector2d> truth;
      std::string what;
      ASSERT_TRUE(scenes.Render(plate, seed, false, true, &image, &truth, &what)) << what;
      if (const char* dir = std::getenv("CARMBA_RECALL_DUMP")) {  // for looking at the views
        cv::Mat shown;
        cv::normalize(image, shown, 0, 255, cv::NORM_MINMAX, CV_8U);
        cv::imwrite(std::string(dir) + "/" + std::to_string(seed) + ".png", shown);
        cv::imwrite(std::string(dir) + "/" + std::to_string(seed) + "_16.png", image);
        std::ofstream tf(std::string(dir) + "/" + std::to_string(seed) + "_truth.txt");
        for (const auto& q : truth) tf << q.x() << " " << q.y() << "\n";
      }
      Score(plate, image, truth, label, &noisy);
      if (v < kCleanViewsPerPlate) {
        ASSERT_TRUE(scenes.Render(plate, seed, true, true, &image, &truth, &what)) << what;
        Score(plate, image, truth, label + " noise-free", &clean);
        ASSERT_TRUE(scenes.Render(plate, seed, true, false, &image, &truth, &what)) << what;
        Score(plate, image, truth, label + " noise-free, no anatomy", &flat);
      }
    }
  }
  const double recall = static_cast<double>(noisy.found) / noisy.spheres;
  const double clean_recall = static_cast<double>(clean.found) / clean.spheres;
  std::cout << "recall " << noisy.found << " / " << noisy.spheres << " = " << recall << " ("
            << noisy.views_found << " of " << noisy.views << " views), wrong grids "
            << noisy.wrong_grids << "; noise-free " << clean.found << " / " << clean.spheres
            << " = " << clean_recall << ", wrong grids " << clean.wrong_grids << "\n"
            << "accuracy as rendered: RMS " << noisy.Rms() << " px per coordinate, mean ("
            << noisy.sum.x() / std::max(noisy.n, 1) << ", " << noisy.sum.y() / std::max(noisy.n, 1)
            << "), max " << noisy.worst << " px\n"
            << "accuracy noise-free (5x5 rays): RMS " << clean.Rms() << " px, mean ("
            << clean.sum.x() / std::max(clean.n, 1) << ", " << clean.sum.y() / std::max(clean.n, 1)
            << "), max " << clean.worst << " px\n"
            << "accuracy noise-free, no anatomy: RMS " << flat.Rms() << " px, mean ("
            << flat.sum.x() / std::max(flat.n, 1) << ", " << flat.sum.y() / std::max(flat.n, 1)
            << "), max " << flat.worst << " px (" << flat.found << " / " << flat.spheres
            << " found)\n";
  EXPECT_GE(recall, kMinRecall);
  EXPECT_GE(clean_recall, kMinRecall);
  EXPECT_EQ(noisy.wrong_grids, 0);
  EXPECT_EQ(clean.wrong_grids, 0);
  EXPECT_EQ(flat.wrong_grids, 0);
  EXPECT_EQ(flat.found, flat.spheres);
  EXPECT_LT(flat.Rms(), kSystematicRmsPx);
  EXPECT_LT(clean.Rms(), kSystematicAnatomyRmsPx);
  for (const Tally* t : {&clean, &flat}) {
    EXPECT_LT(std::abs(t->sum.x() / std::max(t->n, 1)), kSystematicMeanPx);
    EXPECT_LT(std::abs(t->sum.y() / std::max(t->n, 1)), kSystematicMeanPx);
  }
  EXPECT_LT(noisy.Rms(), kNoisyRmsPx);
}

}  // namespace
}  // namespace carmba
