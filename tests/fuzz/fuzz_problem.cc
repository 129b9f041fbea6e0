// Fuzz target `problem` (fuzz_main.cc): carmba::LoadProblem (problem/problem.h), the one problem
// reader (pose, joint and calibration-only problems, in both pose spellings): the input is the
// problem YAML, one directory below the scratch root, so the shipped problems/ resolve ../data/...
#include "fuzz_target.h"
#include "fuzz_util.h"
#include "problem/problem.h"

namespace {

int FuzzProblem(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("p/problem.yaml", data, size);
  (void)carmba::LoadProblem(path);
  return 0;
}

}  // namespace

CARMBA_FUZZ_TARGET(problem, FuzzProblem, nullptr)
