// `carmba calibrate`: intrinsic calibration from images of a grid (or pre-detected observations)
// as a bundle adjustment with covariance, cross-checked with mrcal and OpenCV in the same run.
// Writes camera.json, camera.cameramodel, camera_opencv.yml, observations.csv, corners.vnl,
// report.md (and mrcal/ with the cross-check's script, input and output) into --out; on any
// error nothing is written.
//
// Problem file (problems/calib_*.yaml): a problem of the one schema (problem/problem.h) with plate
// views only, read by the one problem reader:
//   name: ...                    description: ...
//   plate_views: {images: DIR_OR_GLOB, pattern: circles, rows: 5, cols: 5, spacing_mm: 20,
//                 detection: {...}}          # or observations: observations.csv
//   camera: camera.json          # optional: initial intrinsics
//   truth: truth.json            # optional: simulator truth (or a camera.json) to compare with
// Calibration problems written before the one schema (top-level images / observations, pattern,
// rows, cols, spacing_mm, config) are still read. --config and --truth win over the file's.
// Config file (configs/calib_*.yaml): how it is solved, calib/calibrate.h CalibrationOptions keys at
// top level. The grid's detection options: the problem's plate_views.detection, or --detection FILE
// (polarity, roi_px, fov_circle_px, auto_fov_mask, fov_margin_px, min_blob_area_px,
// max_blob_area_px, refine at its top level). The cross-checks: --no-mrcal, --no-opencv,
// --opencv-max-views (60), --mrcal-python (/usr/bin/python3).
#include <gflags/gflags.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <sstream>

#include "calib/calib_output.h"
#include "calib/calibrate.h"
#include "calib/conditioning.h"
#include "calib/crosscheck.h"
#include "cli/command.h"
#include "cli/common_flags.h"
#include "detect/grid_detector.h"
#include "problem/problem.h"
#include "report/calibration_report.h"
#include "report/plots.h"
#include "util/file_util.h"
#include "util/plausible.h"
#include "util/python_worker.h"
#include "util/temp_paths.h"

DEFINE_string(observations, "", "Pre-detected observations.csv (instead of --images).");
DEFINE_string(truth, "", "Ground truth (simulator truth.json or a camera.json) to compare with.");
DEFINE_bool(opencv, true, "Cross-check with cv::calibrateCamera.");
DEFINE_int32(opencv_max_views,
             60,
             "Skip the OpenCV cross-check beyond this many views (calibrateCamera takes minutes "
             "beyond a few hundred).");
DEFINE_double(sphere_diameter_mm,
              0,
              "Diameter of the plate's metal spheres (mm; 0: not known, or flat circles): each "
              "detected centre is corrected for its cone-beam shadow's offset (the problem "
              "file's plate_views.sphere_diameter_mm).");

