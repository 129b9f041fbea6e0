// libFuzzer harness: carmba::ReadImageFile (detect/grid_detector.h) through OpenCV (PNG, PGM, TIFF, JPEG, BMP; OpenCV picks the decoder from the content) and, for inputs with the DICM preamble, GDCM.
#include "fuzz_util.h"
#include "detect/grid_detector.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("image", data, size);
  (void)carmba::ReadImageFile(path);
  return 0;
}
