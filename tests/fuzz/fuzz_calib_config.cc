// libFuzzer harness: carmba::LoadCalibrationOptions (calib/calibrate.h) with the top-level maps
// carmba calibrate leaves to other readers.
#include "fuzz_util.h"
#include "calib/calibrate.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("configs/fuzz_calib.yaml", data, size);
  carmba::CalibrationOptions options;
  (void)carmba::LoadCalibrationOptions(path, &options);
  return 0;
}
