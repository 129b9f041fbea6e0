// libFuzzer harness: carmba::ReadImageFile (detect/grid_detector.h) through OpenCV (PNG, PGM,
// TIFF, JPEG, BMP; OpenCV picks the decoder from the content). Inputs with the DICOM preamble
// ("DICM" at byte 128) go to GDCM in ReadImageFile; they are fuzz_dicom_xray's, which is not yet
// a ctest test because GDCM still aborts on assertions for some files (tests/fuzz/README.md),
// so they are skipped here to keep this harness's CI test about the OpenCV path.
#include <cstring>

#include "detect/grid_detector.h"
#include "fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size >= 132 && std::memcmp(data + 128, "DICM", 4) == 0) return 0;
  const std::string path = carmba::fuzz::WriteInput("image", data, size);
  (void)carmba::ReadImageFile(path);
  return 0;
}
