// Seeded, randomised X-ray views of calibration plates with the image intensifier's effects
// (issue 12): a smooth quadratic fall-off towards the rim, a heel-effect gradient, veiling glare
// and a real anatomical background (a window of the XA frame of GDCM's examples), 16-bit
// 512 x 512 images, plates 550-790 mm from the source (fx ~1850 px), tilted up to 35 degrees.
// Every view keeps all spheres inside the fully exposed field of view. Shared by the recall test
// (recall_test.cc) and the accuracy-near-anatomy test (edge_accuracy_test.cc); scoring against
// the truth up to the grid's symmetries (Score).
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <iostream>
#include <memory>
#include <opencv2/core.hpp>
#include <random>
#include <string>
#include <vector>

#include "camera/camera_model.h"
#include "detect/grid_detector.h"
#include "sim/phantom.h"
#include "sim/xray_render.h"

namespace carmba::recall_scenes {

inline const char* kXaFrame = "/usr/share/doc/libgdcm3.0/examples/00191113.dcm";

// A found point further than this from its true centre is a wrong blob (the scatter is ~0.02 px).
constexpr double kWrongPointPx = 1.0;

struct Plate {
  int rows, cols;
  double pitch_mm, diameter_mm;
};

struct RecallTally {
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
  Eigen::Vector2d Mean() const { return sum / std::max(n, 1); }
};

// The grid's symmetries (rows x cols kept; transposes only for square grids): the detected ids
// are defined up to one of them.
inline std::vector<std::function<int(int, int)>> Symmetries(int rows, int cols) {
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

// What a view was rendered with, besides its image (for relating errors to the background).
struct SceneTruth {
  std::vector<Eigen::Vector2d> centres_px;  // projected sphere centres
  std::vector<double> radius_px;            // the spheres' image radii
  cv::Mat background_gain;                  // the anatomy's multiplicative gain (CV_32F)
};

class RecallScenes {
 public:
  // `gain`: the anatomy frame as a gain of strength 1, at least 512 x 512; each view takes a
  // random 512 x 512 window of it (a frame loaded at 1024 x 1024: the anatomy at twice the size).
  explicit RecallScenes(const cv::Mat& gain) : gain_(gain) {}

  // Renders view `seed` of `plate` (everything drawn from `seed`); fills the truth.
  // `clean`: no noise, 5 x 5 supersampling (the systematic error); `anatomy`: the background.
  bool Render(const Plate& plate, uint64_t seed, bool clean, bool anatomy, cv::Mat* image,
              SceneTruth* truth, std::string* what) const {
    std::mt19937_64 rng(seed);
    auto uni = [&rng](double a, double b) {
      return std::uniform_real_distribution<double>(a, b)(rng);
    };
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
    // The anatomy: a random 512 x 512 window of the frame, random flips, strength 0.35-0.6.
    const int x0 = static_cast<int>(uni(0, gain_.cols - 512)),
              y0 = static_cast<int>(uni(0, gain_.rows - 512));
    cv::Mat window = gain_(cv::Rect(x0, y0, 512, 512)).clone();
    const int flip = static_cast<int>(uni(0, 4));
    if (flip < 3) cv::flip(window, window, flip - 1);
    const double strength = anatomy ? uni(0.5, 0.9) : 0.0;
    o.background_gain = 1.0 - strength + strength * window;
    auto phantom = sim::MakePlatePhantom(
        sim::PlateSpec{
            plate.rows, plate.cols, plate.pitch_mm, plate.diameter_mm, 4.0, 8.0, "steel", "pmma"},
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
      sim::PlacedPhantom placed{&*phantom, Rigid3{R, t - R * centroid}};
      bool inside = true;
      SceneTruth st;
      for (const auto& s : phantom->spheres) {
        const Eigen::Vector3d c = placed.cam_from_phantom * s.center_mm;
        double p[2] = {0, 0};
        if (!ProjectCamPoint(cam.params.data(), c.data(), p)) inside = false;
        const double r = sim::SphereImageRadius(cam, c, s.radius_mm, {p[0], p[1]});
        inside = inside && std::hypot(p[0] - 255.5, p[1] - 255.5) + r <= 250 - 8 - 2;
        st.centres_px.emplace_back(p[0], p[1]);
        st.radius_px.push_back(r);
      }
      if (!inside) continue;
      // The same seed re-rendered (with and without the anatomy) has the same camera and rays.
      if (!grid_ || !grid_->Matches(cam, o)) {
        auto built = sim::RayGrid::Build(cam, o);
        if (!built.ok()) return *what = built.status().message(), false;
        grid_ = *built;
      }
      auto gray = sim::RenderXray(cam, {placed}, o, grid_.get());
      if (!gray.ok()) return *what = gray.status().message(), false;
      *image = sim::ToOutputImage(*gray, 16);
      st.background_gain = o.background_gain;
      *truth = std::move(st);
      return true;
    }
    return *what = "no pose with the plate inside the field of view", false;
  }

 private:
  cv::Mat gain_;
  mutable std::shared_ptr<const sim::RayGrid> grid_;  // the last view's rays
};

// A detected point matched to its sphere: the index into the truth and the error (detected -
// true, px).
struct Matched {
  int truth_index;
  Eigen::Vector2d error_px;
};

// Detects the view and adds it to the tally (and its points to `matched`, optional). Returns the
// detection; a wrong grid (a point off its sphere, or ids no symmetry explains) is counted in
// `t->wrong_grids` and adds no points.
inline GridDetection Score(const Plate& plate, const cv::Mat& image,
                           const std::vector<Eigen::Vector2d>& truth, const std::string& label,
                           RecallTally* t, std::vector<Matched>* matched = nullptr) {
  GridSpec g;
  g.rows = plate.rows;
  g.cols = plate.cols;
  g.spacing_mm = plate.pitch_mm;
  const GridDetection d = DetectGrid(image, g, DetectionOptions());
  ++t->views;
  t->spheres += static_cast<long>(truth.size());
  if (!d.found) {
    std::cout << "  " << label << ": not found: " << d.reason << "\n";
    return d;
  }
  ++t->views_found;
  // Nearest true centre of each point, then one symmetry explaining all ids.
  std::vector<int> truth_id(d.view.point_ids.size(), -1);
  bool wrong = false;
  double worst = 0;
  Eigen::Vector2d worst_at(0, 0);
  for (size_t i = 0; i < d.view.uv_px.size(); ++i) {
    double best = 1e300;
    for (size_t k = 0; k < truth.size(); ++k) {
      const double e = (d.view.uv_px[i] - truth[k]).norm();
      if (e < best) best = e, truth_id[i] = static_cast<int>(k);
    }
    if (best > kWrongPointPx) wrong = true;
    if (best > worst) worst = best, worst_at = d.view.uv_px[i];
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
    std::cout << "  " << label << ": WRONG GRID ("
              << (wrong
                      ? "a point off its sphere: " + std::to_string(worst) + " px at (" +
                            std::to_string(worst_at.x()) + ", " + std::to_string(worst_at.y()) + ")"
                      : std::string("ids"))
              << ")\n";
    return d;
  }
  t->found += static_cast<long>(d.view.uv_px.size());
  if (d.view.uv_px.size() < truth.size()) {
    std::cout << "  " << label << ": " << d.view.uv_px.size() << " of " << truth.size()
              << " points\n";
  }
  for (size_t i = 0; i < d.view.uv_px.size(); ++i) {
    const Eigen::Vector2d e = d.view.uv_px[i] - truth[truth_id[i]];
    t->Add(e);
    if (matched) matched->push_back({truth_id[i], e});
  }
  return d;
}

}  // namespace carmba::recall_scenes
