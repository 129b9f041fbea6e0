// Fuzz target `xray_scene` (fuzz_main.cc): carmba::sim::LoadXrayScene (sim/xray_scene.h): an X-ray
// scene YAML in configs/scenes/ (references ../../data resolve).
#include "fuzz_target.h"
#include "fuzz_util.h"
#include "sim/xray_scene.h"

namespace {

int FuzzXrayScene(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("configs/scenes/fuzz_scene.yaml", data, size);
  (void)carmba::sim::LoadXrayScene(path);
  return 0;
}

}  // namespace

CARMBA_FUZZ_TARGET(xray_scene, FuzzXrayScene, nullptr)
