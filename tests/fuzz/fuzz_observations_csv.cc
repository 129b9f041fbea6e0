// Fuzz target `observations_csv` (fuzz_main.cc): carmba::ReadObservationsCsv
// (detect/observations.h), observations.csv.
#include "detect/observations.h"
#include "fuzz_target.h"
#include "fuzz_util.h"

namespace {

int FuzzObservationsCsv(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("observations.csv", data, size);
  (void)carmba::ReadObservationsCsv(path);
  return 0;
}

}  // namespace

CARMBA_FUZZ_TARGET(observations_csv, FuzzObservationsCsv, nullptr)