namespace {

using namespace carmba;

// The cross-checks, from the flags.
struct CrossCheckConfig {
  bool mrcal = FLAGS_mrcal;
  bool opencv = FLAGS_opencv;
  int opencv_max_views = FLAGS_opencv_max_views;
  std::string python = FLAGS_mrcal_python;
};

// What `carmba calibrate` reads: the flags, completed by a --problem file.
struct CalibrateInputs {
  std::string images = FLAGS_images, observations = FLAGS_observations, config = FLAGS_config;
  std::string truth = FLAGS_truth, pattern = FLAGS_pattern, detection = FLAGS_detection;
  int rows = FLAGS_rows, cols = FLAGS_cols;
  double spacing = FLAGS_spacing_mm, sphere_diameter = FLAGS_sphere_diameter_mm;
};

// Fewer than min_views images with the grid is an error naming the grid and the first skipped.
Status CheckEnoughViews(const CalibrationRun& run, const CalibrationOptions& options) {
  const size_t found = run.observations.views.size();
  if (static_cast<int>(found) >= options.min_views) return Status::Ok();
  const GridSpec& g = run.observations.grid;
  return Status::Error("the grid (" + std::string(GridPatternName(g.pattern)) + " " +
                       std::to_string(g.rows) + " x " + std::to_string(g.cols) + ") was found in " +
                       std::to_string(found) + " of " + std::to_string(found + run.skipped.size()) +
                       " images, min_views is " + std::to_string(options.min_views) +
                       (run.skipped.empty() ? "" : "; first skipped: " + run.skipped[0]));
}

// The grid's observations from the flags (read from the CSV, or detected in the images) through
// the problem's plate-view reader; skipped images and detections into run.
Status CalibrationObservations(const CalibrateInputs& in, GridPattern pattern,
                               const DetectionOptions& detect, const CalibrationOptions& options,
                               CalibrationRun* run) {
  PlateViewsInput plate;
  NameInputsAsFlags(&plate);
  plate.sphere_diameter_mm = in.sphere_diameter;
  plate.observations = in.observations;
  plate.images = in.images;
  plate.spacing_mm_override = in.spacing;
  std::unique_ptr<Progress> progress;
  if (!in.images.empty()) {
    GridSpec grid;
    grid.pattern = pattern;
    grid.rows = in.rows;
    grid.cols = in.cols;
    grid.spacing_mm = in.spacing > 0 ? in.spacing : 20.0;
    plate.grid = grid;
    plate.detection = detect;
    plate.detecting = cli::GridDetectionProgress("calibrate", "calibrate: detecting", &progress);
  }
  Problem p;
  const Status loaded = LoadPlateViews(plate, &p);
  progress.reset();
  CARMBA_RETURN_IF_ERROR(loaded);
  run->observations = p.plate;
  run->skipped = p.skipped_images;
  run->detections = p.plate_detections;
  for (const auto& s : run->skipped) std::cerr << "carmba calibrate: skipped " << s << "\n";
  return run->detections.empty() ? Status::Ok() : CheckEnoughViews(*run, options);
}

// The plate flags that a --problem replaces, if one was given ("" if none).
std::string PlateFlagGiven() {
  for (const char* f :
       {"images", "observations", "pattern", "rows", "cols", "spacing_mm", "sphere_diameter_mm"}) {
    gflags::CommandLineFlagInfo info;
    if (!gflags::GetCommandLineFlagInfo(f, &info) || info.is_default) continue;
    std::string name = f;
    std::replace(name.begin(), name.end(), '_', '-');
    return name;
  }
  return "";
}

// What `carmba calibrate` solves of a problem: one shared intrinsics from plate views alone, the
// plate held at its nominal grid. The rest is `carmba solve`'s.
Status CheckCalibrationProblem(const Problem& p) {
  const std::string solve = "; `carmba solve --problem " + p.path + "` solves it";
  auto refuse = [&](const std::string& what) { return Status::Error(p.path + ": " + what); };
  if (p.plate.views.empty()) {
    return refuse("no plate_views: `carmba calibrate` takes a calibration problem (plate views)");
  }
  if (!p.object_views.empty()) {
    return refuse("object_views: a calibration problem has plate views only" + solve);
  }
  if (p.plate_free) {
    return refuse("plate_views.plate.free: `carmba calibrate` holds the plate at its grid" + solve);
  }
  if (p.per_group || p.smooth || p.camera_prior) {
    return refuse("intrinsics: `carmba calibrate` solves one shared intrinsics without a prior" +
                  solve);
  }
  return Status::Ok();
}

// A --problem (the one problem reader), with the --detection options where the problem gives none.
// An older calibration file's config becomes in->config when --config was not given.
StatusOr<Problem> ReadCalibrationProblem(const std::optional<DetectionOptions>& detect,
                                         CalibrateInputs* in,
                                         CalibrationRun* run) {
  cli::Step("calibrate", "reading the problem " + FLAGS_problem);
  ProblemReadOptions ro;
  ro.plate_detection = detect;
  auto problem = LoadProblem(FLAGS_problem, ro);
  if (!problem.ok()) return problem.status();
  CARMBA_RETURN_IF_ERROR(CheckCalibrationProblem(*problem));
  run->observations = problem->plate;
  run->skipped = problem->skipped_images;
  run->detections = problem->plate_detections;
  for (const auto& s : run->skipped) std::cerr << "carmba calibrate: skipped " << s << "\n";
  if (in->config.empty()) in->config = problem->older_config_file;
  return problem;
}

// The problem's initial intrinsics (its camera, unless the config gives them) and its plate
// sigma (the data's detection noise: it replaces the config's pixel_sigma_px).
void ApplyProblemToOptions(const Problem& p, CalibrationOptions* options) {
  if (p.camera && options->initial_intrinsics.empty()) {
    options->initial_intrinsics.assign(p.camera->params.begin(), p.camera->params.end());
  }
  if (p.plate_sigma_px > 0) options->pixel_sigma_px = p.plate_sigma_px;
}

// --truth: the true camera (truth.json's "camera", or a camera.json), into run and `others`.
Status ReadCalibrationTruth(const std::string& truth, CalibrationRun* run,
                            std::map<std::string, std::array<double, kNumIntrinsics>>* others) {
  auto text = ReadFile(truth);
  if (!text.ok()) return text.status().WithContext("--truth");
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(*text);
  } catch (const std::exception& e) {
    return Status::Error(truth + ": invalid JSON: " + e.what());
  }
  auto cam = CameraFromJson(j.contains("camera") ? j["camera"] : j, truth);
  if (!cam.ok()) return cam.status();
  run->truth = *cam;
  (*others)["truth"] = cam->params;
  return Status::Ok();
}

