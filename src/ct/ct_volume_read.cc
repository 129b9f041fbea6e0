// Reading DICOM CT series (ct_volume.h: ReadCtSeries).
#include "ct/ct_volume.h"

#include <gdcmAttribute.h>
#include <gdcmFileMetaInformation.h>
#include <gdcmReader.h>
#include <gdcmTrace.h>
#include <gdcmTransferSyntax.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <system_error>
#include <fcntl.h>
#include <unistd.h>

#include "io/dicom_image.h"
#include "util/file_util.h"
#include "util/gdcm_util.h"

namespace carmba {
namespace fs = std::filesystem;

namespace {

using gdcm_util::GetString;
using gdcm_util::Trim;

std::string FixedDecimals(double v, int precision = 6) {
  char b[64];
  std::snprintf(b, sizeof(b), "%.*f", precision, v);
  return b;
}

// A backslash-separated list of decimal numbers (DS/IS); false when absent, malformed or of the
// wrong count.
bool GetNumbers(const gdcm::DataSet& ds,
                uint16_t group,
                uint16_t element,
                size_t count,
                std::vector<double>* out) {
  const std::string s = GetString(ds, group, element);
  if (s.empty()) return false;
  out->clear();
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, '\\')) {
    item = Trim(item);
    char* end = nullptr;
    const double v = std::strtod(item.c_str(), &end);
    if (item.empty() || *end != '\0' || !std::isfinite(v)) return false;
    out->push_back(v);
  }
  return out->size() == count;
}

struct Slice {
  std::string file;
  std::string series_uid;
  int rows = 0, columns = 0;
  Eigen::Vector3d ipp, row_dir, col_dir;
  double row_spacing = 0, col_spacing = 0;  // PixelSpacing[0], PixelSpacing[1]
  double slope = 1, intercept = 0;
  double thickness = 0;
  double position = 0;  // along the normal
  std::vector<float> values;  // rescaled to HU
};

template <typename T>
void Rescale(const char* raw, size_t n, double slope, double intercept, float* out) {
  const T* p = reinterpret_cast<const T*>(raw);
  for (size_t i = 0; i < n; ++i) out[i] = static_cast<float>(slope * p[i] + intercept);
}

// Reads one file. Returns ok with *is_image false for files to skip (not DICOM, no pixel data).
Status ReadSlice(const std::string& path, Slice* slice, bool* is_image) {
  *is_image = false;
  DicomImage image;
  DicomImageKind kind;
  DicomImageOptions options;
  options.allow_32_bit = true;
  const Status read = ReadDicomImage(path, options, &image, &kind);
  if (!read.ok()) return read;
  if (kind == DicomImageKind::kNotDicom) return Status::Ok();  // not DICOM: skipped
  const gdcm::DataSet& ds = image.data_set();
  if (kind == DicomImageKind::kNoPixelData) {
    const std::string sop_class = GetString(ds, 0x0008, 0x0016);
    const bool ct_class = sop_class.rfind("1.2.840.10008.5.1.4.1.1.2", 0) == 0;
    if (!ds.FindDataElement(gdcm::Tag(0x0028, 0x0010)) && !ct_class) {
      return Status::Ok();  // not an image (DICOMDIR, report, ...): skipped
    }
    return Status::Error(path + ": corrupt DICOM image: a CT image or Rows (0028,0010) but "
                                "no PixelData (7fe0,0010), truncated?");
  }
  if (image.frames > 1) {
    return Status::Error(path + ": multi-frame image (" + std::to_string(image.frames) +
                         " frames), expected one slice per file");
  }
  slice->file = path;
  slice->columns = image.columns;
  slice->rows = image.rows;
  slice->series_uid = GetString(ds, 0x0020, 0x000e);
  std::vector<double> v;
  if (!GetNumbers(ds, 0x0020, 0x0032, 3, &v)) {
    return Status::Error(path + ": missing or malformed ImagePositionPatient (0020,0032), "
                                "expected 3 numbers");
  }
  slice->ipp = Eigen::Vector3d(v[0], v[1], v[2]);
  if (!GetNumbers(ds, 0x0020, 0x0037, 6, &v)) {
    return Status::Error(path + ": missing or malformed ImageOrientationPatient (0020,0037), "
                                "expected 6 numbers");
  }
  slice->row_dir = Eigen::Vector3d(v[0], v[1], v[2]);
  slice->col_dir = Eigen::Vector3d(v[3], v[4], v[5]);
  if (std::abs(slice->row_dir.norm() - 1) > 1e-3 || std::abs(slice->col_dir.norm() - 1) > 1e-3 ||
      std::abs(slice->row_dir.dot(slice->col_dir)) > 1e-3) {
    return Status::Error(path + ": ImageOrientationPatient (0020,0037) is not two orthogonal "
                                "unit vectors");
  }
  if (!GetNumbers(ds, 0x0028, 0x0030, 2, &v) || !(v[0] > 0) || !(v[1] > 0)) {
    return Status::Error(path + ": missing or malformed PixelSpacing (0028,0030), expected two "
                                "positive numbers");
  }
  slice->row_spacing = v[0];
  slice->col_spacing = v[1];
  if (GetNumbers(ds, 0x0028, 0x1053, 1, &v)) slice->slope = v[0];
  if (GetNumbers(ds, 0x0028, 0x1052, 1, &v)) slice->intercept = v[0];
  if (!(slice->slope != 0)) {
    return Status::Error(path + ": RescaleSlope (0028,1053) is 0");
  }
  if (GetNumbers(ds, 0x0018, 0x0050, 1, &v) && v[0] > 0) slice->thickness = v[0];

  const size_t n = static_cast<size_t>(slice->rows) * slice->columns;
  slice->values.resize(n);
  float* out = slice->values.data();
  const double s = slice->slope, b = slice->intercept;
  const char* raw = image.pixels.data();
  switch (image.bits_allocated) {
    case 8:
      if (image.is_signed) Rescale<int8_t>(raw, n, s, b, out);
      else Rescale<uint8_t>(raw, n, s, b, out);
      break;
    case 16:
      if (image.is_signed) Rescale<int16_t>(raw, n, s, b, out);
      else Rescale<uint16_t>(raw, n, s, b, out);
      break;
    default:
      if (image.is_signed) Rescale<int32_t>(raw, n, s, b, out);
      else Rescale<uint32_t>(raw, n, s, b, out);
      break;
  }
  *is_image = true;
  return Status::Ok();
}

}  // namespace

