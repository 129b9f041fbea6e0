// DICOM projection X-ray images (XA, RF, CR, DX; any SOP class with monochrome pixel data) read
// through GDCM: pixels per frame, and the C-arm geometry tags per frame.
//
// PIXELS
//   * Single- and multi-frame files; one frame = one view. A multi-frame file's views are named
//     `file.dcm#frame1` .. `file.dcm#frameN` (1-based, like DICOM's frame numbers); a single-frame
//     file's view is the file name itself (DicomFrameName).
//   * Bits Allocated 8 -> CV_8U, 16 -> CV_16U, one channel, the stored value of Bits Stored bits
//     (any bits above High Bit, e.g. old overlay bits, are masked off). Signed pixel data
//     (Pixel Representation 1) is shifted to offset binary (+ 2^(BitsStored-1)), so that the
//     order of the grey levels is kept and the image stays unsigned.
//   * MONOCHROME2 convention: MONOCHROME1 (high value = dark) is inverted,
//     v -> (2^BitsStored - 1) - v. Other photometric interpretations (RGB, PALETTE COLOR, YBR)
//     and Samples per Pixel != 1 are errors: X-ray projection images are monochrome.
//   * Rescale slope / intercept, VOI LUTs and Pixel Intensity Relationship (LIN / LOG) are NOT
//     applied: detection works on the stored values.
//   * Transfer syntaxes: whatever GDCM decodes (uncompressed explicit / implicit little endian,
//     big endian, RLE, JPEG baseline / extended / lossless, JPEG-LS, JPEG 2000). One it cannot
//     decode (e.g. MPEG-2, H.264) is an error naming the syntax. The file is parsed and the
//     pixels decoded by io/dicom_image.h: a malformed file is a one-line error, never an abort
//     in GDCM (its structure is walked first, compressed data is decoded in a child process).
//
// GEOMETRY (XA Positioner Module, PS3.3 C.8.7.5; also read from RF, CR, DX when present)
//   * Positioner Primary Angle (0018,1510): LAO positive, RAO negative (deg).
//   * Positioner Secondary Angle (0018,1511): cranial positive, caudal negative (deg).
//     Both are the first frame's. In a multi-frame file, Positioner Primary / Secondary Angle
//     Increment (0018,1520 / 0018,1521) give per frame either ONE value, the constant change per
//     frame (frame k, 0-based, is at angle + k * increment), or one value PER FRAME, the offset of
//     each frame from the first frame's angle (frame k at angle + increment[k]) (PS3.3
//     C.8.7.5.1.3). An increment without its base angle leaves that angle absent.
//   * Distance Source to Detector (0018,1110) = SID, Distance Source to Patient (0018,1111) = SOD
//     (source to isocentre on C-arms), mm; Estimated Radiographic Magnification Factor (0018,1114)
//     = SID / SOD (io/dicom_view.h uses it when SOD is absent).
//   * Imager Pixel Spacing (0018,1164) = "row spacing\column spacing" in mm, at the detector's
//     front plane: row spacing is the distance between adjacent ROWS (vertical, image y), column
//     spacing the distance between adjacent COLUMNS (horizontal, image x). (Pixel Spacing
//     (0028,0030) is NOT used instead: for DX it may be calibrated to the patient plane.)
//   * Absent or empty (zero-length) tags are std::nullopt: real files often carry these tags
//     empty. A present value that is not a number, a wrong number of values, a non-positive
//     distance or spacing, or an increment count that is neither 1 nor the number of frames is an
//     error naming the file and the tag.
//   From these, io/dicom_view.h builds the nominal camera and cam_from_patient of a view.
//
// ERRORS (one line, starting with the file name): unreadable file; not DICOM; corrupt DICOM
// (truncated, or unparsable: GDCM's own diagnostics are silenced); no Pixel Data (7fe0,0010);
// pixel data GDCM cannot decode (naming the transfer syntax UID and name); unsupported
// photometric interpretation, samples per pixel or bits allocated; malformed geometry tags (see
// above). (A `file#frameN` beyond the file's frames is detect/grid_detector.h's error.)
#pragma once

#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "util/status.h"

