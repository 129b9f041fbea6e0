// Simulator speed: a 408 x 408 image of the thesis's 5x5 plate with 3x3 supersampling (target:
// < 0.5 s on one core, ray grid included), and with the 5x5 the shipped scene now uses (argument =
// supersampling). Run: build/tests/carmba_bench --benchmark_filter=Sim
#include <benchmark/benchmark.h>

#include <cstdlib>

#include "sim/xray_scene.h"

namespace {

carmba::sim::XrayScene ThesisCalibration(int supersampling) {
  static const carmba::sim::XrayScene* scene = [] {
    auto s = carmba::sim::LoadXrayScene(std::string(CARMBA_SOURCE_DIR) +
                                        "/configs/scenes/thesis_calibration.yaml");
    if (!s.ok()) std::abort();
    return new carmba::sim::XrayScene(*s);
  }();
  carmba::sim::XrayScene copy = *scene;
  copy.render.supersampling = supersampling;
  return copy;
}

// One image from scratch: ray grid (one UnprojectToNormalized per sub-pixel) + render + noise.
void BM_SimPlate408Cold(benchmark::State& state) {
  const auto scene = ThesisCalibration(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    auto view = carmba::sim::RenderXrayView(scene, 0, nullptr);
    if (!view.ok()) state.SkipWithError(view.status().message().c_str());
    benchmark::DoNotOptimize(view->image.data);
  }
}
BENCHMARK(BM_SimPlate408Cold)->Arg(3)->Arg(5)->Unit(benchmark::kMillisecond);

// Per further view of a scene: the ray grid is shared.
void BM_SimPlate408SharedGrid(benchmark::State& state) {
  const auto scene = ThesisCalibration(static_cast<int>(state.range(0)));
  auto grid = carmba::sim::RayGrid::Build(scene.camera, scene.render);
  if (!grid.ok()) std::abort();
  int i = 0;
  for (auto _ : state) {
    auto view = carmba::sim::RenderXrayView(scene, i++ % 20, grid->get());
    if (!view.ok()) state.SkipWithError(view.status().message().c_str());
    benchmark::DoNotOptimize(view->image.data);
  }
}
BENCHMARK(BM_SimPlate408SharedGrid)->Arg(3)->Arg(5)->Unit(benchmark::kMillisecond);

void BM_SimRayGrid408(benchmark::State& state) {
  const auto scene = ThesisCalibration(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    auto grid = carmba::sim::RayGrid::Build(scene.camera, scene.render);
    benchmark::DoNotOptimize(grid.ok());
  }
}
BENCHMARK(BM_SimRayGrid408)->Arg(3)->Arg(5)->Unit(benchmark::kMillisecond);

}  // namespace
