// Writing DICOM CT series (ct_volume.h: WriteCtSeries, FormatDicomDecimal).
#include <gdcmAttribute.h>
#include <gdcmFileMetaInformation.h>
#include <gdcmImage.h>
#include <gdcmTransferSyntax.h>
#include <gdcmWriter.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <system_error>
#include <fcntl.h>
#include <unistd.h>

#include "ct/ct_volume.h"
#include "util/gdcm_util.h"
#include "util/file_util.h"
#include "util/temp_paths.h"

namespace carmba {
namespace fs = std::filesystem;

std::string FormatDicomDecimal(double value) {
  if (value == 0) return "0";
  for (int precision = 12; precision >= 1; --precision) {
    char b[64];
    std::snprintf(b, sizeof(b), "%.*g", precision, value);
    if (std::strlen(b) <= 16) return b;
  }
  return "0";
}

namespace {

using gdcm_util::PutString;
using gdcm_util::PutUS;

bool ValidUid(const std::string& uid) {
  if (uid.empty() || uid.size() > 64) return false;
  for (char c : uid) {
    if (!(c == '.' || (c >= '0' && c <= '9'))) return false;
  }
  return uid.front() != '.' && uid.back() != '.';
}

}  // namespace

bool CtWriteOptions::Check(std::string* error) const {
  if (!std::isfinite(rescale_slope) || rescale_slope <= 0) {
    *error = "rescale_slope must be a finite number > 0";
    return false;
  }
  if (!std::isfinite(rescale_intercept)) {
    *error = "rescale_intercept must be finite";
    return false;
  }
  if (!ValidUid(study_uid) || !ValidUid(series_uid) || !ValidUid(frame_of_reference_uid) ||
      series_uid.size() > 58) {
    *error = "study/series/frame-of-reference UIDs must be digits and dots of at most 64 "
             "characters (series at most 58)";
    return false;
  }
  return true;
}

Status WriteCtSeries(const CtVolume& volume,
                     const std::string& dir,
                     const CtWriteOptions& options,
                     int64_t* clamped_voxels) {
  SilenceGdcm();
  std::string error;
  if (!options.Check(&error)) return Status::Error("CT write options: " + error);
  const size_t per_slice = static_cast<size_t>(volume.rows) * volume.columns;
  if (volume.rows <= 0 || volume.columns <= 0 || volume.slices <= 0 ||
      volume.hu.size() != per_slice * volume.slices) {
    return Status::Error("CT volume: inconsistent size");
  }
  if (volume.rows > 65535 || volume.columns > 65535) {
    return Status::Error("CT volume: more than 65535 rows or columns");
  }
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_empty(dir, ec)) {
    return Status::Error(dir + ": exists and is not empty, refusing to write a CT series into it");
  }
  const std::string tmp = dir + ".tmp." + std::to_string(::getpid());
  fs::remove_all(tmp, ec);
  const TempPathRegistration registration(tmp);  // removed on SIGINT / SIGTERM (from its making)
  CARMBA_RETURN_IF_ERROR(MakeDirs(tmp));
  auto fail = [&](const std::string& m) {
    std::error_code ec2;
    fs::remove_all(tmp, ec2);
    return Status::Error(m);
  };

