#include "cli/common_flags.h"

DEFINE_string(out, "", "Output directory (or file, where the command says so).");
DEFINE_string(config, "", "Configuration YAML (how it is solved).");
DEFINE_string(problem, "", "Problem YAML (what is estimated from which data).");
DEFINE_string(images, "", "Directory or glob pattern of images.");
DEFINE_string(pattern, "circles", "Calibration pattern: circles | acircles | chessboard.");
DEFINE_int32(rows, 5, "Pattern rows.");
DEFINE_int32(cols, 5, "Pattern columns.");
DEFINE_uint64(seed, 1, "Random seed.");
DEFINE_int32(jobs, 0, "Parallel jobs (0 = all cores).");
