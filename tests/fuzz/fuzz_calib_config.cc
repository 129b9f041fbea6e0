// Fuzz target `calib_config` (fuzz_main.cc): carmba::LoadCalibrationOptions
// (calib/calibration_options.h) with the top-level maps carmba calibrate leaves to other readers.
#include "calib/calibration_options.h"
#include "fuzz_target.h"
#include "fuzz_util.h"

namespace {

int FuzzCalibConfig(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("configs/fuzz_calib.yaml", data, size);
  carmba::CalibrationOptions options;
  (void)carmba::LoadCalibrationOptions(path, &options);
  return 0;
}

}  // namespace

CARMBA_FUZZ_TARGET(calib_config, FuzzCalibConfig, nullptr)
