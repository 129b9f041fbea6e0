#include "io/dicom_xray.h"

#include <gdcmAttribute.h>
#include <gdcmImage.h>
#include <gdcmImageChangeTransferSyntax.h>
#include <gdcmReader.h>
#include <gdcmTrace.h>
#include <gdcmTransferSyntax.h>
#include <gdcmUIDs.h>
#include <gdcmWriter.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <sstream>

#include "io/dicom_image.h"
#include "util/dicom_structure.h"
#include "util/file_util.h"
#include "util/gdcm_util.h"
#include "util/quiet_stderr.h"
#include "util/temp_paths.h"

namespace carmba {
namespace {

using gdcm_util::GetString;
using gdcm_util::PutString;
using gdcm_util::PutUS;
using gdcm_util::Trim;


std::string TagName(uint16_t g, uint16_t e) {
  char b[16];
  std::snprintf(b, sizeof(b), "(%04x,%04x)", g, e);
  return b;
}

// The decimal values (DS / IS) of an element: empty when absent or empty; an error naming the
// file and the tag when a value is not a finite number.
Status GetDecimals(const gdcm::DataSet& ds,
                   uint16_t g,
                   uint16_t e,
                   const std::string& what,
                   const std::string& path,
                   std::vector<double>* out) {
  out->clear();
  const std::string s = GetString(ds, g, e);
  if (s.empty()) return Status::Ok();
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, '\\')) {
    item = Trim(item);
    char* end = nullptr;
    const double v = std::strtod(item.c_str(), &end);
    if (item.empty() || *end != '\0' || !std::isfinite(v)) {
      return Status::Error(path + ": " + what + " " + TagName(g, e) + " is '" + s +
                           "', expected decimal numbers separated by '\\'");
    }
    out->push_back(v);
  }
  return Status::Ok();
}

// One value, or none (absent / empty); `positive` requires > 0.
Status GetOptional(const gdcm::DataSet& ds,
                   uint16_t g,
                   uint16_t e,
                   const std::string& what,
                   const std::string& path,
                   bool positive,
                   std::optional<double>* out) {
  std::vector<double> v;
  CARMBA_RETURN_IF_ERROR(GetDecimals(ds, g, e, what, path, &v));
  out->reset();
  if (v.empty()) return Status::Ok();
  if (v.size() != 1) {
    return Status::Error(path + ": " + what + " " + TagName(g, e) + " has " +
                         std::to_string(v.size()) + " values, expected 1");
  }
  if (positive && !(v[0] > 0)) {
    return Status::Error(path + ": " + what + " " + TagName(g, e) + " is " + GetString(ds, g, e) +
                         ", expected a positive number");
  }
  *out = v[0];
  return Status::Ok();
}


