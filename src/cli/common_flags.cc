#include "cli/common_flags.h"

#include <cmath>

#include "util/plausible.h"

DEFINE_string(out, "", "Output directory (or file, where the command says so).");
DEFINE_string(config, "", "Configuration YAML (how it is solved).");
DEFINE_string(problem, "", "Problem YAML (what is estimated from which data).");
DEFINE_string(images, "",
              "Directory or glob pattern of images (PNG, PGM, TIFF, JPEG, BMP, DICOM; a "
              "multi-frame DICOM file gives one view per frame, file.dcm#frameN).");
DEFINE_string(camera, "",
              "Calibrated camera: camera.json (carmba calibrate), or a joint solve's result.json "
              "(its intrinsics).");
DEFINE_string(pattern, "circles", "Calibration pattern: circles | acircles | chessboard.");
DEFINE_int32(rows, 5, "Pattern rows.");
DEFINE_int32(cols, 5, "Pattern columns.");
DEFINE_double(spacing_mm, 0,
              "Grid pitch in mm (0: the problem's or the observations', otherwise 20).");
DEFINE_uint64(seed, 1, "Random seed.");
DEFINE_int32(jobs, 0, "Parallel jobs (0 = all cores).");

namespace carmba::cli {
bool CheckSpacingFlag(std::string* error) {
  if (FLAGS_spacing_mm == 0) return true;
  if (!InRange(FLAGS_spacing_mm, plausible::kGridSpacingMm)) {
    *error = "--spacing_mm: expected 0 (not given) or " +
             FormatRange(plausible::kGridSpacingMm) + ", got " + FormatCompact(FLAGS_spacing_mm);
    return false;
  }
  return true;
}

bool CheckGridFlags(std::string* error) {
  return CheckRange("--rows", FLAGS_rows, plausible::kGridRowsCols, error) &&
         CheckRange("--cols", FLAGS_cols, plausible::kGridRowsCols, error) &&
         CheckSpacingFlag(error);
}

bool CheckJobsFlag(std::string* error) {
  if (InRange(FLAGS_jobs, plausible::kJobs)) return true;
  *error = "--jobs: expected " + FormatRange(plausible::kJobs) + " (0 = all cores), got " +
           std::to_string(FLAGS_jobs);
  return false;
}
}  // namespace carmba::cli
