#include "cli/common_flags.h"

#include <cmath>

DEFINE_string(out, "", "Output directory (or file, where the command says so).");
DEFINE_string(config, "", "Configuration YAML (how it is solved).");
DEFINE_string(problem, "", "Problem YAML (what is estimated from which data).");
DEFINE_string(images, "",
              "Directory or glob pattern of images (PNG, PGM, TIFF, JPEG, BMP, DICOM; a "
              "multi-frame DICOM file gives one view per frame, file.dcm#frameN).");
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
  if (!(FLAGS_spacing_mm > 0) || !std::isfinite(FLAGS_spacing_mm)) {
    *error = "--spacing_mm: expected a positive number of mm, got " +
             std::to_string(FLAGS_spacing_mm);
    return false;
  }
  return true;
}
}  // namespace carmba::cli