Status ReadGeometry(const gdcm::DataSet& ds,
                    const std::string& path,
                    int num_frames,
                    std::vector<XrayFrameGeometry>* out) {
  XrayFrameGeometry base;
  CARMBA_RETURN_IF_ERROR(GetOptional(
      ds, 0x0018, 0x1510, "Positioner Primary Angle", path, false, &base.primary_angle_deg));
  CARMBA_RETURN_IF_ERROR(GetOptional(
      ds, 0x0018, 0x1511, "Positioner Secondary Angle", path, false, &base.secondary_angle_deg));
  CARMBA_RETURN_IF_ERROR(
      GetOptional(ds, 0x0018, 0x1110, "Distance Source to Detector", path, true, &base.sid_mm));
  CARMBA_RETURN_IF_ERROR(
      GetOptional(ds, 0x0018, 0x1111, "Distance Source to Patient", path, true, &base.sod_mm));
  CARMBA_RETURN_IF_ERROR(GetOptional(ds,
                                     0x0018,
                                     0x1114,
                                     "Estimated Radiographic Magnification Factor",
                                     path,
                                     true,
                                     &base.magnification));
  std::vector<double> spacing;
  CARMBA_RETURN_IF_ERROR(GetDecimals(ds, 0x0018, 0x1164, "Imager Pixel Spacing", path, &spacing));
  if (!spacing.empty()) {
    if (spacing.size() != 2 || !(spacing[0] > 0) || !(spacing[1] > 0)) {
      return Status::Error(path + ": Imager Pixel Spacing (0018,1164) is '" +
                           GetString(ds, 0x0018, 0x1164) +
                           "', expected two positive numbers (row\\column spacing, mm)");
    }
    base.pixel_spacing_row_mm = spacing[0];
    base.pixel_spacing_col_mm = spacing[1];
  }
  std::vector<double> inc[2];
  const char* inc_name[2] = {"Positioner Primary Angle Increment",
                             "Positioner Secondary Angle Increment"};
  for (int a = 0; a < 2; ++a) {
    const uint16_t e = a == 0 ? 0x1520 : 0x1521;
    CARMBA_RETURN_IF_ERROR(GetDecimals(ds, 0x0018, e, inc_name[a], path, &inc[a]));
    if (inc[a].size() > 1 && static_cast<int>(inc[a].size()) != num_frames) {
      return Status::Error(path + ": " + inc_name[a] + " " + TagName(0x0018, e) + " has " +
                           std::to_string(inc[a].size()) +
                           " values, expected 1 or one per frame (" + std::to_string(num_frames) +
                           ")");
    }
  }
  out->assign(num_frames, base);
  for (int k = 0; k < num_frames; ++k) {
    // PS3.3 C.8.7.5.1.3: one value = the change per frame; one per frame = offsets from the first
    // frame's angle.
    auto offset = [&](const std::vector<double>& v) {
      if (v.empty()) return 0.0;
      return v.size() == 1 ? k * v[0] : v[k];
    };
    XrayFrameGeometry& g = (*out)[k];
    if (g.primary_angle_deg) *g.primary_angle_deg += offset(inc[0]);
    if (g.secondary_angle_deg) *g.secondary_angle_deg += offset(inc[1]);
  }
  return Status::Ok();
}

// To the MONOCHROME2-convention stored value in place (see the header); nothing to do for the
// common case of unsigned MONOCHROME2 data using all its bits.
template <typename T>
void ToStoredValues(T* p, size_t n, int bits_stored, int high_bit, bool is_signed, bool mono1) {
  const int shift = high_bit + 1 - bits_stored;
  const uint32_t mask = (1u << bits_stored) - 1u;
  const uint32_t sign_bit = 1u << (bits_stored - 1);
  if (shift == 0 && bits_stored == 8 * static_cast<int>(sizeof(T)) && !is_signed && !mono1) {
    return;
  }
  for (size_t i = 0; i < n; ++i) {
    uint32_t v = (static_cast<uint32_t>(p[i]) >> shift) & mask;
    if (is_signed) v ^= sign_bit;  // two's complement -> offset binary
    if (mono1) v = mask - v;
    p[i] = static_cast<T>(v);
  }
}

}  // namespace

bool IsDicomFileName(const std::string& path) {
  std::string file;
  int frame = 0;
  std::string err;
  if (SplitDicomFrameName(path, &file, &frame, &err)) return true;
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) {
    return static_cast<char>(std::tolower(c));
  });
  if (ext == ".dcm" || ext == ".dicom") return true;
  static const char* kOtherImages[] = {
      ".png", ".pgm", ".ppm", ".pnm", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp"};
  for (const char* e : kOtherImages) {
    if (ext == e) return false;
  }
  return HasDicmMarker(path);
}

std::string DicomFrameName(const std::string& file, int index, int num_frames) {
  return num_frames == 1 ? file : file + "#frame" + std::to_string(index + 1);
}

bool SplitDicomFrameName(const std::string& name,
                         std::string* file,
                         int* frame_index,
                         std::string* error) {
  const FrameName split = SplitFrameSuffix(name);
  if (split.suffix.empty()) return false;
  const std::string num = split.suffix.substr(6);  // after "#frame"
  char* end = nullptr;
  const long n = std::strtol(num.c_str(), &end, 10);
  if (num.empty() || *end != '\0' || n < 1 || n > 1000000) {
    *error = name + ": frame suffix '#frame" + num + "', expected #frameN with N = 1, 2, ...";
    return true;
  }
  *file = split.file;
  *frame_index = static_cast<int>(n - 1);
  return true;
}

