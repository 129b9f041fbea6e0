#include "cli/common_flags.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <sstream>

#include "study/study_inputs.h"
#include "util/file_util.h"
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
DEFINE_int32(rows, 5,
             "Grid rows, i.e. points per column: for a chessboard the inner corners (squares - "
             "1); for circles and acircles the circles (acircles: every other row is offset by "
             "half a pitch).");
DEFINE_int32(cols, 5,
             "Grid columns, i.e. points per row: for a chessboard the inner corners (squares - "
             "1); for circles and acircles the circles in one row.");
DEFINE_double(spacing_mm, 0,
              "Grid pitch in mm (0: the problem's or the observations', otherwise 20).");
DEFINE_uint64(seed, 1, "Random seed.");
DEFINE_int32(jobs, 0, "Parallel jobs (0 = all cores).");
DEFINE_bool(force, false,
            "Write over an existing result in --out (without it an existing non-empty output "
            "directory or an existing output file is an error).");
DEFINE_bool(verbose, false,
            "Progress on stderr: the steps, and one line per image / view / run when stderr is "
            "not a terminal (on a terminal a progress bar is shown anyway).");

DEFINE_bool(plots, true,
            "Draw report.html's plots (matplotlib, in one Python process overlapping the work); "
            "--no-plots writes the report without them and runs no Python for it.");
DEFINE_double(
    marker_diameter_mm,
    0,
    "Marker (bead) diameter (mm), converted to px with the nominal magnification (pose: "
    "fx / SOD of the DICOM frame, or --source-to-object-mm; track: fx / the distance from "
    "each source to the cameras' common field).");
DEFINE_bool(mrcal, true, "Cross-check with mrcal (python3-mrcal); --no-mrcal skips it.");
DEFINE_string(mrcal_python, "/usr/bin/python3", "The Python with mrcal for the cross-check.");
DEFINE_string(detection,
              "",
              "YAML of detection options at its top level: pose, the markers' "
              "(detect/marker_views.h ReadObjectViewsOptions; flags override it); calibrate and "
              "detect, the grid's (the keys of a problem's plate_views.detection).");

namespace carmba::cli {
namespace {

using Clock = std::chrono::steady_clock;

// The step in progress (Step / EndSteps); the clock starts with the process.
struct StepClock {
  Clock::time_point process_start = Clock::now();
  Clock::time_point step_start;
  std::string what;  // empty: no step open
};
StepClock& Steps() {
  static StepClock clock;
  return clock;
}
const bool kStepClockStarted [[maybe_unused]] = (Steps(), true);

std::string Seconds(Clock::time_point from, Clock::time_point to) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3f s", std::chrono::duration<double>(to - from).count());
  return buf;
}

void CloseStep(const std::string& command, Clock::time_point now) {
  StepClock& c = Steps();
  if (c.what.empty()) return;
  std::cerr << "carmba " << command << ": " << c.what << ": " << Seconds(c.step_start, now)
            << std::endl;
  c.what.clear();
}

}  // namespace

bool CheckSpacingFlag(std::string* error) {
  if (FLAGS_spacing_mm == 0) return true;
  if (!InRange(FLAGS_spacing_mm, plausible::kGridSpacingMm)) {
    *error = "--spacing-mm: expected 0 (not given) or " +
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

Status CheckOutDir(bool also_allowed, const std::string& how_to_override) {
  return CheckOutputDir(FLAGS_out, "--out", FLAGS_force || also_allowed, how_to_override);
}

Status CheckOutFile() { return CheckOutputFile(FLAGS_out, "--out", FLAGS_force); }

const std::vector<std::string>& InputFlagNames() {
  static const std::vector<std::string> kNames = {
      "images", "camera", "config",   "problem",   "observations", "truth",  "dicom", "model",
      "fiducials", "detection", "result", "scene", "study", "shards", "points"};
  return kNames;
}

std::vector<InputPath> InputsOfFlags(const std::vector<std::string>& flag_names) {
  std::vector<InputPath> inputs;
  for (const std::string& name : flag_names) {
    if (std::find(InputFlagNames().begin(), InputFlagNames().end(), name) ==
        InputFlagNames().end()) {
      continue;
    }
    std::string value;
    if (!gflags::GetCommandLineOption(name.c_str(), &value) || value.empty()) continue;
    std::string dashed = name;
    std::replace(dashed.begin(), dashed.end(), '_', '-');
    if (name != "shards") {
      inputs.push_back({"--" + dashed, value});
      continue;
    }
    std::stringstream items(value);
    for (std::string item; std::getline(items, item, ',');) {
      if (!item.empty()) inputs.push_back({"--" + dashed, item});
    }
  }
  return inputs;
}

std::vector<InputPath> InputsOfFlagsAndFilesTheyName(const std::vector<std::string>& flag_names) {
  std::vector<InputPath> inputs = InputsOfFlags(flag_names);
  const size_t num_flags = inputs.size();
  for (size_t k = 0; k < num_flags; ++k) {
    const std::string path = inputs[k].path;
    auto ends_with = [&](const std::string& e) {
      return path.size() > e.size() && path.compare(path.size() - e.size(), e.size(), e) == 0;
    };
    if (!(ends_with(".yaml") || ends_with(".yml")) || IsDirectory(path) || !FileExists(path)) {
      continue;
    }
    const std::string what = "named in " + inputs[k].what + " " + path + ":";
    for (const std::string& f : FilesNamedInYaml(path)) inputs.push_back({what, f});
  }
  return inputs;
}

Status CheckOutIsNoInput(const std::vector<InputPath>& inputs) {
  for (const InputPath& in : inputs) {
    CARMBA_RETURN_IF_ERROR(CheckOutputIsNotInput(FLAGS_out, "--out", in.path, in.what));
  }
  return Status::Ok();
}

std::unique_ptr<Progress> MakeProgress(const std::string& label,
                                       int total,
                                       const std::string& unit) {
  return std::make_unique<Progress>(
      label, total, unit, ChooseProgressStyle(::isatty(STDERR_FILENO) == 1, FLAGS_verbose));
}

std::function<ProgressFn(int)> GridDetectionProgress(const std::string& command,
                                                     const std::string& label,
                                                     std::unique_ptr<Progress>* progress) {
  return [command, label, progress](int num_images) {
    Step(command, "detecting the grid in " + std::to_string(num_images) + " images");
    *progress = MakeProgress(label, num_images, "images");
    return (*progress)->Callback();
  };
}

void Step(const std::string& command, const std::string& what) {
  if (!FLAGS_verbose) return;
  const Clock::time_point now = Clock::now();
  CloseStep(command, now);
  std::cerr << "carmba " << command << ": " << what << std::endl;
  Steps().what = what;
  Steps().step_start = now;
}

void EndSteps(const std::string& command) {
  if (!FLAGS_verbose) return;
  const Clock::time_point now = Clock::now();
  CloseStep(command, now);
  std::cerr << "carmba " << command << ": total " << Seconds(Steps().process_start, now)
            << std::endl;
}
}  // namespace carmba::cli
