// Reading the pixels of a DICOM image (one file, one or more frames) for the X-ray image reader
// (io/dicom_xray.h) and the CT series reader (ct/ct_volume.h).
//
// GDCM parses the file (gdcm::Reader) and decodes compressed pixel data (its codecs), but the
// image pixel module is interpreted here, not by gdcm::ImageReader: Debian's GDCM keeps its
// assertions, and ImageReader's image-module code (pixel format, icon images, overlays, palette
// tables, media-storage guesses) aborts the process on malformed files, where carmba owes the user
// a one-line error (found by fuzz_dicom_xray, one assertion after another). Before GDCM sees a
// file, gdcm_util::CheckDicomFile walks its structure and checks its VRs. Compressed pixel data is
// decoded by GDCM's codecs in a separate decoder process (forked once, kept between images): a
// codec that aborts or crashes on a malformed stream makes that image an error.
#pragma once

#include <gdcmDataSet.h>
#include <gdcmFileMetaInformation.h>

#include <memory>
#include <string>
#include <vector>

#include "util/status.h"

namespace gdcm {
class Reader;
}

namespace carmba {

// A parsed DICOM image with its decoded pixels.
struct DicomImage {
  DicomImage();
  ~DicomImage();
  DicomImage(DicomImage&&) noexcept;
  DicomImage& operator=(DicomImage&&) noexcept;

  std::unique_ptr<gdcm::Reader> reader;  // the parsed file
  const gdcm::DataSet& data_set() const;
  const gdcm::FileMetaInformation& header() const;

  std::string transfer_syntax_uid;  // (0002,0010) as stored; "" without a file meta group
  std::string photometric;          // (0028,0004) without padding
  int rows = 0, columns = 0, frames = 1;
  int bits_allocated = 0;  // 8, 16 or 32
  int bits_stored = 0;
  int high_bit = 0;
  bool is_signed = false;  // Pixel Representation (0028,0103) 1
  // frames x rows x columns samples of bits_allocated / 8 bytes each, native byte order, as
  // stored (no rescale, no masking of the bits above High Bit).
  std::vector<char> pixels;
};

enum class DicomImageKind {
  kImage,        // *out holds the image
  kNotDicom,     // no DICM preamble and no DICOM element at the start
  kNoPixelData,  // a DICOM file without Pixel Data (7fe0,0010); *out has the parsed file
};

struct DicomImageOptions {
  bool allow_32_bit = false;  // Bits Allocated 32 (CT); X-ray images take 8 or 16
};

// Parses `path` and decodes its pixels: monochrome (Samples per Pixel 1) images only. Returns an
// error starting with `path` for a corrupt file, an unsupported pixel format or pixel data that
// cannot be decoded; Ok with *kind kNotDicom / kNoPixelData for the callers to decide.
Status ReadDicomImage(const std::string& path,
                      const DicomImageOptions& options,
                      DicomImage* out,
                      DicomImageKind* kind);

// A short name for a transfer syntax UID, e.g. "JPEG Lossless ... (1.2.840.10008.1.2.4.70)".
std::string TransferSyntaxName(const std::string& uid);

}  // namespace carmba
