// Sphere-centre accuracy next to anatomical edges (issue 12): seeded views of the recall scenes
// (recall_scenes.h: intensifier fall-off, heel, glare, several plates, depths and tilts) over a
// SHARP anatomical background (the XA frame at ~1.1 x the image size instead of the recall test's
// 2 x), rendered noise-free (5 x 5 rays: the systematic error) and with noise. Each found centre's
// error against the truth is related to the background around its sphere: the anatomy's gain
// over the detector's disc and ring (radius 1.5 r + 5 px), fitted by a plane; its residual RMS
// relative to the level ("non-planarity": what a local plane cannot follow, e.g. a bone edge)
// bins the errors.
// The errors are also binned by the detector's own flag (GridDetection::background_shift_px).
// By hand: CARMBA_EDGE_VIEWS=N views per plate (default 4), CARMBA_EDGE_SEED=S other scenes,
// CARMBA_EDGE_WORST=1 prints the worst points.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iomanip>
#include <iostream>

#include "detect/recall_scenes.h"
#include "figures.h"
#include "test_env.h"

namespace carmba {
namespace {

using namespace recall_scenes;

// Bounds, with margin over what was measured (default run: see the test's end; the README's
// detection section has the 30-view figures).
constexpr double kMaxErrorPx = 0.15;  // any point, noise-free or as rendered
constexpr double kCleanRmsPx = 0.025;  // per coordinate, noise-free
constexpr double kNoisyRmsPx = 0.032;  // per coordinate, as rendered
constexpr double kRoughRmsPx = 0.05;   // noise-free, background non-planarity >= 2 %
constexpr double kMinFound = 0.97;     // found / spheres (sharp anatomy drops a few)

// The background's non-planarity around a sphere (see the top).
double NonPlanarity(const cv::Mat& gain, const Eigen::Vector2d& c, double r) {
  const double R = 1.5 * r + 5.0;
  double s1 = 0, sx = 0, sy = 0, sxx = 0, sxy = 0, syy = 0, sv = 0, sxv = 0, syv = 0;
  std::vector<cv::Vec3d> px;
  for (int y = static_cast<int>(std::floor(c.y() - R)); y <= static_cast<int>(std::ceil(c.y() + R));
       ++y) {
    for (int x = static_cast<int>(std::floor(c.x() - R));
         x <= static_cast<int>(std::ceil(c.x() + R));
         ++x) {
      if (x < 0 || y < 0 || x >= gain.cols || y >= gain.rows) continue;
      const double dx = x - c.x(), dy = y - c.y();
      if (dx * dx + dy * dy > R * R) continue;
      const double v = gain.at<float>(y, x);
      px.emplace_back(dx, dy, v);
      s1 += 1, sx += dx, sy += dy, sxx += dx * dx, sxy += dx * dy, syy += dy * dy;
      sv += v, sxv += dx * v, syv += dy * v;
    }
  }
  cv::Vec3d p;
  if (!cv::solve(cv::Matx33d(s1, sx, sy, sx, sxx, sxy, sy, sxy, syy), cv::Vec3d(sv, sxv, syv), p,
                 cv::DECOMP_CHOLESKY)) {
    return 0;
  }
  double ss = 0;
  for (const cv::Vec3d& q : px) ss += std::pow(q[2] - (p[0] + p[1] * q[0] + p[2] * q[1]), 2);
  return std::sqrt(ss / px.size()) / p[0];
}

// Errors binned by the background's non-planarity.
struct Bins {
  static constexpr double kEdges[] = {0.0, 0.005, 0.01, 0.02, 0.04, 1e9};
  static constexpr int kNum = 5;
  RecallTally t[kNum];
  void Add(double nonplanar, const Eigen::Vector2d& e) {
    int b = 0;
    while (b + 1 < kNum && nonplanar >= kEdges[b + 1]) ++b;
    t[b].Add(e);
  }
  void Print(const std::string& what) const {
    std::cout << what << " (by the background's non-planarity):\n";
    for (int b = 0; b < kNum; ++b) {
      std::cout << "  " << std::setw(5) << 100 * kEdges[b] << " .. " << std::setw(5)
                << (b + 1 < kNum ? std::to_string(100 * kEdges[b + 1]).substr(0, 4) : "inf")
                << " %: " << std::setw(5) << t[b].n << " points, RMS " << std::setprecision(4)
                << t[b].Rms() << " px, mean (" << t[b].Mean().x() << ", " << t[b].Mean().y()
                << "), max " << t[b].worst << " px\n";
    }
  }
};

struct RunStats {
  RecallTally all;
  Bins bins;
  int over_02 = 0, over_05 = 0;
  std::vector<std::pair<double, double>> shift_vs_error;  // (background_shift_px, |error|)
  // The errors binned by the detector's own flag, the core / whole-blob centroid distance.
  void PrintByShift(const std::string& what) const {
    std::cout << what << " (by the core / whole-blob centroid distance):\n";
    const double edges[] = {0, 0.02, 0.04, 0.06, 0.1};
    for (int b = 0; b < 4; ++b) {
      int n = 0;
      double s2 = 0, worst = 0;
      for (const auto& [shift, e] : shift_vs_error) {
        if (shift < edges[b] || shift >= edges[b + 1]) continue;
        ++n, s2 += e * e, worst = std::max(worst, e);
      }
      std::cout << "  " << edges[b] << " .. " << edges[b + 1] << " px: " << n << " points, RMS "
                << std::sqrt(s2 / (2.0 * std::max(n, 1))) << " px, max " << worst << " px\n";
    }
  }
};

TEST(EdgeAccuracy, CentresNextToSharpAnatomy) {
  if (!std::filesystem::exists(kXaFrame)) GTEST_SKIP() << kXaFrame << " not installed";
  auto gain = sim::LoadBackgroundGain(kXaFrame, 560, 560, 1.0, 0.6);
  ASSERT_TRUE(gain.ok()) << gain.status().message();
  RecallScenes scenes(*gain);
  const std::vector<Plate> plates = {{6, 8, 15, 2.5}, {5, 5, 20, 3.06}, {6, 7, 15, 2.5}};
  const int views = testing::EnvOr("CARMBA_EDGE_VIEWS", 4);
  const uint64_t seed_base = testing::EnvOr<uint64_t>("CARMBA_EDGE_SEED", 70000);
  const bool print_worst = std::getenv("CARMBA_EDGE_WORST") != nullptr;
  RunStats clean, noisy;
  for (size_t p = 0; p < plates.size(); ++p) {
    for (int v = 0; v < views; ++v) {
      const uint64_t seed = seed_base + 1000 * (p + 1) + v;
      for (bool is_clean : {true, false}) {
        RunStats& run = is_clean ? clean : noisy;
        cv::Mat image;
        SceneTruth truth;
        std::string what;
        ASSERT_TRUE(scenes.Render(plates[p], seed, is_clean, true, &image, &truth, &what)) << what;
        std::vector<Matched> matched;
        const std::string label = "seed " + std::to_string(seed) + (is_clean ? " noise-free" : "");
        const GridDetection d =
            Score(plates[p], image, truth.centres_px, label, &run.all, &matched);
        for (size_t i = 0; i < matched.size(); ++i) {
          const Matched& m = matched[i];
          run.shift_vs_error.emplace_back(d.background_shift_px[i], m.error_px.norm());
          const double np = NonPlanarity(truth.background_gain, truth.centres_px[m.truth_index],
                                         truth.radius_px[m.truth_index]);
          run.bins.Add(np, m.error_px);
          run.over_02 += m.error_px.norm() > 0.2;
          run.over_05 += m.error_px.norm() > 0.5;
          if (print_worst && m.error_px.norm() > 0.1) {
            std::cout << "  " << label << " sphere " << m.truth_index << " at ("
                      << truth.centres_px[m.truth_index].transpose() << "): error "
                      << m.error_px.norm() << " px, non-planarity " << 100 * np << " %\n";
          }
        }
      }
    }
  }
  for (const RunStats* r : {&clean, &noisy}) {
    std::cout << (r == &clean ? "noise-free" : "as rendered") << ": " << r->all.found << " / "
              << r->all.spheres << " found, wrong grids " << r->all.wrong_grids << ", RMS "
              << r->all.Rms() << " px per coordinate, mean (" << r->all.Mean().transpose()
              << "), max " << r->all.worst << " px, " << r->over_02 << " over 0.2 px, "
              << r->over_05 << " over 0.5 px\n";
    r->bins.Print(r == &clean ? "noise-free" : "as rendered");
  }
  for (const RunStats* r : {&clean, &noisy})
    r->PrintByShift(r == &clean ? "noise-free" : "as rendered");
  // Bounds (default run, 4 views per plate). Before the core centroid (issue 12) this run had a
  // point 1.8 px off (a wrong grid by the recall test's definition), noise-free max 0.50 px and
  // 0.20 px RMS over the points with >= 4 % non-planarity; now max ~0.1 px.
  EXPECT_EQ(clean.all.wrong_grids, 0);
  EXPECT_EQ(noisy.all.wrong_grids, 0);
  EXPECT_LT(clean.all.worst, kMaxErrorPx);
  EXPECT_LT(noisy.all.worst, kMaxErrorPx);
  EXPECT_LT(clean.all.Rms(), kCleanRmsPx);
  EXPECT_LT(noisy.all.Rms(), kNoisyRmsPx);
  RecallTally rough;  // noise-free, non-planarity >= 2 %
  for (int b = 3; b < Bins::kNum; ++b) {
    rough.n += clean.bins.t[b].n;
    rough.sum2 += clean.bins.t[b].sum2;
  }
  EXPECT_LT(rough.Rms(), kRoughRmsPx) << rough.n << " points";
  testing::RecordFigure("edge.clean",
                        "%.3f px RMS per coordinate, worst %.3f px, points with >= 4 %% "
                        "background non-planarity %.3f px RMS",
                        clean.all.Rms(),
                        clean.all.worst,
                        clean.bins.t[Bins::kNum - 1].Rms());
  testing::RecordFigure("edge.noisy",
                        "%.3f px RMS, worst %.3f px; %ld / %ld spheres of %d views kept",
                        noisy.all.Rms(),
                        noisy.all.worst,
                        noisy.all.found,
                        noisy.all.spheres,
                        noisy.all.views);
  // The points dropped as unreliable stay few (recall).
  EXPECT_GE(clean.all.found, kMinFound * clean.all.spheres);
  EXPECT_GE(noisy.all.found, kMinFound * noisy.all.spheres);
}

}  // namespace
}  // namespace carmba
