// Fuzz target `image` (fuzz_main.cc): carmba::ReadImageFile (detect/grid_detector.h): OpenCV's
// decoders (PNG, PGM, TIFF, JPEG, BMP; OpenCV picks the decoder from the content) and, for inputs
// with the DICOM preamble ("DICM" at byte 128), the DICOM reader (io/dicom_image.h, GDCM).
#include "detect/grid_detector.h"
#include "fuzz_target.h"
#include "fuzz_util.h"
#include "io/image_files.h"

namespace {

int FuzzImage(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("image", data, size);
  (void)carmba::ReadImageFile(path);
  return 0;
}

}  // namespace

CARMBA_FUZZ_TARGET(image, FuzzImage, nullptr)