Status CheckProjectionImage(const DicomXrayImage& image) {
  // CT Image, Enhanced CT, MR Image, Enhanced MR Image Storage.
  static const char* kVolumeClasses[] = {"1.2.840.10008.5.1.4.1.1.2",
                                         "1.2.840.10008.5.1.4.1.1.2.1",
                                         "1.2.840.10008.5.1.4.1.1.4",
                                         "1.2.840.10008.5.1.4.1.1.4.1"};
  bool volume = image.modality == "CT" || image.modality == "MR" || image.modality == "PT" ||
                image.modality == "NM";
  for (const char* uid : kVolumeClasses) volume = volume || image.sop_class_uid == uid;
  if (!volume) return Status::Ok();
  const std::string what = image.modality.empty() ? "SOP Class " + image.sop_class_uid
                                                  : "Modality " + image.modality;
  return Status::Error(image.file + " is a " + (image.modality.empty() ? "CT" : image.modality) +
                       " slice (" + what + "), not an X-ray projection: a CT series is read by " +
                       "'carmba ct-fiducials --dicom DIR'");
}

StatusOr<DicomXrayImage> ReadDicomXray(const std::string& path) {
  DicomImage image;
  DicomImageKind kind;
  CARMBA_RETURN_IF_ERROR(ReadDicomImage(path, DicomImageOptions(), &image, &kind));
  if (kind == DicomImageKind::kNotDicom) {
    return Status::Error(path +
                         ": not a DICOM file (no DICM preamble, no DICOM element at the "
                         "start)");
  }
  const gdcm::DataSet& ds = image.data_set();
  if (kind == DicomImageKind::kNoPixelData) {
    if (ds.FindDataElement(gdcm::Tag(0x0028, 0x0010))) {
      return Status::Error(path +
                           ": corrupt or truncated DICOM image: Rows (0028,0010) but no "
                           "Pixel Data (7fe0,0010)");
    }
    return Status::Error(path + ": no Pixel Data (7fe0,0010): not an image");
  }
  DicomXrayImage out;
  out.file = path;
  out.sop_class_uid = GetString(ds, 0x0008, 0x0016);
  out.modality = GetString(ds, 0x0008, 0x0060);
  out.transfer_syntax_uid = image.transfer_syntax_uid;
  out.photometric = image.photometric;
  out.patient_orientation = GetString(ds, 0x0020, 0x0020);
  const auto pi = gdcm::PhotometricInterpretation::GetPIType(out.photometric.c_str());
  if (pi != gdcm::PhotometricInterpretation::MONOCHROME1 &&
      pi != gdcm::PhotometricInterpretation::MONOCHROME2) {
    return Status::Error(path + ": Photometric Interpretation (0028,0004) is '" + out.photometric +
                         "', expected MONOCHROME1 or MONOCHROME2");
  }
  out.bits_allocated = image.bits_allocated;
  out.bits_stored = image.bits_stored;
  out.was_signed = image.is_signed;
  const int rows = image.rows, cols = image.columns, num_frames = image.frames;
  const size_t bytes_per = out.bits_allocated / 8;
  // All frames in one buffer, one row range per frame.
  cv::Mat all(rows * num_frames, cols, bytes_per == 1 ? CV_8UC1 : CV_16UC1);
  std::memcpy(all.data, image.pixels.data(), image.pixels.size());
  image.pixels = std::vector<char>();
  const bool mono1 = pi == gdcm::PhotometricInterpretation::MONOCHROME1;
  if (bytes_per == 1) {
    ToStoredValues(
        all.ptr<uint8_t>(), all.total(), out.bits_stored, image.high_bit, out.was_signed, mono1);
  } else {
    ToStoredValues(
        all.ptr<uint16_t>(), all.total(), out.bits_stored, image.high_bit, out.was_signed, mono1);
  }
  for (int f = 0; f < num_frames; ++f) out.frames.push_back(all.rowRange(f * rows, (f + 1) * rows));
  CARMBA_RETURN_IF_ERROR(ReadGeometry(ds, path, num_frames, &out.geometry));
  return out;
}

// ---------------------------------------------------------------------------------------------
// Writing.

namespace {

std::string Decimal(double value) {
  for (int precision = 12; precision >= 1; --precision) {
    char b[64];
    std::snprintf(b, sizeof(b), "%.*g", precision, value);
    if (std::string(b).size() <= 16) return b;
  }
  return "0";
}

std::string Decimals(const std::vector<double>& v) {
  std::string s;
  for (size_t i = 0; i < v.size(); ++i) s += (i ? "\\" : "") + Decimal(v[i]);
  return s;
}

}  // namespace