namespace carmba {

// The C-arm geometry of one frame, as stored (plus the increments, applied). std::nullopt =
// absent or empty in the file.
struct XrayFrameGeometry {
  std::optional<double> primary_angle_deg;    // LAO +, RAO - (0018,1510) (+ 0018,1520)
  std::optional<double> secondary_angle_deg;  // cranial +, caudal - (0018,1511) (+ 0018,1521)
  std::optional<double> sid_mm;               // Distance Source to Detector (0018,1110)
  std::optional<double> sod_mm;               // Distance Source to Patient (0018,1111)
  std::optional<double> magnification;  // Estimated Radiographic Magnification Factor (0018,1114)
  std::optional<double> pixel_spacing_row_mm;  // Imager Pixel Spacing (0018,1164)[0]: along y
  std::optional<double> pixel_spacing_col_mm;  // Imager Pixel Spacing (0018,1164)[1]: along x
};

struct DicomXrayImage {
  std::string file;
  std::string sop_class_uid;        // (0008,0016)
  std::string modality;             // (0008,0060), e.g. XA, RF, CR, DX
  std::string transfer_syntax_uid;  // (0002,0010) as stored
  std::string photometric;          // (0028,0004) as stored: MONOCHROME1 or MONOCHROME2
  // Patient Orientation (0020,0020) as stored, e.g. "R\F": the patient directions of the image's
  // rows (+x) and columns (+y); empty when absent. io/dicom_view.h checks it against the pose.
  std::string patient_orientation;
  int bits_allocated = 0;
  int bits_stored = 0;
  bool was_signed = false;  // Pixel Representation 1 (shifted to offset binary)
  // CV_8U / CV_16U, MONOCHROME2 convention; row ranges of one buffer (disjoint, continuous).
  std::vector<cv::Mat> frames;
  std::vector<XrayFrameGeometry> geometry;  // one per frame
};

// Reads all frames of a DICOM file and their geometry (see the header comment).
StatusOr<DicomXrayImage> ReadDicomXray(const std::string& path);

// Error when `image` is a slice of a volume, not a projection: Modality CT / MR / PT / NM or a CT /
// MR image SOP class. The message names the file and points to `carmba ct-fiducials`, so that a
// CT series given as X-ray images is one line, not one "too few blobs" per slice.
Status CheckProjectionImage(const DicomXrayImage& image);

// True for names taken as DICOM: a `#frameN` suffix, the extension .dcm / .dicom (any case), or,
// for a file without one of the image extensions OpenCV reads (png, pgm, ppm, pnm, tif, tiff,
// jpg, jpeg, bmp), the DICM preamble (Siemens .IMA, UID-like names, no extension).
bool IsDicomFileName(const std::string& path);

// The view name of frame `index` (0-based) of a file with `num_frames` frames: the file name
// itself for a single frame, `file#frame<index+1>` otherwise.
std::string DicomFrameName(const std::string& file, int index, int num_frames);

// Splits `file#frameN` into the file and the 0-based frame index (N - 1). Returns false (and
// leaves the outputs alone) when `name` has no such suffix; an error message in *error when the
// suffix is there but N is not a positive integer.
bool SplitDicomFrameName(const std::string& name,
                         std::string* file,
                         int* frame_index,
                         std::string* error);

// What WriteDicomXray writes (tests, and simulated acquisitions for other tools).
struct DicomXrayWriteOptions {
  // "xa" (X-Ray Angiographic Image Storage) or "rf" (X-Ray Radiofluoroscopic Image Storage).
  std::string sop_class = "xa";
  // "MONOCHROME2", or "MONOCHROME1" (the frames are inverted on writing, so that reading gives
  // back the same MONOCHROME2-convention pixels).
  std::string photometric = "MONOCHROME2";
  // Bits Stored (<= the frames' depth: 8 for CV_8U, 16 for CV_16U); 0 = the full depth.
  int bits_stored = 0;
  // "explicit_le" (uncompressed), "jpeg_lossless" (JPEG process 14, selection value 1),
  // "jpeg_ls_lossless", "rle".
  std::string transfer_syntax = "explicit_le";
  // The geometry tags: written when set. Angles are the first frame's; increments, when not
  // empty, are written as given (one value, or one per frame).
  XrayFrameGeometry geometry;
  std::vector<double> primary_increment_deg;
  std::vector<double> secondary_increment_deg;
  std::string patient_orientation;  // (0020,0020), written when not empty, e.g. "R\F"
  std::string study_uid = "1.2.826.0.1.3680043.10.1393.1";
  std::string series_uid = "1.2.826.0.1.3680043.10.1393.1.1";
  std::string sop_instance_uid = "1.2.826.0.1.3680043.10.1393.1.1.1";

  bool Check(std::string* error) const;
};

// Writes `frames` (all CV_8U or all CV_16U, one channel, the same size; values < 2^bits_stored)
// as one DICOM file. Written to `path.tmp.<pid>` first, then renamed.
Status WriteDicomXray(const std::string& path,
                      const std::vector<cv::Mat>& frames,
                      const DicomXrayWriteOptions& options);

}  // namespace carmba
