// Image files as carmba reads them: PNG, PGM, TIFF, JPEG, BMP through OpenCV (unchanged, 8/16
// bit, size-checked from the header before decoding), DICOM projection images through GDCM
// (io/dicom_xray.h), one view per frame of a multi-frame file.
#pragma once

#include <opencv2/core.hpp>

#include <optional>
#include <string>
#include <vector>

#include "io/dicom_xray.h"
#include "util/status.h"

namespace carmba {

// Reads an image unchanged (8/16 bit); error naming the file if unreadable or empty. DICOM files
// (io/dicom_xray.h IsDicomFileName: .dcm, .dicom, a DICM preamble, or `file#frameN` for frame N
// of a multi-frame file) are read through GDCM; a multi-frame file without `#frameN` is an error
// (ReadImageViews reads all its frames).
StatusOr<cv::Mat> ReadImageFile(const std::string& path);

// One view of an image file: its name (the file, or `file#frameN` for a frame of a multi-frame
// DICOM file) and its pixels.
struct NamedImage {
  std::string name;
  cv::Mat image;
  // A DICOM frame's C-arm tags (io/dicom_xray.h); std::nullopt for other image files.
  std::optional<XrayFrameGeometry> geometry;
};
// The views of a file: one for an ordinary image or a single-frame DICOM file, one per frame for a
// multi-frame DICOM file (io/dicom_xray.h; `file#frameN` reads frame N only).
StatusOr<std::vector<NamedImage>> ReadImageViews(const std::string& path);

}  // namespace carmba