bool DicomXrayWriteOptions::Check(std::string* error) const {
  if (sop_class != "xa" && sop_class != "rf") {
    return *error = "sop_class must be 'xa' or 'rf', not '" + sop_class + "'", false;
  }
  if (photometric != "MONOCHROME1" && photometric != "MONOCHROME2") {
    return *error = "photometric must be MONOCHROME1 or MONOCHROME2, not '" + photometric + "'",
           false;
  }
  if (transfer_syntax != "explicit_le" && transfer_syntax != "jpeg_lossless" &&
      transfer_syntax != "jpeg_ls_lossless" && transfer_syntax != "rle") {
    return *error =
               "transfer_syntax must be explicit_le, jpeg_lossless, jpeg_ls_lossless or rle, "
               "not '" +
               transfer_syntax + "'",
           false;
  }
  if (bits_stored < 0 || bits_stored > 16) return *error = "bits_stored must be 0..16", false;
  return true;
}

namespace {

// The frames' pixels in one buffer (MONOCHROME1: inverted); an error when a value exceeds
// 2^bits - 1.
Status PackFrames(const std::string& path,
                  const std::vector<cv::Mat>& frames,
                  int depth_bits,
                  int bits,
                  bool mono1,
                  std::vector<char>* buffer) {
  const cv::Mat& f0 = frames[0];
  const uint32_t max_value = (1u << bits) - 1u;
  const size_t n = static_cast<size_t>(f0.rows) * f0.cols;
  buffer->assign(n * frames.size() * (depth_bits / 8), 0);
  for (size_t k = 0; k < frames.size(); ++k) {
    cv::Mat f = frames[k].isContinuous() ? frames[k] : frames[k].clone();
    double hi = 0;
    cv::minMaxLoc(f, nullptr, &hi);
    if (hi > max_value) {
      return Status::Error(path + ": frame " + std::to_string(k + 1) + " has value " +
                           std::to_string(static_cast<int>(hi)) +
                           " > 2^bits_stored - 1 = " + std::to_string(max_value));
    }
    if (mono1) {
      cv::Mat inverted = cv::Scalar::all(max_value) - f;  // a new buffer: the input is const
      f = inverted;
    }
    std::memcpy(buffer->data() + k * n * (depth_bits / 8), f.data, n * (depth_bits / 8));
  }

  return Status::Ok();
}

// The pixel data element in the transfer syntax the options ask for (GDCM encodes it); *ts the
// syntax.
StatusOr<gdcm::DataElement> EncodePixels(const std::string& path,
                                         const std::vector<cv::Mat>& frames,
                                         const std::vector<char>& buffer,
                                         int depth_bits,
                                         int bits,
                                         bool mono1,
                                         const DicomXrayWriteOptions& options,
                                         gdcm::TransferSyntax* ts_out) {
  const cv::Mat& f0 = frames[0];
  // Reference counted: a filter's SetInput takes a SmartPointer to it (a stack object would be
  // deleted by the filter).
  gdcm::SmartPointer<gdcm::Image> image_ptr = new gdcm::Image;
  gdcm::Image& image = *image_ptr;
  image.SetNumberOfDimensions(frames.size() > 1 ? 3 : 2);
  image.SetDimension(0, f0.cols);
  image.SetDimension(1, f0.rows);
  if (frames.size() > 1) image.SetDimension(2, static_cast<unsigned int>(frames.size()));
  gdcm::PixelFormat pf(depth_bits == 8 ? gdcm::PixelFormat::UINT8 : gdcm::PixelFormat::UINT16);
  pf.SetBitsStored(static_cast<uint16_t>(bits));
  pf.SetHighBit(static_cast<uint16_t>(bits - 1));
  image.SetPixelFormat(pf);
  image.SetPhotometricInterpretation(mono1 ? gdcm::PhotometricInterpretation::MONOCHROME1
                                           : gdcm::PhotometricInterpretation::MONOCHROME2);
  image.SetTransferSyntax(gdcm::TransferSyntax::ExplicitVRLittleEndian);
  gdcm::DataElement pixels(gdcm::Tag(0x7fe0, 0x0010));
  pixels.SetVR(depth_bits == 8 ? gdcm::VR::OB : gdcm::VR::OW);
  pixels.SetByteValue(buffer.data(), static_cast<uint32_t>(buffer.size()));
  image.SetDataElement(pixels);

  gdcm::TransferSyntax& ts = *ts_out;
  ts = gdcm::TransferSyntax::ExplicitVRLittleEndian;
  gdcm::DataElement encoded = pixels;
  if (options.transfer_syntax != "explicit_le") {
    ts = options.transfer_syntax == "jpeg_lossless" ? gdcm::TransferSyntax::JPEGLosslessProcess14_1
         : options.transfer_syntax == "jpeg_ls_lossless" ? gdcm::TransferSyntax::JPEGLSLossless
                                                         : gdcm::TransferSyntax::RLELossless;
    gdcm::ImageChangeTransferSyntax change;
    change.SetTransferSyntax(ts);
    change.SetInput(image);
    bool changed;
    {
      QuietStderr quiet;
      changed = change.Change();
    }
    if (!changed) {
      return Status::Error(path + ": GDCM cannot encode the frames as " + options.transfer_syntax);
    }
    encoded = change.GetOutput().GetDataElement();
  }

  return encoded;
}

// The XA / RF image's tags: SOP class and instance, patient, the C-arm geometry, UIDs, the image
// pixel module.
void PutXrayTags(gdcm::DataSet& ds, const std::vector<cv::Mat>& frames, int depth_bits, int bits,
                 const DicomXrayWriteOptions& options) {
  const cv::Mat& f0 = frames[0];
  const bool xa = options.sop_class == "xa";
  PutString(&ds, 0x0008, 0x0008, gdcm::VR::CS, "ORIGINAL\\PRIMARY\\SINGLE PLANE");
  PutString(&ds,
            0x0008,
            0x0016,
            gdcm::VR::UI,
            xa ? "1.2.840.10008.5.1.4.1.1.12.1" : "1.2.840.10008.5.1.4.1.1.12.2");
  PutString(&ds, 0x0008, 0x0018, gdcm::VR::UI, options.sop_instance_uid);
  PutString(&ds, 0x0008, 0x0060, gdcm::VR::CS, xa ? "XA" : "RF");
  PutString(&ds, 0x0008, 0x0070, gdcm::VR::LO, "carmba");
  PutString(&ds, 0x0010, 0x0010, gdcm::VR::PN, "CARMBA^PHANTOM");
  PutString(&ds, 0x0010, 0x0020, gdcm::VR::LO, "CARMBA0001");
  const XrayFrameGeometry& g = options.geometry;
  if (g.sid_mm) PutString(&ds, 0x0018, 0x1110, gdcm::VR::DS, Decimal(*g.sid_mm));
  if (g.sod_mm) PutString(&ds, 0x0018, 0x1111, gdcm::VR::DS, Decimal(*g.sod_mm));
  if (g.magnification) PutString(&ds, 0x0018, 0x1114, gdcm::VR::DS, Decimal(*g.magnification));
  if (g.pixel_spacing_row_mm && g.pixel_spacing_col_mm) {
    PutString(&ds,
              0x0018,
              0x1164,
              gdcm::VR::DS,
              Decimal(*g.pixel_spacing_row_mm) + "\\" + Decimal(*g.pixel_spacing_col_mm));
  }
  PutString(&ds,
            0x0018,
            0x1500,
            gdcm::VR::CS,
            options.primary_increment_deg.empty() && options.secondary_increment_deg.empty()
                ? "STATIC"
                : "DYNAMIC");
  if (g.primary_angle_deg) {
    PutString(&ds, 0x0018, 0x1510, gdcm::VR::DS, Decimal(*g.primary_angle_deg));
  }
  if (g.secondary_angle_deg) {
    PutString(&ds, 0x0018, 0x1511, gdcm::VR::DS, Decimal(*g.secondary_angle_deg));
  }
  if (!options.primary_increment_deg.empty()) {
    PutString(&ds, 0x0018, 0x1520, gdcm::VR::DS, Decimals(options.primary_increment_deg));
  }
  if (!options.secondary_increment_deg.empty()) {
    PutString(&ds, 0x0018, 0x1521, gdcm::VR::DS, Decimals(options.secondary_increment_deg));
  }
  PutString(&ds, 0x0020, 0x000d, gdcm::VR::UI, options.study_uid);
  PutString(&ds, 0x0020, 0x000e, gdcm::VR::UI, options.series_uid);
  PutString(&ds, 0x0020, 0x0011, gdcm::VR::IS, "1");
  PutString(&ds, 0x0020, 0x0013, gdcm::VR::IS, "1");
  if (!options.patient_orientation.empty()) {
    PutString(&ds, 0x0020, 0x0020, gdcm::VR::CS, options.patient_orientation);
  }
  PutUS<0x0028, 0x0002>(&ds, 1);
  PutString(&ds, 0x0028, 0x0004, gdcm::VR::CS, options.photometric);
  if (frames.size() > 1) {
    PutString(&ds, 0x0028, 0x0008, gdcm::VR::IS, std::to_string(frames.size()));
  }
  PutUS<0x0028, 0x0010>(&ds, static_cast<uint16_t>(f0.rows));
  PutUS<0x0028, 0x0011>(&ds, static_cast<uint16_t>(f0.cols));
  PutUS<0x0028, 0x0100>(&ds, static_cast<uint16_t>(depth_bits));
  PutUS<0x0028, 0x0101>(&ds, static_cast<uint16_t>(bits));
  PutUS<0x0028, 0x0102>(&ds, static_cast<uint16_t>(bits - 1));
  PutUS<0x0028, 0x0103>(&ds, 0);
  PutString(&ds, 0x0028, 0x1040, gdcm::VR::CS, "LIN");
}

// Writes through a temporary file renamed into place (removed on failure, SIGINT, SIGTERM).
Status WriteAtomically(const std::string& path, gdcm::Writer* writer_ptr) {
  gdcm::Writer& writer = *writer_ptr;
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  const TempPathRegistration registration(tmp);  // removed on SIGINT / SIGTERM
  writer.SetFileName(tmp.c_str());
  bool written;
  {
    QuietStderr quiet;
    written = writer.Write();
  }
  std::error_code ec;
  if (!written) {
    std::filesystem::remove(tmp, ec);
    return Status::Error(path + ": GDCM could not write the file");
  }
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    return Status::Error(path + ": cannot rename the written file into place");
  }
  return Status::Ok();
}

}  // namespace

