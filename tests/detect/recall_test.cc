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

#include "detect/recall_scenes.h"
#include "figures.h"
#include "test_env.h"
#include "util/image_codecs.h"

namespace carmba {
namespace {

using namespace recall_scenes;

// The target.
constexpr double kMinRecall = 0.995;
// Accuracy bounds. Without the anatomy (fall-off, heel, glare only) the systematic error is the
// shipped scenes' (README: ~0.004 px RMS; measured here 0.0034): bound 0.006 as in
// simulated_scene_test.cc. The anatomy adds structure inside the background ring that its plane
// does not follow: measured 0.012 px RMS, max 0.056 px (before and after the recall changes;
// 0.015 px, max 0.18 px on the scenes of CARMBA_RECALL_SEED=50000), bound 0.02. With noise
// (600-2000 quanta per pixel) measured 0.027 px RMS.
constexpr double kSystematicRmsPx = 0.006;
constexpr double kSystematicAnatomyRmsPx = 0.02;
constexpr double kSystematicMeanPx = 0.003;
constexpr double kRecallNoisyRmsPx = 0.035;

TEST(DetectionRecall, IntensifierEffectsAndAnatomy) {
  if (!std::filesystem::exists(kXaFrame)) GTEST_SKIP() << kXaFrame << " not installed";
  // The frame at twice the image size, strength 1 (gain = the frame's normalised level); each
  // view takes a window and its own strength.
  auto gain = sim::LoadBackgroundGain(kXaFrame, 1024, 1024, 1.0, 0.6);
  ASSERT_TRUE(gain.ok()) << gain.status().message();
  RecallScenes scenes(*gain);
  const std::vector<Plate> plates = {{6, 8, 15, 2.5}, {5, 5, 20, 3.06}, {6, 7, 15, 2.5}};
  // CARMBA_RECALL_VIEWS=N: N views per plate instead (a longer run by hand).
  const int kViewsPerPlate = testing::EnvOr("CARMBA_RECALL_VIEWS", 10);
  constexpr int kCleanViewsPerPlate = 3;
  // CARMBA_RECALL_SEED=S: other scenes (seeds S + 1000 p + v instead of 1000 p + v).
  const uint64_t seed_base = testing::EnvOr<uint64_t>("CARMBA_RECALL_SEED", 0);
  RecallTally noisy, clean, flat;
  for (size_t p = 0; p < plates.size(); ++p) {
    const Plate& plate = plates[p];
    for (int v = 0; v < kViewsPerPlate; ++v) {
      const uint64_t seed = seed_base + 1000 * (p + 1) + v;
      const std::string label = std::to_string(plate.rows) + "x" + std::to_string(plate.cols) +
                                " seed " + std::to_string(seed);
      cv::Mat image;
      SceneTruth truth;
      std::string what;
      ASSERT_TRUE(scenes.Render(plate, seed, false, true, &image, &truth, &what)) << what;
      if (const char* dir = std::getenv("CARMBA_RECALL_DUMP")) {  // for looking at the views
        cv::Mat shown;
        cv::normalize(image, shown, 0, 255, cv::NORM_MINMAX, CV_8U);
        carmba::ImWrite(std::string(dir) + "/" + std::to_string(seed) + ".png", shown);
        carmba::ImWrite(std::string(dir) + "/" + std::to_string(seed) + "_16.png", image);
        std::ofstream tf(std::string(dir) + "/" + std::to_string(seed) + "_truth.txt");
        for (const auto& q : truth.centres_px) tf << q.x() << " " << q.y() << "\n";
      }
      Score(plate, image, truth.centres_px, label, &noisy);
      if (v < kCleanViewsPerPlate) {
        ASSERT_TRUE(scenes.Render(plate, seed, true, true, &image, &truth, &what)) << what;
        Score(plate, image, truth.centres_px, label + " noise-free", &clean);
        ASSERT_TRUE(scenes.Render(plate, seed, true, false, &image, &truth, &what)) << what;
        Score(plate, image, truth.centres_px, label + " noise-free, no anatomy", &flat);
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
  testing::RecordFigure("detrecall.found",
                        "%ld / %ld spheres of %d views, %d wrong grids",
                        noisy.found,
                        noisy.spheres,
                        noisy.views,
                        noisy.wrong_grids);
  testing::RecordFigure("detrecall.systematic",
                        "%.3f px RMS without the anatomy, %.3f px with it",
                        flat.Rms(),
                        clean.Rms());
  EXPECT_GE(recall, kMinRecall);
  EXPECT_GE(clean_recall, kMinRecall);
  EXPECT_EQ(noisy.wrong_grids, 0);
  EXPECT_EQ(clean.wrong_grids, 0);
  EXPECT_EQ(flat.wrong_grids, 0);
  EXPECT_EQ(flat.found, flat.spheres);
  EXPECT_LT(flat.Rms(), kSystematicRmsPx);
  EXPECT_LT(clean.Rms(), kSystematicAnatomyRmsPx);
  for (const RecallTally* t : {&clean, &flat}) {
    EXPECT_LT(std::abs(t->sum.x() / std::max(t->n, 1)), kSystematicMeanPx);
    EXPECT_LT(std::abs(t->sum.y() / std::max(t->n, 1)), kSystematicMeanPx);
  }
  EXPECT_LT(noisy.Rms(), kRecallNoisyRmsPx);
}

}  // namespace
}  // namespace carmba