// The OpenCV cross-check (when enabled and the views are few enough for it), into run.
void OpenCvCrossCheck(const CrossCheckConfig& cross,
                      const CalibrationOptions& options,
                      CalibrationRun* run,
                      std::map<std::string, std::array<double, kNumIntrinsics>>* others) {
  if (!cross.opencv) {
    run->opencv_error = "disabled";
    return;
  }
  if (static_cast<int>(run->observations.views.size()) > cross.opencv_max_views) {
    run->opencv_error = std::to_string(run->observations.views.size()) +
                        " views > --opencv-max-views (" + std::to_string(cross.opencv_max_views) +
                        "): calibrateCamera too slow";
    return;
  }
  cli::Step("calibrate", "OpenCV cross-check (cv::calibrateCamera)");
  auto ref = RunOpenCvCalibration(
      SolvedObservations(run->observations, run->result), options, run->result);
  if (ref.ok()) {
    run->opencv = *ref;
    (*others)["opencv"] = ref->intrinsics;
  } else {
    run->opencv_error = ref.status().message();
  }
}

// The mrcal cross-check in `work` (when enabled), into run.
void MrcalCrossCheck(const CrossCheckConfig& cross, PythonWorker* warm, const std::string& work,
                     const std::map<std::string, std::array<double, kNumIntrinsics>>& others,
                     CalibrationRun* run) {
  if (!cross.mrcal) {
    run->mrcal_error = "disabled";
    return;
  }
  cli::Step("calibrate", "mrcal cross-check (" + cross.python + ")");
  MrcalCrossCheckOptions mo;
  mo.python = cross.python;
  mo.work_dir = work;
  mo.warm = warm;
  auto m = RunMrcalCrossCheck(
      SolvedObservations(run->observations, run->result), run->result, others, mo);
  if (m.ok()) {
    run->mrcal = *m;
  } else {
    run->mrcal_error = m.status().message();
    std::cerr << "carmba calibrate: warning: " << run->mrcal_error << "\n";
  }
}

// The effective inputs (after the problem file) as a command line that reproduces this run.
std::string CalibrateCommandLine(const CalibrateInputs& in, const CalibrationRun& run,
                                 const CrossCheckConfig& cross) {
  auto quoted = [](const std::string& v) { return "'" + v + "'"; };
  std::ostringstream cmd;
  cmd << "carmba calibrate";
  if (!FLAGS_problem.empty()) {
    cmd << " --problem " << quoted(FLAGS_problem);
  } else if (!in.images.empty()) {
    cmd << " --images " << quoted(in.images) << " --pattern " << in.pattern << " --rows " << in.rows
        << " --cols " << in.cols;
  } else {
    cmd << " --observations " << quoted(in.observations);
  }
  if (FLAGS_problem.empty()) cmd << " --spacing-mm " << run.observations.grid.spacing_mm;
  if (FLAGS_problem.empty() && run.observations.grid.sphere_diameter_mm > 0) {
    cmd << " --sphere-diameter-mm " << run.observations.grid.sphere_diameter_mm;
  }
  if (!in.detection.empty()) cmd << " --detection " << quoted(in.detection);
  if (!in.config.empty()) cmd << " --config " << quoted(in.config);
  if (!in.truth.empty()) cmd << " --truth " << quoted(in.truth);
  if (!cross.mrcal) cmd << " --no-mrcal";
  if (!cross.opencv) cmd << " --no-opencv";
  cmd << " --out " << quoted(FLAGS_out);
  return cmd.str();
}

