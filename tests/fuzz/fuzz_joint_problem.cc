// libFuzzer harness: carmba::LoadJointProblem (joint/joint_problem.h): the joint problem YAML (relative references resolve against the scratch layout, see fuzz_util.h).
#include "fuzz_util.h"
#include "joint/joint_problem.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("p/joint.yaml", data, size);
  (void)carmba::LoadJointProblem(path);
  return 0;
}
