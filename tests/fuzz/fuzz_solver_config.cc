// Fuzz target `solver_config` (fuzz_main.cc): carmba::LoadSolverConfig (problem/solver_config.h): a
// solver config YAML.
#include "fuzz_target.h"
#include "fuzz_util.h"
#include "problem/solver_config.h"

namespace {

int FuzzSolverConfig(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("configs/fuzz_config.yaml", data, size);
  (void)carmba::LoadSolverConfig(path);
  return 0;
}

}  // namespace

CARMBA_FUZZ_TARGET(solver_config, FuzzSolverConfig, nullptr)
