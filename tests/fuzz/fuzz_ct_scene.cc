// libFuzzer harness: carmba::ParseCtScene (ct/ct_simulate.h), the CT scene reader, on a scene YAML
// (no simulation).
#include "fuzz_util.h"
#include "ct/ct_simulate.h"
#include "util/yaml_reader.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("configs/scenes/fuzz_ct.yaml", data, size);
  carmba::YamlMap scene = carmba::YamlMap::Load(path);
  if (!scene.status().ok()) return 0;
  carmba::CtScene ct;
  (void)carmba::ParseCtScene(scene, &ct);
  return 0;
}
