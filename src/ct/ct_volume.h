// A CT volume in Hounsfield units with its patient geometry, and DICOM CT series I/O (GDCM).
//
// Geometry (DICOM patient coordinates, LPS, mm). A voxel has integer indices (i, j, k):
//   i = column index within a slice (0 .. columns-1), along the slice's ROW direction, the first
//       triplet of ImageOrientationPatient (0020,0037);
//   j = row index within a slice (0 .. rows-1), along the slice's COLUMN direction, the second
//       triplet of ImageOrientationPatient;
//   k = slice index after sorting the slices by their position along the slice normal
//       n = row_dir x col_dir (ascending), NOT by file name or InstanceNumber.
// The centre of voxel (i, j, k) is at
//   p_in_patient = origin_mm + i * spacing_mm[0] * axes.col(0) + j * spacing_mm[1] * axes.col(1)
//                  + k * spacing_mm[2] * axes.col(2)
// where origin_mm is ImagePositionPatient (0020,0032) of the first sorted slice (the centre of its
// first transmitted pixel), spacing_mm[0] is the column spacing (PixelSpacing[1]),
// spacing_mm[1] the row spacing (PixelSpacing[0]), spacing_mm[2] the distance between successive
// slice positions and axes.col(2) the unit step between successive positions (equal to n for an
// ordinary or obliquely oriented series; it differs from n only for a sheared, gantry-tilted
// acquisition, which is supported the same way). Voxel values are HU = slope * stored + intercept
// (RescaleSlope/RescaleIntercept, 0028,1053/1052).
#pragma once

#include <Eigen/Core>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "util/status.h"

namespace carmba {

struct CtVolume {
  int columns = 0;  // voxels along i
  int rows = 0;     // voxels along j
  int slices = 0;   // voxels along k
  Eigen::Vector3d origin_mm = Eigen::Vector3d::Zero();
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();  // unit columns: i, j, k directions
  Eigen::Vector3d spacing_mm = Eigen::Vector3d::Ones();  // along i, j, k
  double slice_thickness_mm = 0;  // SliceThickness (0018,0050); 0 when absent
  std::vector<float> hu;          // size columns*rows*slices, index i + columns*(j + rows*k)
  std::string series_uid;         // SeriesInstanceUID (0020,000E)
  std::vector<std::string> files;  // the file of each sorted slice (reading only)

  size_t Index(int i, int j, int k) const {
    return static_cast<size_t>(i) + static_cast<size_t>(columns) *
                                         (static_cast<size_t>(j) + static_cast<size_t>(rows) * k);
  }
  float At(int i, int j, int k) const { return hu[Index(i, j, k)]; }
  // Patient position (mm) of a point given in continuous voxel indices (integer = voxel centre).
  Eigen::Vector3d PatientFromIndex(const Eigen::Vector3d& ijk) const {
    return origin_mm + axes * spacing_mm.cwiseProduct(ijk);
  }
  // The linear map from index offsets to patient offsets (mm per index).
  Eigen::Matrix3d PatientFromIndexLinear() const { return axes * spacing_mm.asDiagonal(); }
  double VoxelVolumeMm3() const {
    return std::abs(PatientFromIndexLinear().determinant());
  }
};

// HU at continuous voxel indices `ijk` (integer = voxel centre), trilinear between the eight
// voxels around it; indices outside the volume are clamped to it.
inline double TrilinearHu(const CtVolume& vol, const Eigen::Vector3d& ijk) {
  const int dims[3] = {vol.columns, vol.rows, vol.slices};
  const std::ptrdiff_t stride[3] = {
      1, vol.columns, static_cast<std::ptrdiff_t>(vol.columns) * vol.rows};
  std::ptrdiff_t base = 0, next[3];
  double f[3];
  for (int a = 0; a < 3; ++a) {
    const double xa = std::clamp(ijk[a], 0.0, dims[a] - 1.0);
    const int i0 = std::min(static_cast<int>(std::floor(xa)), std::max(0, dims[a] - 2));
    f[a] = xa - i0;
    base += i0 * stride[a];
    next[a] = i0 + 1 < dims[a] ? stride[a] : 0;  // a single voxel thick: its own neighbour
  }
  const float* p = vol.hu.data() + base;
  double v = 0;
  for (int dk = 0; dk < 2; ++dk) {
    for (int dj = 0; dj < 2; ++dj) {
      for (int di = 0; di < 2; ++di) {
        v += (di ? f[0] : 1 - f[0]) * (dj ? f[1] : 1 - f[1]) * (dk ? f[2] : 1 - f[2]) *
             p[di * next[0] + dj * next[1] + dk * next[2]];
      }
    }
  }
  return v;
}

struct CtReadOptions {
  // Read only the series with this SeriesInstanceUID (0020,000E). Empty: the directory must hold
  // exactly one series.
  std::string series_uid;
  // Two slice steps (distances between successive sorted positions along the normal) are equal
  // when they differ by less than this, in mm. Larger differences are reported as a gap.
  double spacing_tolerance_mm = 0.01;
  // Direction cosines of two slices agree when they differ by less than this (per component).
  double orientation_tolerance = 1e-4;

  bool Check(std::string* error) const;
};

// Reads a CT series from a directory (every regular file in it, any names, any order; not
// recursive). Files that are not DICOM (no "DICM" marker at byte 128 and not parseable as DICOM)
// and DICOMDIR files are skipped and counted in *skipped_files (may be null). Errors, each a
// one-line message naming the directory or file: no DICOM image files; several series (listing
// their UIDs, unless options.series_uid selects one); a file with the DICM marker that GDCM
// cannot parse; pixel data GDCM cannot decode (naming the transfer syntax); missing
// ImagePositionPatient/ImageOrientationPatient/PixelSpacing; inconsistent orientation, size,
// pixel spacing or in-plane offset; two slices at the same position; unevenly spaced or missing
// slices (naming the two files and positions around the gap and the expected step); a
// single-slice series without SliceThickness.
StatusOr<CtVolume> ReadCtSeries(const std::string& dir,
                                const CtReadOptions& options = CtReadOptions(),
                                std::vector<std::string>* skipped_files = nullptr);

struct CtWriteOptions {
  double rescale_slope = 1.0;         // HU = slope * stored + intercept
  double rescale_intercept = -1024.0;
  std::string study_uid;   // all three must be valid DICOM UIDs (digits and dots, <= 64 chars);
  std::string series_uid;  // SOPInstanceUIDs are series_uid + "." + (slice index + 1)
  std::string frame_of_reference_uid;
  std::string patient_name = "CARMBA^PHANTOM";
  std::string series_description = "carmba simulated CT";

  bool Check(std::string* error) const;
};

// Writes `volume` as a DICOM CT series (CT Image Storage, explicit VR little endian, signed
// 16-bit, one file per slice named slice_0001.dcm ...) into `dir`, which must not exist or be
// empty: into dir.tmp.<pid> first, then renamed, so an error leaves no partial series. Stored
// values are round((HU - intercept) / slope) clamped to the int16 range; the number clamped is
// returned in *clamped_voxels (may be null). The slice thickness written is
// volume.slice_thickness_mm (or the slice spacing when it is 0).
Status WriteCtSeries(const CtVolume& volume,
                     const std::string& dir,
                     const CtWriteOptions& options,
                     int64_t* clamped_voxels = nullptr);

// Formats a number for a DICOM DS element (at most 16 characters, as precise as fits).
std::string FormatDicomDecimal(double value);

}  // namespace carmba
