// libFuzzer harness: carmba::ReadImageFile (detect/grid_detector.h): OpenCV's decoders (PNG,
// PGM, TIFF, JPEG, BMP; OpenCV picks the decoder from the content) and, for inputs with the DICOM
// preamble ("DICM" at byte 128), the DICOM reader (io/dicom_image.h, GDCM).
#include "detect/grid_detector.h"
#include "io/image_files.h"
#include "fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("image", data, size);
  (void)carmba::ReadImageFile(path);
  return 0;
}
