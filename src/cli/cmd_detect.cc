// `carmba detect`: finds a calibration grid in every image and writes observations.csv
// (detect/observations.h); images without the grid are listed on stderr with the reason.
#include <gflags/gflags.h>
#include <yaml-cpp/yaml.h>

#include <iostream>

#include "cli/command.h"
#include "cli/common_flags.h"
#include "detect/grid_detector.h"
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
  auto files = ListImageFiles(FLAGS_images);
  if (!files.ok()) return cli::Fail(kCmd, files.status().WithContext("--images"));
  std::vector<std::string> skipped;
  double per_image = 0;
  StatusOr<ObservationSet> obs = Status::Error("not detected");
  cli::Step(kCmd, "detecting the grid in " + std::to_string(files->size()) + " images");
  {
    auto progress = cli::MakeProgress("detect", static_cast<int>(files->size()), "images");
    obs = DetectGridInFiles(*files, grid, options, &skipped, &per_image, nullptr,
                            progress->Callback());
  }
  if (!obs.ok()) return cli::Fail(kCmd, obs.status());
  for (const auto& s : skipped) std::cerr << "carmba detect: not found: " << s << "\n";
  if (obs->views.empty()) {
    return cli::Fail(kCmd, "the grid was found in none of the " + std::to_string(skipped.size()) +
                               " images (first: " + skipped[0] + ")");
  }
  cli::Step(kCmd, "writing " + FLAGS_out);
  Status s = MakeParentDirs(FLAGS_out);
  if (s.ok()) s = WriteObservationsCsv(*obs, FLAGS_out);
  if (!s.ok()) return cli::Fail(kCmd, s);
  // A multi-frame DICOM file counts one image per frame.
  std::cout << "found the grid in " << obs->views.size() << " of "
            << obs->views.size() + skipped.size() << " images (" << per_image * 1e3
            << " ms per image); wrote " << FLAGS_out << std::endl;
  return 0;
}

}  // namespace

CARMBA_COMMAND_FLAGS(detect, "images,pattern,rows,cols,spacing_mm,detection,out,force");
CARMBA_REQUIRED_FLAGS(detect, "images,out");
CARMBA_REGISTER_COMMAND(detect,
                        "Detect a calibration grid in images; write observations.csv (--out, a "
                        "file).",
                        RunDetect);