// The conditioning warnings on stderr, the one-line summary on stdout.
void PrintCalibrationSummary(const CalibrationRun& run) {
  const auto& r = run.result;
  for (const auto& w :
       AssessConditioning(r, run.observations.width, run.observations.height).warnings) {
    std::cerr << "carmba calibrate: warning: " << w << std::endl;
  }
  std::cout << "calibrated " << r.views.size() << " views (" << run.skipped.size()
            << " skipped): fx " << r.camera.params[kFx] << " +- " << r.sigma[kFx] << ", fy "
            << r.camera.params[kFy] << " +- " << r.sigma[kFy] << ", cx " << r.camera.params[kCx]
            << " +- " << r.sigma[kCx] << ", cy " << r.camera.params[kCy] << " +- " << r.sigma[kCy]
            << " px (" << (r.sigma_estimated ? "a-posteriori" : "a-priori") << " pixel sigma "
            << r.sigma_px << " px); RMS " << r.rms_px << " px per coordinate (OpenCV figure "
            << r.rms_opencv_px << ")";
  if (run.mrcal) {
    // With held intrinsics, mrcal's figure for the same free set (like with like).
    const nlohmann::json& m = *run.mrcal;
    const bool held = m.contains("held") && m["held"].is_object();
    std::cout << "; mrcal RMS " << (held ? m["held"] : m)["rms_px"].get<double>()
              << (held ? " (same free intrinsics)" : "");
  }
  std::cout << "; wrote " << FLAGS_out << "/{camera.json, camera.cameramodel, camera_opencv.yml, "
            << "observations.csv, corners.vnl, report.md, report.html}" << std::endl;
}

// The calibration config (how it is solved), when one is given.
Status LoadCalibrateConfig(const std::string& path, CalibrationOptions* options) {
  return path.empty() ? Status::Ok() : LoadCalibrationOptions(path, options);
}

// --detection: the grid's detection options, for --images or a problem that gives none.
Status LoadCalibrateDetection(const CalibrateInputs& in, std::optional<DetectionOptions>* detect) {
  if (in.detection.empty()) return Status::Ok();
  DetectionOptions d;
  CARMBA_RETURN_IF_ERROR(LoadDetectionOptions(in.detection, &d));
  *detect = d;
  return Status::Ok();
}

// The plate views, from a --problem or from the flags, into run (and the problem's options into
// options; an older problem's config read). mrcal's interpreter starts once the config is known.
Status CalibrationPlateViews(CalibrateInputs* in,
                             const std::optional<DetectionOptions>& detect,
                             const CrossCheckConfig& cross,
                             CalibrationOptions* options,
                             std::unique_ptr<PythonWorker>* mrcal_python,
                             CalibrationRun* run) {
  const bool config_given = !in->config.empty();
  if (config_given && cross.mrcal) *mrcal_python = StartMrcalPython(cross.python);
  if (FLAGS_problem.empty()) {
    auto pat = ParseGridPattern(in->pattern);
    if (!pat.ok()) return pat.status().WithContext("--pattern");
    return CalibrationObservations(*in, *pat, detect.value_or(DetectionOptions()), *options, run);
  }
  auto problem = ReadCalibrationProblem(detect, in, run);
  if (!problem.ok()) return problem.status();
  if (!config_given) {
    CARMBA_RETURN_IF_ERROR(LoadCalibrateConfig(in->config, options));
    if (cross.mrcal) *mrcal_python = StartMrcalPython(cross.python);
  }
  ApplyProblemToOptions(*problem, options);
  if (!run->detections.empty()) CARMBA_RETURN_IF_ERROR(CheckEnoughViews(*run, *options));
  if (in->truth.empty() && problem->truth.camera) run->truth = *problem->truth.camera;
  return Status::Ok();
}

