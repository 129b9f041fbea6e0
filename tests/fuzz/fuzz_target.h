// The fuzz targets of the one harness executable (fuzz_main.cc): each tests/fuzz/fuzz_NAME.cc
// registers its target under NAME with
//   CARMBA_FUZZ_TARGET(NAME, RunFunction, InitFunctionOrNullptr)
// where RunFunction(data, size) is libFuzzer's LLVMFuzzerTestOneInput for that reader and the
// optional InitFunction() (returning 0) its LLVMFuzzerInitialize. The build links all targets
// into one executable and names it fuzz_NAME once per target (symlinks); the executable runs
// the target its own name names.
#pragma once

#include <cstddef>
#include <cstdint>

namespace carmba::fuzz {

struct Target {
  const char* name = nullptr;
  int (*run)(const uint8_t* data, size_t size) = nullptr;
  int (*init)() = nullptr;
};

// Adds `target` to the executable's table (at static initialisation); returns true.
bool RegisterTarget(const Target& target);

}  // namespace carmba::fuzz

#define CARMBA_FUZZ_TARGET(NAME, RUN, INIT)                   \
  [[maybe_unused]] static const bool carmba_fuzz_target_##NAME = \
      carmba::fuzz::RegisterTarget({#NAME, RUN, INIT});
