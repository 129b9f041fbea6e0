// The bare cost of one pose-study run without the study runner: make a synthetic problem of the
// thesis object (5 views, 9 markers) and solve it with POSIT + bundle adjustment + covariance,
// single-threaded. Compare its time per iteration with `carmba study` on a study of such runs:
// the runner's overhead is the study's wall time x jobs minus the runs' summed times (printed by
// `carmba study` as "runner overhead"), and the per-run gap between a run's time and this bare
// solve is the run function's own work (truth metrics, residuals, JSON).
//
//   build/tests/carmba_bench --benchmark_filter=StudyBareSolve
#include <benchmark/benchmark.h>

#include "problem/pose_solver.h"
#include "synthetic/synthetic_pose.h"

namespace carmba {
namespace {

void BM_StudyBareSolve(benchmark::State& state) {
  StatusOr<Camera> camera = ReadCameraJson(std::string(CARMBA_SOURCE_DIR) +
                                           "/data/thesis/camera.json");
  if (!camera.ok()) {
    state.SkipWithError(camera.status().message().c_str());
    return;
  }
  SyntheticPoseSpec spec;
  spec.camera = *camera;
  spec.markers = ThesisMarkers();
  SolverConfig config;
  config.initializer = Initializer::kPosit;
  config.num_threads = 1;
  uint64_t seed = 0;
  for (auto _ : state) {
    const Problem problem = MakeSyntheticPoseProblem(spec, 0.5, 0.1, ++seed);
    StatusOr<PoseSolution> solution = SolvePoseProblem(problem, config);
    if (!solution.ok()) {
      state.SkipWithError(solution.status().message().c_str());
      return;
    }
    benchmark::DoNotOptimize(solution->ba_result->rms_object_px);
  }
}
BENCHMARK(BM_StudyBareSolve)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace carmba
