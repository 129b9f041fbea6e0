// Shared by the simulated-scene calibration tests: a shipped simulator scene's truth as
// calibration observations.
#pragma once

#include <gtest/gtest.h>

#include <string>

#include "detect/observations.h"
#include "sim/xray_scene.h"

namespace carmba {

inline sim::XrayScene LoadShippedScene(const std::string& name) {
  auto s = sim::LoadXrayScene(std::string(CARMBA_SOURCE_DIR) + "/configs/scenes/" + name + ".yaml");
  EXPECT_TRUE(s.ok()) << s.status().message();
  return s.ok() ? *s : sim::XrayScene();
}

inline GridSpec SceneGrid(const sim::XrayScene& scene) {
  GridSpec g;
  g.pattern = GridPattern::kCircles;
  g.rows = scene.plate.rows;
  g.cols = scene.plate.cols;
  g.spacing_mm = scene.plate.pitch_mm;
  return g;
}

// The true projected sphere centres of every view (ids = the plate's row-major sphere order).
inline ObservationSet SceneTruthObservations(const sim::XrayScene& scene) {
  ObservationSet obs;
  obs.grid = SceneGrid(scene);
  obs.width = scene.camera.width;
  obs.height = scene.camera.height;
  for (int i = 0; i < static_cast<int>(scene.views.size()); ++i) {
    auto uv = sim::ProjectSphereCenters(scene.camera,
                                        sim::PlacedPhantom{&scene.phantom, scene.CamFromObject(i)});
    EXPECT_TRUE(uv.ok());
    ViewObservations v;
    v.image = scene.views[i].name;
    for (size_t k = 0; k < uv->size(); ++k) {
      v.point_ids.push_back(static_cast<int>(k));
      v.uv_px.push_back((*uv)[k]);
    }
    obs.views.push_back(v);
  }
  return obs;
}

}  // namespace carmba
