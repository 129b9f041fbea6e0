// libFuzzer harness: carmba::LoadSolverConfig (problem/solver_config.h): a solver config YAML.
#include "fuzz_util.h"
#include "problem/solver_config.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("configs/fuzz_config.yaml", data, size);
  (void)carmba::LoadSolverConfig(path);
  return 0;
}
