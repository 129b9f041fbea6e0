// Pose benchmarks: one view's POSIT + bundle adjustment + covariance, 4 and 9 markers, analytic
// vs autodiff Jacobians. Run: build/tests/carmba_bench --benchmark_filter=Pose
#include <benchmark/benchmark.h>

#include <memory>

#include "ba/reprojection_error.h"
#include "problem/pose_solver.h"
#include "synthetic/synthetic_pose.h"

namespace carmba {
namespace {

Problem OneViewProblem(int num_markers) {
  SyntheticPoseSpec spec;
  spec.camera.width = spec.camera.height = 408;
  spec.camera.params = {2061.389, 2254.646, 203.655, 205.117, -0.2, 0.05, 1e-3, -1e-3, 0};
  spec.markers = ThesisMarkers();
  if (num_markers == 4) spec.markers = {spec.markers[2], spec.markers[3], spec.markers[6],
                                        spec.markers[7]};  // the thesis's markers 3, 4, 7, 8
  spec.view_angles_deg = {30};
  spec.pairs.clear();
  return MakeSyntheticPoseProblem(spec, 0.5, 0.2, 7);
}

void BM_PoseOneView(benchmark::State& state) {
  const Problem p = OneViewProblem(static_cast<int>(state.range(0)));
  SolverConfig c;
  c.analytic_jacobians = state.range(1) == 1;
  const ba::CovarianceAlgorithm algos[4] = {ba::CovarianceAlgorithm::kDenseSvd,
                                            ba::CovarianceAlgorithm::kSparseQr,
                                            ba::CovarianceAlgorithm::kEigenSparseQr,
                                            ba::CovarianceAlgorithm::kSchur};
  c.covariance_algorithm = algos[state.range(2)];
  const char* solvers[3] = {"dense_schur", "dense_qr", "dense_normal_cholesky"};
  c.linear_solver = solvers[state.range(3)];
  int iterations = 0;
  for (auto _ : state) {
    auto s = SolvePoseProblem(p, c);
    if (!s.ok() || !s->has_covariance) state.SkipWithError("solve failed");
    iterations = s.ok() ? s->ba_result->iterations : -1;
    benchmark::DoNotOptimize(s);
  }
  state.counters["lm_iterations"] = iterations;
  state.SetLabel(std::string(c.analytic_jacobians ? "analytic" : "autodiff") + ", " +
                 std::to_string(state.range(0)) + " markers, " +
                 NameOf(ba::kCovarianceAlgorithmNames, c.covariance_algorithm) + ", " +
                 c.linear_solver);
}
BENCHMARK(BM_PoseOneView)
    // markers, analytic (1) / autodiff (0), covariance (0 dense_svd, 1 sparse_qr,
    // 2 eigen_sparse_qr, 3 schur = the default), linear solver (0 dense_schur = the default,
    // 1 dense_qr, 2 dense_normal_cholesky)
    ->Args({4, 1, 3, 0})
    ->Args({4, 0, 3, 0})
    ->Args({9, 1, 3, 0})
    ->Args({9, 0, 3, 0})
    ->Args({9, 1, 0, 0})
    ->Args({9, 1, 1, 0})
    ->Args({9, 1, 2, 0})
    ->Args({9, 0, 2, 0})
    ->Args({9, 1, 3, 1})
    ->Args({9, 1, 3, 2})
    ->Args({9, 0, 3, 2})
->Unit(benchmark::kMicrosecond);

// One reprojection residual with its three Jacobian blocks: analytic vs autodiff.
void BM_ReprojectionResidual(benchmark::State& state) {
  const double intrinsics[9] = {2061.389, 2254.646, 203.655, 205.117, -0.2, 0.05, 1e-3, -1e-3, 0};
  const double pose[6] = {0.3, -0.4, 0.2, 10, -20, 700};
  const double point[3] = {-58.85, 1, 14};
  const double* params[3] = {pose, point, intrinsics};
  double r[2], J0[12], J1[6], J2[18];
  double* jac[3] = {J0, J1, J2};
  std::unique_ptr<ceres::CostFunction> cost(
      state.range(0) == 1 ? ReprojectionError::Create(200, 210, 0.5)
                          : ReprojectionErrorAutoDiff::Create(200, 210, 0.5));
  for (auto _ : state) {
    cost->Evaluate(params, r, jac);
    benchmark::DoNotOptimize(J2[17]);
  }
  state.SetLabel(state.range(0) == 1 ? "analytic" : "autodiff");
}
BENCHMARK(BM_ReprojectionResidual)->Arg(1)->Arg(0);

// The five-view thesis-like problem (9 markers).
void BM_PoseFiveViews(benchmark::State& state) {
  SyntheticPoseSpec spec;
  spec.camera.width = spec.camera.height = 408;
  spec.camera.params = {2061.389, 2254.646, 203.655, 205.117, -0.2, 0.05, 1e-3, -1e-3, 0};
  spec.markers = ThesisMarkers();
  const Problem p = MakeSyntheticPoseProblem(spec, 0.5, 0.2, 7);
  SolverConfig c;
  c.analytic_jacobians = state.range(0) == 1;
  for (auto _ : state) {
    auto s = SolvePoseProblem(p, c);
    benchmark::DoNotOptimize(s);
  }
  state.SetLabel(c.analytic_jacobians ? "analytic" : "autodiff");
}
BENCHMARK(BM_PoseFiveViews)->Arg(1)->Arg(0)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace carmba
