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

// Short ids for views named as ReadImageViews names them, for tables, CSVs and result.json (the
// full names are kept beside them): the file's stem, with `#frameN` kept for a frame of a
// multi-frame file ("/data/run.dcm#frame3" -> "run#frame3"). Where two names would get the same
// id, every id is the path below the names' common directory, without extensions
// ("a/v1.png", "b/v1.png" -> "a/v1", "b/v1"); names that differ only in their extension keep
// their whole names.
std::vector<std::string> ShortViewIds(const std::vector<std::string>& names);

}  // namespace carmba
