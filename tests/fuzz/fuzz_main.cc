// The one harness executable: libFuzzer's entry points, dispatched to the fuzz target that the
// executable's own file name names (fuzz_NAME, a symlink per target made by the build;
// fuzz_target.h). One executable instead of one per reader: the fuzz step of scripts/test.sh
// compiles and links the harnesses once (tests/fuzz/README.md has the times).
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "fuzz_target.h"

namespace carmba::fuzz {
namespace {

std::vector<Target>& Targets() {
  static std::vector<Target>& targets = *new std::vector<Target>();
  return targets;
}

const Target* chosen = nullptr;

// "fuzz_csv" from ".../fuzz_csv".
std::string TargetName(const char* argv0) {
  std::string name = argv0;
  const size_t slash = name.rfind('/');
  if (slash != std::string::npos) name = name.substr(slash + 1);
  const std::string prefix = "fuzz_";
  return name.compare(0, prefix.size(), prefix) == 0 ? name.substr(prefix.size()) : name;
}

}  // namespace

bool RegisterTarget(const Target& target) {
  Targets().push_back(target);
  return true;
}

}  // namespace carmba::fuzz

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
  using namespace carmba::fuzz;
  const std::string name = *argc > 0 ? TargetName((*argv)[0]) : "";
  for (const Target& t : Targets()) {
    if (name == t.name) chosen = &t;
  }
  if (chosen == nullptr) {
    std::string names;
    for (const Target& t : Targets()) names += std::string(names.empty() ? "" : ", ") + t.name;
    std::fprintf(stderr,
                 "carmba fuzz: no fuzz target named '%s': run this executable as fuzz_NAME, "
                 "NAME one of %s\n",
                 name.c_str(), names.c_str());
    std::exit(2);
  }
  return chosen->init != nullptr ? chosen->init() : 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return carmba::fuzz::chosen->run(data, size);
}
