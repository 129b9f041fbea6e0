// libFuzzer harness: carmba::ReadObservationsCsv (detect/observations.h), observations.csv.
#include "fuzz_util.h"
#include "detect/observations.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("observations.csv", data, size);
  (void)carmba::ReadObservationsCsv(path);
  return 0;
}