int RunCalibrate() {
  const char* kCmd = "calibrate";
  CalibrateInputs in;
  {
    std::string err;
    if (!cli::CheckGridFlags(&err)) return cli::FailUsage(kCmd, err);
    if (FLAGS_sphere_diameter_mm != 0 &&
        !InRange(FLAGS_sphere_diameter_mm, plausible::kMarkerDiameterMm)) {
      return cli::FailUsage(kCmd,
                            "--sphere-diameter-mm: expected 0 (not known) or " +
                                FormatRange(plausible::kMarkerDiameterMm) + ", got " +
                                FormatCompact(FLAGS_sphere_diameter_mm));
    }
  }
  if (!FLAGS_problem.empty() && !PlateFlagGiven().empty()) {
    return cli::FailUsage(kCmd, "--" + PlateFlagGiven() +
                                    ": the --problem names the plate views; give one or the other");
  }
  // --out is required (checked before this runs: cli/command.h).
  if (const Status s = cli::CheckOutDir(); !s.ok()) return cli::Fail(kCmd, s);
  if (FLAGS_problem.empty() && in.images.empty() == in.observations.empty()) {
    return cli::Fail(kCmd, "give exactly one of --images and --observations (or a --problem)");
  }
  if (!in.detection.empty() && !in.observations.empty()) {
    return cli::FailUsage(kCmd,
                          "--detection: the --observations are already detected; give it with "
                          "--images or a --problem");
  }
  CalibrationOptions options;
  std::optional<DetectionOptions> detect;
  const CrossCheckConfig cross;
  if (const Status s = LoadCalibrateConfig(in.config, &options); !s.ok()) return cli::Fail(kCmd, s);
  if (const Status s = LoadCalibrateDetection(in, &detect); !s.ok()) return cli::Fail(kCmd, s);
  // The plot and mrcal interpreters start now: their imports overlap the detection and the
  // solve; the plots are then drawn while the cross-checks run.
  PlotOptions plot_options;
  plot_options.enabled = FLAGS_plots;
  PlotProcess plots(plot_options);
  std::unique_ptr<PythonWorker> mrcal_python;
  CalibrationRun run;
  if (const Status s = CalibrationPlateViews(&in, detect, cross, &options, &mrcal_python, &run);
      !s.ok()) {
    return cli::Fail(kCmd, s);
  }
  run.options = options;
  cli::Step(kCmd,
            "bundle adjustment over " + std::to_string(run.observations.views.size()) + " views");
  auto result = Calibrate(run.observations, options);
  if (!result.ok()) return cli::Fail(kCmd, result.status());
  run.result = *result;
  // Where the pitch came from, for the error on an implausible plate distance.
  const std::string pitch_source = FLAGS_spacing_mm > 0 ? "--spacing-mm"
                                   : !FLAGS_problem.empty() ? FLAGS_problem + ": spacing_mm"
                                   : !in.observations.empty() ? in.observations + " spacing_mm"
                                                              : "--spacing-mm (default)";
  if (const Status s =
          CheckPlateDistance(run.result, run.observations.grid.spacing_mm, pitch_source);
      !s.ok()) {
    return cli::Fail(kCmd, s);
  }
  plots.Draw(CalibrationPlotData(run));

  std::map<std::string, std::array<double, kNumIntrinsics>> others;
  if (!in.truth.empty()) {
    if (const Status s = ReadCalibrationTruth(in.truth, &run, &others); !s.ok())
      return cli::Fail(kCmd, s);
  } else if (run.truth) {
    others["truth"] = run.truth->params;
  }
  OpenCvCrossCheck(cross, options, &run, &others);
  const ScopedTempPath work_dir(FLAGS_out + ".mrcal.tmp." + std::to_string(::getpid()));
  const std::string& work = work_dir.path();
  MrcalCrossCheck(cross, mrcal_python.get(), work, others, &run);
  run.command_line = CalibrateCommandLine(in, run, cross);
  std::string report_warning;
  cli::Step(kCmd, "waiting for the plots");
  const PlotSet plot_set = plots.Result();
  cli::Step(kCmd, "writing the outputs");
  Status s =
      WriteCalibrationOutputs(run, FLAGS_out, cross.mrcal ? work : "", &report_warning, &plot_set);
  if (!s.ok()) return cli::Fail(kCmd, s);
  if (!report_warning.empty()) {
    std::cerr << "carmba " << kCmd << ": warning: " << report_warning << std::endl;
  }
  PrintCalibrationSummary(run);
  return 0;
}

}  // namespace

CARMBA_COMMAND_FLAGS(calibrate,
                     "images,pattern,rows,cols,spacing_mm,config,problem,out,force,plots,mrcal,"
                     "mrcal_python,detection");
CARMBA_REQUIRED_FLAGS(calibrate, "out");
CARMBA_REGISTER_COMMAND(calibrate,
                        "Calibrate the C-arm's intrinsics from grid images (bundle adjustment, "
                        "covariance, mrcal and OpenCV cross-checks). Give exactly one of "
                        "--images, --observations, --problem.",
                        RunCalibrate);
