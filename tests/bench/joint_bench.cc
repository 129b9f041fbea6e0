// The joint bundle adjustment through the engine (src/ba): the synthetic joint problem with 20
// plate views of the 5x5 plate and 7 object views of the 9-marker object (all noise sources on),
// started away from the optimum (intrinsics off by 1 % / 2 px, poses by ~0.5 deg / 2 mm); solve +
// covariance + error budget timed. And one object view with 9 markers through the engine: POSIT +
// bundle adjustment (intrinsics held, CT priors) + covariance.
//   taskset -c 0 build/tests/carmba_bench --benchmark_filter='Joint|EngineOneView'
//   --benchmark_repetitions=3
#include <benchmark/benchmark.h>

#include <random>

#include "analysis/lens_models.h"
#include "ba/bundle_adjuster.h"
#include "ba/quantities.h"
#include "problem/ba_assembly.h"
#include "synthetic/synthetic_joint.h"

namespace {

using namespace carmba;

ba::SyntheticJoint Perturbed(const ba::SyntheticJointSpec& spec, uint64_t seed) {
  ba::SyntheticJoint sj = ba::MakeSyntheticJoint(spec, ba::NoiseSwitches(), seed);
  std::mt19937_64 rng(seed + 1);
  std::normal_distribution<double> g(0.0, 1.0);
  auto& intr = sj.problem.groups[0].initial;
  intr[kFx] *= 1.01, intr[kFy] *= 0.99, intr[kCx] += 2, intr[kCy] -= 2;
  for (auto& v : sj.problem.views) {
    for (int i = 0; i < 3; ++i) v.initial[i] += 0.01 * g(rng);
    for (int i = 3; i < 6; ++i) v.initial[i] += 2.0 * g(rng);
  }
  return sj;
}

void BM_JointSolveCovarianceBudget(benchmark::State& state) {
  ba::SyntheticJointSpec spec;  // 20 plate views, 7 object views
  const ba::SyntheticJoint sj = Perturbed(spec, 42);
  const ba::BaOptions o;
  int iterations = 0;
  double sigma_fx = 0;
  for (auto _ : state) {
    auto r = ba::SolveBundleAdjustment(sj.problem, o);
    if (!r.ok()) {
      state.SkipWithError(r.status().message().c_str());
      return;
    }
    const auto budget = ba::ComputeErrorBudget(sj.problem, *r, sj.pairs);
    iterations = r->iterations;
    sigma_fx = budget[0].sigma;
    benchmark::DoNotOptimize(budget.back().sigma);
  }
  state.counters["iterations"] = iterations;
  state.counters["sigma_fx_px"] = sigma_fx;
}

// The self-checks of issue 21 against that solve, in one run: 0 the a-priori solve (as before),
// 1 with covariance.scale per_group (variance components, iterated), 2 per_group and the
// distortion models compared (4 models, 5 held-out folds: analysis/lens_models.h), as
// `carmba solve --config configs/joint.yaml` runs them.
//   build/tests/carmba_bench --benchmark_filter='JointSelfChecks' --benchmark_repetitions=5
void BM_JointSelfChecks(benchmark::State& state) {
  ba::SyntheticJointSpec spec;
  const ba::SyntheticJoint sj = Perturbed(spec, 42);
  ba::BaOptions o;
  if (state.range(0) >= 1) o.covariance_scale = ba::CovarianceScale::kPerGroup;
  int variance_iterations = 0, iterations = 0;
  for (auto _ : state) {
    ba::BaProblem p = sj.problem;
    if (state.range(0) == 2) {
      auto sel = analysis::SelectDistortionModel(p, o);
      if (!sel.ok()) {
        state.SkipWithError(sel.status().message().c_str());
        return;
      }
      analysis::ApplyDistortionModel(sel->recommended, &p);
      analysis::StartFromFit(*sel->Score(sel->recommended), &p);
    }
    auto r = ba::SolveBundleAdjustment(p, o);
    if (!r.ok()) {
      state.SkipWithError(r.status().message().c_str());
      return;
    }
    const auto budget = ba::ComputeErrorBudget(p, *r, sj.pairs);
    variance_iterations = r->variance_iterations;
    iterations = r->iterations;
    benchmark::DoNotOptimize(budget.back().sigma);
  }
  state.counters["variance_iterations"] = variance_iterations;
  state.counters["iterations"] = iterations;
}
BENCHMARK(BM_JointSelfChecks)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

// The distortion-model comparison of BM_JointSelfChecks/2 alone (its share of that run).
void BM_JointDistortionSelection(benchmark::State& state) {
  const ba::SyntheticJoint sj = Perturbed(ba::SyntheticJointSpec(), 42);
  ba::BaOptions o;
  o.covariance_scale = ba::CovarianceScale::kPerGroup;
  for (auto _ : state) {
    auto sel = analysis::SelectDistortionModel(sj.problem, o);
    if (!sel.ok()) {
      state.SkipWithError(sel.status().message().c_str());
      return;
    }
    benchmark::DoNotOptimize(sel->recommended);
  }
}
BENCHMARK(BM_JointDistortionSelection)->Unit(benchmark::kMillisecond);

// One object view, 9 markers: POSIT initial pose, then the engine with the intrinsics held and the
// markers tied to their CT centres, covariance of the pose.
void BM_EngineOneView(benchmark::State& state) {
  ba::SyntheticJointSpec spec;
  spec.num_plate_views = 0;
  spec.object_angles_deg = {30};
  ba::SyntheticJoint sj = ba::MakeSyntheticJoint(spec, ba::NoiseSwitches(), 7);
  sj.problem.groups[0].free.fill(false);
  Camera cam;
  std::copy(
      sj.problem.groups[0].initial.begin(), sj.problem.groups[0].initial.end(), cam.params.begin());
  ba::BaView& view = sj.problem.views[0];
  std::vector<Eigen::Vector3d> pts;
  for (int id : view.point_ids) pts.push_back(sj.problem.markers[id - 1].p_ct);
  const ba::BaOptions o;
  double rms = 0;
  for (auto _ : state) {
    auto init = InitialObjectPose(cam, Initializer::kPosit, pts, view.uv_px);
    if (!init.ok()) {
      state.SkipWithError(init.status().message().c_str());
      return;
    }
    view.initial = *init;
    auto r = ba::SolveBundleAdjustment(sj.problem, o);
    if (!r.ok()) {
      state.SkipWithError(r.status().message().c_str());
      return;
    }
    rms = r->rms_object_px;
    benchmark::DoNotOptimize(r->Covariance({r->layout->view_block(0)})(0, 0));
  }
  state.counters["rms_px"] = rms;
}

}  // namespace

BENCHMARK(BM_JointSolveCovarianceBudget)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_EngineOneView)->Unit(benchmark::kMicrosecond);
