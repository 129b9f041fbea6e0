// Grid detection per image on the shipped simulator scenes (the target: under 10 ms per
// 408 x 408 image): 5x5 plate, 408 x 408, 8 bit; 6x7 plate, 512 x 512, 16 bit.
#include <benchmark/benchmark.h>

#include <map>
#include <string>
#include <vector>

#include "detect/grid_detector.h"
#include "sim/xray_scene.h"

namespace {

struct SceneImages {
  carmba::GridSpec grid;
  std::vector<cv::Mat> images;
};

const SceneImages& Images(const std::string& name) {
  static std::map<std::string, SceneImages> cache;
  auto it = cache.find(name);
  if (it != cache.end()) return it->second;
  SceneImages& s = cache[name];
  auto scene = carmba::sim::LoadXrayScene(std::string(CARMBA_SOURCE_DIR) + "/configs/scenes/" +
                                          name + ".yaml");
  if (!scene.ok()) return s;
  s.grid.rows = scene->plate.rows;
  s.grid.cols = scene->plate.cols;
  s.grid.spacing_mm = scene->plate.pitch_mm;
  auto grid = carmba::sim::RayGrid::Build(scene->camera, scene->render);
  for (int i = 0; i < 8 && i < static_cast<int>(scene->views.size()); ++i) {
    auto v = carmba::sim::RenderXrayView(*scene, i, grid->get());
    if (v.ok()) s.images.push_back(v->image);
  }
  return s;
}

void DetectScene(benchmark::State& state, const std::string& name) {
  const SceneImages& s = Images(name);
  if (s.images.empty()) {
    state.SkipWithError("scene did not render");
    return;
  }
  size_t i = 0;
  int found = 0;
  for (auto _ : state) {
    carmba::GridDetection d = carmba::DetectGrid(s.images[i++ % s.images.size()], s.grid,
                                                 carmba::DetectionOptions());
    found += d.found;
    benchmark::DoNotOptimize(d);
  }
  state.counters["found"] = benchmark::Counter(found, benchmark::Counter::kAvgIterations);
}

void BM_DetectThesis408x408(benchmark::State& state) { DetectScene(state, "thesis_calibration"); }
void BM_DetectPincushion512x512x16bit(benchmark::State& state) {
  DetectScene(state, "calib_7x6_pincushion");
}

}  // namespace

BENCHMARK(BM_DetectThesis408x408)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DetectPincushion512x512x16bit)->Unit(benchmark::kMillisecond);
