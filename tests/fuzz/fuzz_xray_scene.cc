// libFuzzer harness: carmba::sim::LoadXrayScene (sim/xray_scene.h): an X-ray scene YAML in
// configs/scenes/ (references ../../data resolve).
#include "fuzz_util.h"
#include "sim/xray_scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("configs/scenes/fuzz_scene.yaml", data, size);
  (void)carmba::sim::LoadXrayScene(path);
  return 0;
}
