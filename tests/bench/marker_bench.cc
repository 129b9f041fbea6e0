// Detection + correspondence of one 512x512 object view (issue 11's target: under 15 ms on one
// core): configs/scenes/markers_clutter.yaml (anatomy, 2 spurious beads, a wire), 16 bit; the
// full hypothesise-and-verify search (no nominal prediction), and detection alone.
#include <benchmark/benchmark.h>

#include <string>
#include <vector>

#include "detect/marker_blobs.h"
#include "pose/marker_correspondence.h"
#include "sim/xray_scene.h"

namespace {

struct MarkerScene {
  carmba::Camera camera;
  std::vector<Eigen::Vector3d> markers;
  std::vector<cv::Mat> images;
};

const MarkerScene& Scene() {
  static MarkerScene s;
  if (!s.images.empty()) return s;
  auto scene = carmba::sim::LoadXrayScene(std::string(CARMBA_SOURCE_DIR) +
                                          "/configs/scenes/markers_clutter.yaml");
  if (!scene.ok()) return s;
  s.camera = scene->camera;
  for (const auto& sp : scene->phantom.spheres) s.markers.push_back(sp.center_mm);
  auto grid = carmba::sim::RayGrid::Build(scene->camera, scene->render);
  for (int i = 0; i < static_cast<int>(scene->views.size()); ++i) {
    auto v = carmba::sim::RenderXrayView(*scene, i, grid->get());
    if (v.ok()) s.images.push_back(v->image);
  }
  return s;
}

carmba::MarkerBlobOptions Options(const MarkerScene& s) {
  carmba::MarkerBlobOptions o;
  o.diameter_mm = 2.0;
  o.px_per_mm = s.camera.params[carmba::kFx] / 700.0;
  return o;
}

void BM_MarkerDetectAndLabel(benchmark::State& state) {
  const MarkerScene& s = Scene();
  if (s.images.empty()) return state.SkipWithError("scene did not render");
  const carmba::MarkerBlobOptions o = Options(s);
  size_t i = 0;
  int labelled = 0;
  for (auto _ : state) {
    const carmba::MarkerBlobDetection d =
        carmba::DetectMarkerBlobs(s.images[i++ % s.images.size()], o);
    std::vector<Eigen::Vector2d> uv;
    for (const auto& b : d.blobs) uv.emplace_back(b.uv_px.x, b.uv_px.y);
    carmba::CorrespondenceOptions co;
    co.px_per_mm = o.px_per_mm;  // the nominal magnification, as `carmba pose` passes it
    auto lab = carmba::LabelMarkerBlobs(s.camera, s.markers, uv, co);
    labelled += lab.ok();
    benchmark::DoNotOptimize(lab);
  }
  state.counters["labelled_fraction"] = static_cast<double>(labelled) / state.iterations();
}
BENCHMARK(BM_MarkerDetectAndLabel)->Unit(benchmark::kMillisecond);

void BM_MarkerDetectOnly(benchmark::State& state) {
  const MarkerScene& s = Scene();
  if (s.images.empty()) return state.SkipWithError("scene did not render");
  const carmba::MarkerBlobOptions o = Options(s);
  size_t i = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(carmba::DetectMarkerBlobs(s.images[i++ % s.images.size()], o));
  }
}
BENCHMARK(BM_MarkerDetectOnly)->Unit(benchmark::kMillisecond);

}  // namespace
