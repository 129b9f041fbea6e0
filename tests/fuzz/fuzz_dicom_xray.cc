// libFuzzer harness: carmba::ReadDicomXray (io/dicom_xray.h): one DICOM XA/RF/CR/DX file.
#include "fuzz_util.h"
#include "io/dicom_xray.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("xray.dcm", data, size);
  (void)carmba::ReadDicomXray(path);
  return 0;
}
