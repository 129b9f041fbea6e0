// `carmba track`'s pipeline on the real Autoscoper wrist set (data/real/autoscoper-wrist: 3 frames
// x 2 cameras of 1760 x 1760), split into its stages: reading and detecting the beads (the marker
// detector and the pair fit), matching and identity, the bundle adjustment over all frames with
// its covariance and the checks. The outputs (CSV, JSON, report, overlays) are not timed.
//   taskset -c 0 build/tests/carmba_bench --benchmark_filter='Track' --benchmark_repetitions=3
#include <benchmark/benchmark.h>

#include "track/track.h"
#include "util/file_util.h"

namespace {

using namespace carmba;

const std::string kWrist = std::string(CARMBA_SOURCE_DIR) + "/data/real/autoscoper-wrist";

struct WristInputs {
  std::vector<TrackCamera> cameras;
  std::vector<TrackFrame> frames;
};

WristInputs Inputs() {
  WristInputs in;
  std::vector<std::vector<std::string>> images;
  for (const char* c : {"cam01", "cam02"}) {
    in.cameras.push_back(
        *ReadXmaCalibration(kWrist + "/calibration/xr_calib_wrist_" + std::string(c) + ".txt", c));
    images.push_back(*ListImageFiles(kWrist + "/images/" + c));
  }
  in.frames = *PairFrames(images, nullptr);
  return in;
}

void BM_TrackWrist(benchmark::State& state) {
  const WristInputs in = Inputs();
  TrackOptions o;
  o.marker_diameter_mm = 1;
  double detect = 0, match = 0, ba = 0;
  size_t beads = 0;
  for (auto _ : state) {
    auto r = Track(in.cameras, in.frames, o);
    if (!r.ok()) {
      state.SkipWithError(r.status().message().c_str());
      return;
    }
    detect += r->time_detect_s, match += r->time_match_s, ba += r->time_ba_s;
    beads = r->beads.size();
  }
  const double n = static_cast<double>(state.iterations());
  state.counters["detect_s"] = detect / n;
  state.counters["match_s"] = match / n;
  state.counters["ba_s"] = ba / n;
  state.counters["beads"] = static_cast<double>(beads);
}
BENCHMARK(BM_TrackWrist)->Unit(benchmark::kMillisecond);

}  // namespace
