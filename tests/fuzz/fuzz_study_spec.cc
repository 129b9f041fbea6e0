// Fuzz target `study_spec` (fuzz_main.cc): carmba::LoadStudySpec (study/study_spec.h): a study YAML
// in configs/studies/ (references ../../problems and ../*.yaml resolve).
#include "fuzz_target.h"
#include "fuzz_util.h"
#include "study/study_spec.h"

namespace {

int FuzzStudySpec(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("configs/studies/fuzz_study.yaml", data, size);
  (void)carmba::LoadStudySpec(path);
  return 0;
}

}  // namespace

CARMBA_FUZZ_TARGET(study_spec, FuzzStudySpec, nullptr)
