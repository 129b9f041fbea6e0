// Image sizes read from a file's header, before anything is decoded, so that an absurd image (a
// 30000 x 30000 PNG, a corrupt header) is refused in milliseconds instead of after gigabytes of
// decoding (bounds: plausible::kImagePixels, plausible::kImageBytes).
//
// Formats: PNG (IHDR), JPEG (the first SOFn marker), BMP (BITMAPINFOHEADER or later), TIFF (the
// first IFD, either byte order; BigTIFF), PGM / PPM / PNM (P1..P6). DICOM is checked by its own
// reader from Rows / Columns / Number of Frames (io/dicom_image.cc).
#pragma once

#include <cstdint>
#include <string>

#include "util/status.h"

namespace carmba {

struct ImageHeader {
  std::string format;  // "PNG", "JPEG", "BMP", "TIFF", "PNM"
  int64_t width = 0;
  int64_t height = 0;
  int64_t channels = 1;
  int64_t bytes_per_sample = 1;  // 1 for 8-bit (or less), 2 for 16-bit, 4 for 32-bit
};

// The header of `path`. found = false (and Ok) when the file is none of the formats above (its
// decoder then has the last word); an error only when the file cannot be read.
StatusOr<ImageHeader> ReadImageHeader(const std::string& path, bool* found);

// Checks `header` against the bounds: "PATH: 30000 x 30000 px PNG image, more than carmba reads
// (1 .. 1e+08 px: ...)". Ok for sizes within them.
Status CheckImageSize(const std::string& path, const ImageHeader& header);

// ReadImageHeader + CheckImageSize (Ok for files of other formats).
Status CheckImageFileSize(const std::string& path);

}  // namespace carmba
