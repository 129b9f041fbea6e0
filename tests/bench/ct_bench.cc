// CT benchmarks (issue 3 and 5): simulating a 512 x 512 x 120 thesis_ct series (voxelisation,
// noise, DICOM writing) and reading + segmenting it (GDCM reading of 120 files, threshold,
// components, centres). Single-threaded code: one core.
//   carmba_bench --benchmark_filter=Ct
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <filesystem>

#include "ct/ct_simulate.h"
#include "ct/ct_volume.h"
#include "ct/marker_detection.h"
#include "scratch.h"

namespace {

namespace fs = std::filesystem;

std::string ScenePath() {
  return std::string(CARMBA_SOURCE_DIR) + "/configs/scenes/thesis_ct.yaml";
}

// `name` (not created) in this process's scratch directory (removed at exit).
std::string BenchDir(const char* name) {
  static const carmba::test::ScratchDir dir("bench");
  return dir.File(name);
}

void BM_CtSimulateThesis512x512x120(benchmark::State& state) {
  const std::string dir = BenchDir("ctsim");
  for (auto _ : state) {
    state.PauseTiming();
    fs::remove_all(dir);
    carmba::YamlMap scene = carmba::YamlMap::Load(ScenePath());
    nlohmann::json truth;
    state.ResumeTiming();
    const carmba::Status s = carmba::SimulateCtScene(scene, dir, &truth);
    if (!s.ok()) state.SkipWithError(s.message().c_str());
  }
  fs::remove_all(dir);
}
BENCHMARK(BM_CtSimulateThesis512x512x120)->Unit(benchmark::kMillisecond)->Iterations(3);

void BM_CtReadAndSegmentThesis512x512x120(benchmark::State& state) {
  const std::string dir = BenchDir("ctread");
  fs::remove_all(dir);
  carmba::YamlMap scene = carmba::YamlMap::Load(ScenePath());
  nlohmann::json truth;
  const carmba::Status s = carmba::SimulateCtScene(scene, dir, &truth);
  if (!s.ok()) {
    state.SkipWithError(s.message().c_str());
    return;
  }
  carmba::MarkerDetectionOptions opt;
  opt.expected_count = 9;
  for (auto _ : state) {
    auto volume = carmba::ReadCtSeries(dir + "/ct");
    if (!volume.ok()) {
      state.SkipWithError(volume.status().message().c_str());
      break;
    }
    auto det = carmba::DetectMarkers(*volume, opt);
    if (!det.ok()) {
      state.SkipWithError(det.status().message().c_str());
      break;
    }
    benchmark::DoNotOptimize(det->markers.size());
  }
  fs::remove_all(dir);
}
BENCHMARK(BM_CtReadAndSegmentThesis512x512x120)->Unit(benchmark::kMillisecond)->Iterations(5);

}  // namespace
