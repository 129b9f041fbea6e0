// Calibration time: carmba (closed-form init + two-stage bundle adjustment + covariance of the
// intrinsics + projection uncertainty + residual statistics, all timed) vs mrcal's C API
// (mrcal_optimize, LENSMODEL_OPENCV5, no warp, no regularization, no outlier rejection; seeded with
// carmba's closed-form initial values, computed outside the timed region since mrcal's C API has
// no seeding function: mrcal's time is its solve alone, no seeding and no covariance) vs
// cv::calibrateCamera (its own initialisation), on identical synthetic observations of the 5x5
// plate (0.3 px noise), 16, 200 and 1000 views. The counters give each solver's RMS and fx, cx, so
// that a speed-up from stopping early would show. One core (mrcal's CHOLMOD could use more):
//   cmake --build build --target carmba_bench &&
//   taskset -c 0 build/tests/carmba_bench --benchmark_filter=Calib --benchmark_repetitions=3
#include <benchmark/benchmark.h>

#include <opencv2/calib3d.hpp>

#include <map>

#include "ba/bundle_adjuster.h"
#include "calib/calibrate.h"
#include "synthetic/synthetic_views.h"

extern "C" {
#include <mrcal/mrcal.h>
}

namespace {

using namespace carmba;

const std::array<double, kNumIntrinsics> kTruth = {2061.4, 2254.6, 203.7, 205.1, -0.3,
                                                   2.0,    0.0005, -0.0003, 0.0};

const ObservationSet& Views(int n) {
  static std::map<int, ObservationSet> cache;
  auto it = cache.find(n);
  if (it == cache.end()) {
    SyntheticViewsOptions so;
    so.num_views = n;
    so.seed = 100 + n;
    GridSpec g;
    it = cache.emplace(n, MakeSyntheticViews(kTruth, 408, 408, g, so)).first;
  }
  return it->second;
}

// range(0): views; range(1): 0 = carmba's Schur LM (the default), 1 = Ceres (solver: ceres).
void BM_CalibCarmba(benchmark::State& state) {
  const ObservationSet& obs = Views(static_cast<int>(state.range(0)));
  CalibrationOptions opt;
  if (state.range(1) == 1) opt.solve.backend = ba::Backend::kCeres;
  state.SetLabel(NameOf(ba::kBackendNames, opt.solve.backend));
  double rms = 0, fx = 0, cx = 0;
  for (auto _ : state) {
    auto r = Calibrate(obs, opt);
    if (!r.ok()) {
      state.SkipWithError(r.status().message().c_str());
      return;
    }
    rms = r->rms_px;
    fx = r->camera.params[kFx];
    cx = r->camera.params[kCx];
    benchmark::DoNotOptimize(r->covariance(0, 0));
  }
  state.counters["rms_px"] = rms;
  state.counters["fx_px"] = fx;
  state.counters["cx_px"] = cx;
}

void BM_CalibMrcalC(benchmark::State& state) {
  const ObservationSet& obs = Views(static_cast<int>(state.range(0)));
  auto seed = Calibrate(obs, CalibrationOptions());  // for its closed-form initial values only
  if (!seed.ok()) {
    state.SkipWithError("seed failed");
    return;
  }
  const int nv = static_cast<int>(obs.views.size());
  const int W = obs.grid.cols, H = obs.grid.rows;
  std::vector<mrcal_observation_board_t> boards(nv);
  std::vector<mrcal_point3_t> pool0(nv * W * H);
  for (int v = 0; v < nv; ++v) {
    boards[v].icam.intrinsics = 0;
    boards[v].icam.extrinsics = -1;
    boards[v].iframe = v;
    for (int i = 0; i < W * H; ++i) {
      pool0[v * W * H + i].x = 0;
      pool0[v * W * H + i].y = 0;
      pool0[v * W * H + i].z = -1;
    }
    for (size_t j = 0; j < obs.views[v].uv_px.size(); ++j) {
      mrcal_point3_t& p = pool0[v * W * H + obs.views[v].point_ids[j]];
      p.x = obs.views[v].uv_px[j].x();
      p.y = obs.views[v].uv_px[j].y();
      p.z = 1.0;
    }
  }
  mrcal_lensmodel_t lens;
  lens.type = MRCAL_LENSMODEL_OPENCV5;
  mrcal_problem_selections_t sel{};
  sel.do_optimize_intrinsics_core = true;
  sel.do_optimize_intrinsics_distortions = true;
  sel.do_optimize_extrinsics = false;
  sel.do_optimize_frames = true;
  sel.do_optimize_calobject_warp = false;
  sel.do_apply_regularization = false;
  sel.do_apply_outlier_rejection = false;
  mrcal_problem_constants_t constants{0, 1e6};
  const int imagersize[2] = {obs.width, obs.height};
  double rms = 0, fx = 0, cx = 0;
  for (auto _ : state) {
    state.PauseTiming();
    std::vector<double> intr(seed->initial_intrinsics.begin(), seed->initial_intrinsics.end());
    std::vector<mrcal_pose_t> frames(nv);
    for (int v = 0; v < nv; ++v) {
      const auto& p = seed->initial_cam_from_plate[v];
      frames[v].r.x = p[0], frames[v].r.y = p[1], frames[v].r.z = p[2];
      frames[v].t.x = p[3], frames[v].t.y = p[4], frames[v].t.z = p[5];
    }
    std::vector<mrcal_point3_t> pool = pool0;
    state.ResumeTiming();
    mrcal_stats_t stats = mrcal_optimize(
        nullptr, 0, nullptr, 0, intr.data(), nullptr, frames.data(), nullptr, nullptr, 1, 0, nv, 0,
        0, boards.data(), nullptr, nv, 0, pool.data(), &lens, imagersize, sel, &constants,
        obs.grid.spacing_mm, W, H, false, false);
    rms = stats.rms_reproj_error__pixels;
    fx = intr[kFx];
    cx = intr[kCx];
    benchmark::DoNotOptimize(intr[0]);
  }
  state.counters["rms_px"] = rms;
  state.counters["fx_px"] = fx;
  state.counters["cx_px"] = cx;
}

// Calibration through the bundle-adjustment engine (src/ba; range(1): 0 = backend ceres, Ceres
// DENSE_SCHUR with the analytic per-point reprojection blocks; 1 = backend carmba_lm; the
// covariance of the intrinsics from the engine's Schur module, plate poses eliminated), seeded
// like mrcal with carmba's closed-form initial values (outside the timed region); solve +
// covariance timed.
void BM_CalibEngine(benchmark::State& state) {
  const ObservationSet& obs = Views(static_cast<int>(state.range(0)));
  auto seed = Calibrate(obs, CalibrationOptions());  // for its closed-form initial values only
  if (!seed.ok()) {
    state.SkipWithError("seed failed");
    return;
  }
  ba::BaProblem p;
  ba::IntrinsicsGroup g;
  std::copy(seed->initial_intrinsics.begin(), seed->initial_intrinsics.end(), g.initial.begin());
  g.width = obs.width;
  g.height = obs.height;
  p.groups.push_back(g);
  for (int id = 0; id < obs.grid.NumPoints(); ++id)
    p.plate.points.push_back(obs.grid.PointInPlate(id));
  for (size_t v = 0; v < obs.views.size(); ++v) {
    ba::BaView view;
    view.id = std::to_string(v);
    view.kind = ba::ViewKind::kPlate;
    view.sigma_px = 0.3;
    for (int i = 0; i < 6; ++i) view.initial[i] = seed->initial_cam_from_plate[v][i];
    view.point_ids = obs.views[v].point_ids;
    view.uv_px = obs.views[v].uv_px;
    p.views.push_back(view);
  }
  ba::BaOptions o;
  if (state.range(1) == 1) o.backend = ba::Backend::kCarmbaLm;
  state.SetLabel(NameOf(ba::kBackendNames, o.backend));
  o.function_tolerance = 1e-10;
  o.gradient_tolerance = 1e-14;
  o.parameter_tolerance = 1e-10;
  double rms = 0, fx = 0, cx = 0;
  for (auto _ : state) {
    auto r = ba::SolveBundleAdjustment(p, o);
    if (!r.ok()) {
      state.SkipWithError(r.status().message().c_str());
      return;
    }
    rms = r->rms_plate_px;
    fx = r->state[kFx];
    cx = r->state[kCx];
    benchmark::DoNotOptimize(r->Covariance({0})(0, 0));
  }
  state.counters["rms_px"] = rms;
  state.counters["fx_px"] = fx;
  state.counters["cx_px"] = cx;
}

void BM_CalibOpenCv(benchmark::State& state) {
  const ObservationSet& obs = Views(static_cast<int>(state.range(0)));
  std::vector<std::vector<cv::Point3f>> op;
  std::vector<std::vector<cv::Point2f>> ip;
  for (const auto& v : obs.views) {
    std::vector<cv::Point3f> o;
    std::vector<cv::Point2f> i;
    for (size_t j = 0; j < v.uv_px.size(); ++j) {
      const Eigen::Vector3d P = obs.grid.PointInPlate(v.point_ids[j]);
      o.emplace_back(P.x(), P.y(), P.z());
      i.emplace_back(v.uv_px[j].x(), v.uv_px[j].y());
    }
    op.push_back(o);
    ip.push_back(i);
  }
  double rms = 0, fx = 0, cx = 0;
  for (auto _ : state) {
    cv::Mat K, d;
    std::vector<cv::Mat> rv, tv;
    rms = cv::calibrateCamera(op, ip, cv::Size(obs.width, obs.height), K, d, rv, tv) /
          std::sqrt(2.0);
    fx = K.at<double>(0, 0);
    cx = K.at<double>(0, 2);
  }
  state.counters["rms_px"] = rms;
  state.counters["fx_px"] = fx;
  state.counters["cx_px"] = cx;
}

}  // namespace

BENCHMARK(BM_CalibCarmba)
    ->Args({16, 0})
    ->Args({200, 0})
    ->Args({1000, 0})
    ->Args({16, 1})
    ->Args({200, 1})
    ->Args({1000, 1})
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_CalibMrcalC)->Arg(16)->Arg(200)->Arg(1000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_CalibEngine)
    ->Args({16, 0})
    ->Args({200, 0})
    ->Args({1000, 0})
    ->Args({16, 1})
    ->Args({200, 1})
    ->Args({1000, 1})
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_CalibOpenCv)->Arg(16)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_CalibOpenCv)->Arg(200)->Iterations(1)->Unit(benchmark::kMillisecond);
