// libFuzzer harness: carmba::LoadPoseProblem (problem/pose_problem.h): the input is the problem YAML, one directory below the scratch root, so the shipped problems/ resolve ../data/...
#include "fuzz_util.h"
#include "problem/pose_problem.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("p/problem.yaml", data, size);
  (void)carmba::LoadPoseProblem(path);
  return 0;
}
