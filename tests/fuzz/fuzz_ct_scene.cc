// Fuzz target `ct_scene` (fuzz_main.cc): carmba::ParseCtScene (ct/ct_simulate.h), the CT scene
// reader, on a scene YAML (no simulation).
#include "ct/ct_simulate.h"
#include "fuzz_target.h"
#include "fuzz_util.h"
#include "util/yaml_reader.h"

namespace {

int FuzzCtScene(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("configs/scenes/fuzz_ct.yaml", data, size);
  carmba::YamlMap scene = carmba::YamlMap::Load(path);
  if (!scene.status().ok()) return 0;
  carmba::CtScene ct;
  (void)carmba::ParseCtScene(scene, &ct);
  return 0;
}

}  // namespace

CARMBA_FUZZ_TARGET(ct_scene, FuzzCtScene, nullptr)