Status WriteDicomXray(const std::string& path,
                      const std::vector<cv::Mat>& frames,
                      const DicomXrayWriteOptions& options) {
  SilenceGdcm();
  std::string error;
  if (!options.Check(&error)) return Status::Error(path + ": DICOM write options: " + error);
  if (frames.empty()) return Status::Error(path + ": no frames to write");
  const cv::Mat& f0 = frames[0];
  if ((f0.type() != CV_8UC1 && f0.type() != CV_16UC1) || f0.rows > 65535 || f0.cols > 65535) {
    return Status::Error(path + ": frames must be CV_8UC1 or CV_16UC1 of at most 65535 px a side");
  }
  for (const auto& f : frames) {
    if (f.type() != f0.type() || f.size() != f0.size()) {
      return Status::Error(path + ": all frames must have the first frame's size and type");
    }
  }
  const int depth_bits = f0.type() == CV_8UC1 ? 8 : 16;
  const int bits = options.bits_stored > 0 ? options.bits_stored : depth_bits;
  if (bits > depth_bits) {
    return Status::Error(path + ": bits_stored " + std::to_string(bits) + " exceeds the frames' " +
                         std::to_string(depth_bits) + " bits");
  }
  const bool mono1 = options.photometric == "MONOCHROME1";
  std::vector<char> buffer;
  CARMBA_RETURN_IF_ERROR(PackFrames(path, frames, depth_bits, bits, mono1, &buffer));
  gdcm::TransferSyntax ts;
  auto encoded = EncodePixels(path, frames, buffer, depth_bits, bits, mono1, options, &ts);
  if (!encoded.ok()) return encoded.status();
  gdcm::Writer writer;
  gdcm::File& file = writer.GetFile();
  gdcm::DataSet& ds = file.GetDataSet();
  PutXrayTags(ds, frames, depth_bits, bits, options);
  ds.Replace(*encoded);
  file.GetHeader().SetDataSetTransferSyntax(ts);
  return WriteAtomically(path, &writer);
}

}  // namespace carmba
