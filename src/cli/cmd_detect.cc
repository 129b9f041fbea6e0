// `carmba detect`: finds a calibration grid in every image and writes observations.csv
// (detect/observations.h); images without the grid are listed on stderr with the reason.
#include <gflags/gflags.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <chrono>
#include <iostream>
#include <memory>

#include "cli/command.h"
#include "cli/common_flags.h"
#include "detect/grid_detector.h"
#include "problem/problem.h"
#include "util/file_util.h"

namespace {

using namespace carmba;

int RunDetect() {
  const char* kCmd = "detect";
  // --images and --out are required (checked before this runs: cli/command.h).
  if (const Status s = cli::CheckOutFile(); !s.ok()) return cli::Fail(kCmd, s);
  auto pat = ParseGridPattern(FLAGS_pattern);
  if (!pat.ok()) return cli::FailUsage(kCmd, pat.status().WithContext("--pattern"));
  GridSpec grid;
  grid.pattern = *pat;
  grid.rows = FLAGS_rows;
  grid.cols = FLAGS_cols;
  std::string err;
  if (!cli::CheckGridFlags(&err)) return cli::FailUsage(kCmd, err);
  grid.spacing_mm = FLAGS_spacing_mm > 0 ? FLAGS_spacing_mm : 20.0;  // recorded in the CSV
  if (!grid.Check(&err)) return cli::FailUsage(kCmd, err);
  DetectionOptions options;
  if (!FLAGS_detection.empty()) {
    if (const Status s = LoadDetectionOptions(FLAGS_detection, &options); !s.ok())
      return cli::Fail(kCmd, s);
  }
  // The problem's plate-view reader, as `carmba calibrate --images` reads its flags.
  PlateViewsInput plate;
  NameInputsAsFlags(&plate);
  plate.images = FLAGS_images;
  plate.grid = grid;
  plate.detection = options;
  std::unique_ptr<Progress> progress;
  plate.detecting = cli::GridDetectionProgress(kCmd, "detect", &progress);
  Problem found;
  const auto start = std::chrono::steady_clock::now();
  const Status loaded = LoadPlateViews(plate, &found);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  progress.reset();
  if (!loaded.ok()) return cli::Fail(kCmd, loaded);
  const ObservationSet* obs = &found.plate;
  const std::vector<std::string>& skipped = found.skipped_images;
  for (const auto& s : skipped) std::cerr << "carmba detect: not found: " << s << "\n";
  cli::Step(kCmd, "writing " + FLAGS_out);
  Status s = MakeParentDirs(FLAGS_out);
  if (s.ok()) s = WriteObservationsCsv(*obs, FLAGS_out);
  if (!s.ok()) return cli::Fail(kCmd, s);
  // A multi-frame DICOM file counts one image per frame.
  const size_t images = obs->views.size() + skipped.size();
  std::cout << "found the grid in " << obs->views.size() << " of " << images << " images ("
            << seconds * 1e3 / std::max<size_t>(images, 1) << " ms per image); wrote " << FLAGS_out
            << std::endl;
  return 0;
}

}  // namespace

CARMBA_COMMAND_FLAGS(detect, "images,pattern,rows,cols,spacing_mm,detection,out,force");
CARMBA_REQUIRED_FLAGS(detect, "images,out");
CARMBA_REGISTER_COMMAND(detect,
                        "Detect a calibration grid in images; write observations.csv (--out, a "
                        "file).",
                        RunDetect);