  const Eigen::Vector3d row_dir = volume.axes.col(0), col_dir = volume.axes.col(1);
  std::string iop;
  for (int a = 0; a < 3; ++a) iop += (a ? "\\" : "") + FormatDicomDecimal(row_dir[a]);
  for (int a = 0; a < 3; ++a) iop += "\\" + FormatDicomDecimal(col_dir[a]);
  const std::string pixel_spacing = FormatDicomDecimal(volume.spacing_mm.y()) + "\\" +
                                    FormatDicomDecimal(volume.spacing_mm.x());
  const double thickness =
      volume.slice_thickness_mm > 0 ? volume.slice_thickness_mm : volume.spacing_mm.z();
  const Eigen::Vector3d normal = row_dir.cross(col_dir);
  int64_t clamped = 0;
  std::vector<int16_t> stored(per_slice);
  for (int k = 0; k < volume.slices; ++k) {
    const float* hu = volume.hu.data() + per_slice * k;
    for (size_t p = 0; p < per_slice; ++p) {
      double s = std::round((hu[p] - options.rescale_intercept) / options.rescale_slope);
      if (!(s >= -32768)) {
        s = -32768;
        ++clamped;
      } else if (s > 32767) {
        s = 32767;
        ++clamped;
      }
      stored[p] = static_cast<int16_t>(s);
    }
    gdcm::Writer writer;
    gdcm::File& file = writer.GetFile();
    gdcm::DataSet& ds = file.GetDataSet();
    const std::string sop_uid = options.series_uid + "." + std::to_string(k + 1);
    PutString(&ds, 0x0008, 0x0008, gdcm::VR::CS, "DERIVED\\SECONDARY\\AXIAL");
    PutString(&ds, 0x0008, 0x0016, gdcm::VR::UI, "1.2.840.10008.5.1.4.1.1.2");
    PutString(&ds, 0x0008, 0x0018, gdcm::VR::UI, sop_uid);
    PutString(&ds, 0x0008, 0x0060, gdcm::VR::CS, "CT");
    PutString(&ds, 0x0008, 0x0070, gdcm::VR::LO, "carmba");
    PutString(&ds, 0x0008, 0x103e, gdcm::VR::LO, options.series_description);
    PutString(&ds, 0x0010, 0x0010, gdcm::VR::PN, options.patient_name);
    PutString(&ds, 0x0010, 0x0020, gdcm::VR::LO, "CARMBA0001");
    PutString(&ds, 0x0018, 0x0050, gdcm::VR::DS, FormatDicomDecimal(thickness));
    PutString(&ds, 0x0020, 0x000d, gdcm::VR::UI, options.study_uid);
    PutString(&ds, 0x0020, 0x000e, gdcm::VR::UI, options.series_uid);
    PutString(&ds, 0x0020, 0x0011, gdcm::VR::IS, "1");
    PutString(&ds, 0x0020, 0x0013, gdcm::VR::IS, std::to_string(k + 1));
    const Eigen::Vector3d ipp = volume.PatientFromIndex(Eigen::Vector3d(0, 0, k));
    PutString(&ds, 0x0020, 0x0032, gdcm::VR::DS,
              FormatDicomDecimal(ipp.x()) + "\\" + FormatDicomDecimal(ipp.y()) + "\\" +
                  FormatDicomDecimal(ipp.z()));
    PutString(&ds, 0x0020, 0x0037, gdcm::VR::DS, iop);
    PutString(&ds, 0x0020, 0x0052, gdcm::VR::UI, options.frame_of_reference_uid);
    PutString(&ds, 0x0020, 0x1041, gdcm::VR::DS, FormatDicomDecimal(ipp.dot(normal)));
    PutUS<0x0028, 0x0002>(&ds, 1);
    PutString(&ds, 0x0028, 0x0004, gdcm::VR::CS, "MONOCHROME2");
    PutUS<0x0028, 0x0010>(&ds, static_cast<uint16_t>(volume.rows));
    PutUS<0x0028, 0x0011>(&ds, static_cast<uint16_t>(volume.columns));
    PutString(&ds, 0x0028, 0x0030, gdcm::VR::DS, pixel_spacing);
    PutUS<0x0028, 0x0100>(&ds, 16);
    PutUS<0x0028, 0x0101>(&ds, 16);
    PutUS<0x0028, 0x0102>(&ds, 15);
    PutUS<0x0028, 0x0103>(&ds, 1);
    PutString(&ds, 0x0028, 0x1052, gdcm::VR::DS, FormatDicomDecimal(options.rescale_intercept));
    PutString(&ds, 0x0028, 0x1053, gdcm::VR::DS, FormatDicomDecimal(options.rescale_slope));
    PutString(&ds, 0x0028, 0x1054, gdcm::VR::LO, "HU");
    gdcm::DataElement pixels(gdcm::Tag(0x7fe0, 0x0010));
    pixels.SetVR(gdcm::VR::OW);
    pixels.SetByteValue(reinterpret_cast<const char*>(stored.data()),
                        static_cast<uint32_t>(per_slice * sizeof(int16_t)));
    ds.Replace(pixels);
    file.GetHeader().SetDataSetTransferSyntax(gdcm::TransferSyntax::ExplicitVRLittleEndian);
    char name[32];
    std::snprintf(name, sizeof(name), "slice_%04d.dcm", k + 1);
    const std::string path = tmp + "/" + name;
    writer.SetFileName(path.c_str());
    if (!writer.Write()) return fail(path + ": GDCM could not write the file");
  }
  if (fs::exists(dir, ec)) fs::remove(dir, ec);  // empty (checked above)
  fs::rename(tmp, dir, ec);
  if (ec) return fail(dir + ": cannot rename the written series into place: " + ec.message());
  if (clamped_voxels) *clamped_voxels = clamped;
  return Status::Ok();
}

}  // namespace carmba
