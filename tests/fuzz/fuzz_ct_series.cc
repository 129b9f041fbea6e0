// Fuzz target `ct_series` (fuzz_main.cc): carmba::ReadCtSeries (ct/ct_volume.h), the DICOM CT
// series reader, on a directory holding only the fuzzed slice and on one holding the fuzzed slice
// next to a valid slice (the seed CT_small.dcm), so both the one-file path and the series
// consistency checks run.
#include <filesystem>

#include "ct/ct_volume.h"
#include "fuzz_target.h"
#include "fuzz_util.h"

namespace {

int InitCtSeries() {
  namespace fs = std::filesystem;
  const std::string root = carmba::fuzz::ScratchDir();
  fs::create_directories(root + "/ct1");
  fs::create_directories(root + "/ct2");
  fs::copy_file(CARMBA_FUZZ_SEEDS "/ct/CT_small.dcm", root + "/ct2/a.dcm");
  return 0;
}

int FuzzCtSeries(const uint8_t* data, size_t size) {
  const std::string root = carmba::fuzz::ScratchDir();
  carmba::fuzz::WriteInput("ct1/slice.dcm", data, size);
  (void)carmba::ReadCtSeries(root + "/ct1");
  carmba::fuzz::WriteInput("ct2/b.dcm", data, size);
  (void)carmba::ReadCtSeries(root + "/ct2");
  return 0;
}

}  // namespace

CARMBA_FUZZ_TARGET(ct_series, FuzzCtSeries, InitCtSeries)