bool CtReadOptions::Check(std::string* error) const {
  if (!(spacing_tolerance_mm > 0)) {
    *error = "spacing_tolerance_mm must be > 0";
    return false;
  }
  if (!(orientation_tolerance > 0)) {
    *error = "orientation_tolerance must be > 0";
    return false;
  }
  return true;
}

StatusOr<CtVolume> ReadCtSeries(const std::string& dir,
                                const CtReadOptions& options,
                                std::vector<std::string>* skipped_files) {
  SilenceGdcm();
  std::string error;
  if (!options.Check(&error)) return Status::Error("CT read options: " + error);
  if (!IsDirectory(dir)) return Status::Error(dir + ": not a directory");
  std::vector<std::string> paths;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    if (e.is_regular_file()) paths.push_back(e.path().string());
  }
  if (ec) return Status::Error(dir + ": cannot list directory: " + ec.message());
  std::sort(paths.begin(), paths.end());

  std::map<std::string, std::vector<Slice>> by_series;
  std::vector<std::string> skipped;
  for (const auto& p : paths) {
    Slice s;
    bool is_image = false;
    CARMBA_RETURN_IF_ERROR(ReadSlice(p, &s, &is_image));
    if (!is_image) {
      skipped.push_back(p);
      continue;
    }
    by_series[s.series_uid].push_back(std::move(s));
  }
  if (skipped_files) *skipped_files = skipped;
  if (by_series.empty()) {
    return Status::Error(dir + ": no DICOM image files (" + std::to_string(paths.size()) +
                         " files looked at)");
  }
  std::vector<Slice> slices;
  if (!options.series_uid.empty()) {
    auto it = by_series.find(options.series_uid);
    if (it == by_series.end()) {
      std::string list;
      for (const auto& [uid, v] : by_series) list += (list.empty() ? "" : ", ") + uid;
      return Status::Error(dir + ": no series with SeriesInstanceUID '" + options.series_uid +
                           "' (found: " + list + ")");
    }
    slices = std::move(it->second);
  } else if (by_series.size() > 1) {
    std::string list;
    for (const auto& [uid, v] : by_series) {
      list += (list.empty() ? "" : ", ") + (uid.empty() ? std::string("<none>") : uid) + " (" +
              std::to_string(v.size()) + " files)";
    }
    return Status::Error(dir + ": " + std::to_string(by_series.size()) +
                         " series mixed in one directory, select one by SeriesInstanceUID: " +
                         list);
  } else {
    slices = std::move(by_series.begin()->second);
  }

  // Consistency of size, orientation and pixel spacing with the first file.
  const Slice& ref = slices.front();
  for (const auto& s : slices) {
    if (s.rows != ref.rows || s.columns != ref.columns) {
      return Status::Error(s.file + ": " + std::to_string(s.columns) + "x" +
                           std::to_string(s.rows) + " pixels, but " + ref.file + " has " +
                           std::to_string(ref.columns) + "x" + std::to_string(ref.rows));
    }
    if ((s.row_dir - ref.row_dir).cwiseAbs().maxCoeff() > options.orientation_tolerance ||
        (s.col_dir - ref.col_dir).cwiseAbs().maxCoeff() > options.orientation_tolerance) {
      return Status::Error(s.file + ": ImageOrientationPatient differs from that of " + ref.file +
                           " (inconsistent orientation within the series)");
    }
    if (std::abs(s.row_spacing - ref.row_spacing) > 1e-6 ||
        std::abs(s.col_spacing - ref.col_spacing) > 1e-6) {
      return Status::Error(s.file + ": PixelSpacing differs from that of " + ref.file);
    }
  }
  // Orthonormalised in-plane axes and the normal.
  Eigen::Vector3d x = ref.row_dir.normalized();
  Eigen::Vector3d y = (ref.col_dir - x.dot(ref.col_dir) * x).normalized();
  const Eigen::Vector3d normal = x.cross(y);
  for (auto& s : slices) s.position = s.ipp.dot(normal);
  std::sort(slices.begin(), slices.end(),
            [](const Slice& a, const Slice& b) { return a.position < b.position; });

  CtVolume vol;
  vol.columns = ref.columns;
  vol.rows = ref.rows;
  vol.slices = static_cast<int>(slices.size());
  vol.series_uid = ref.series_uid;
  vol.slice_thickness_mm = ref.thickness;
  vol.spacing_mm = Eigen::Vector3d(ref.col_spacing, ref.row_spacing, 0);
  vol.origin_mm = slices.front().ipp;
  Eigen::Vector3d step;
  const int n = vol.slices;
  if (n == 1) {
    if (!(ref.thickness > 0)) {
      return Status::Error(ref.file + ": a single-slice series without SliceThickness "
                                      "(0018,0050): the slice spacing is unknown");
    }
    step = ref.thickness * normal;
  } else {
    std::vector<double> steps;
    for (int k = 0; k + 1 < n; ++k) {
      const double d = slices[k + 1].position - slices[k].position;
      if (d < 1e-3) {
        return Status::Error(dir + ": two slices at the same position " +
                             FixedDecimals(slices[k].position, 3) + " mm along the normal: " +
                             BaseName(slices[k].file) + " and " + BaseName(slices[k + 1].file));
      }
      steps.push_back(d);
    }
    std::vector<double> sorted = steps;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double expected = sorted[sorted.size() / 2];
    for (int k = 0; k + 1 < n; ++k) {
      if (std::abs(steps[k] - expected) > options.spacing_tolerance_mm) {
        const double missing = steps[k] / expected - 1;
        return Status::Error(
            dir + ": unevenly spaced or missing slices: gap of " + FixedDecimals(steps[k], 3) +
            " mm between " + BaseName(slices[k].file) + " (at " +
            FixedDecimals(slices[k].position, 3) + " mm along the slice normal) and " +
            BaseName(slices[k + 1].file) + " (at " + FixedDecimals(slices[k + 1].position, 3) +
            " mm), expected " + FixedDecimals(expected, 3) + " mm like the other slices" +
            (missing > 0.5 ? " (about " + std::to_string(static_cast<int>(std::lround(missing))) +
                                 " slices missing)"
                           : ""));
      }
    }
    step = (slices.back().ipp - slices.front().ipp) / (n - 1);
    for (int k = 0; k + 1 < n; ++k) {
      const Eigen::Vector3d d = slices[k + 1].ipp - slices[k].ipp;
      if ((d - step).norm() > options.spacing_tolerance_mm + 1e-6 * step.norm()) {
        return Status::Error(dir + ": inconsistent in-plane offset between " +
                             BaseName(slices[k].file) + " and " + BaseName(slices[k + 1].file) +
                             ": ImagePositionPatient moves by (" + FixedDecimals(d.x(), 3) + ", " +
                             FixedDecimals(d.y(), 3) + ", " + FixedDecimals(d.z(), 3) +
                             ") mm, expected (" + FixedDecimals(step.x(), 3) + ", " +
                             FixedDecimals(step.y(), 3) + ", " + FixedDecimals(step.z(), 3) + ")");
      }
    }
  }
  vol.spacing_mm.z() = step.norm();
  vol.axes.col(0) = x;
  vol.axes.col(1) = y;
  vol.axes.col(2) = step.normalized();
  const size_t per_slice = static_cast<size_t>(vol.rows) * vol.columns;
  vol.hu.resize(per_slice * n);
  for (int k = 0; k < n; ++k) {
    std::copy(slices[k].values.begin(), slices[k].values.end(), vol.hu.begin() + per_slice * k);
    vol.files.push_back(slices[k].file);
  }
  return vol;
}

}  // namespace carmba
