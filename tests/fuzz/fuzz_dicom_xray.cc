// Fuzz target `dicom_xray` (fuzz_main.cc): carmba::ReadDicomXray (io/dicom_xray.h): one DICOM
// XA/RF/CR/DX file.
#include "fuzz_target.h"
#include "fuzz_util.h"
#include "io/dicom_xray.h"

namespace {

int FuzzDicomXray(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("xray.dcm", data, size);
  (void)carmba::ReadDicomXray(path);
  return 0;
}

}  // namespace

CARMBA_FUZZ_TARGET(dicom_xray, FuzzDicomXray, nullptr)
