// libFuzzer harness: carmba::LoadSolverConfig (problem/pose_problem.h): a pose solver config YAML.
#include "fuzz_util.h"
#include "problem/pose_problem.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("configs/fuzz_config.yaml", data, size);
  (void)carmba::LoadSolverConfig(path);
  return 0;
}
