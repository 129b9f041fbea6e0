// `carmba pose`: object poses from X-ray images. Marker blobs are detected in every view
// (detect/marker_blobs.h), labelled with the CT fiducials through the calibrated camera
// (pose/marker_correspondence.h, detect/marker_views.h), and the labelled views are solved as one
// pose bundle adjustment (problem/pose_solver.h, the engine in ba/) with each blob's pixel sigma.
// Writes into --out: observations.csv, overlay_<view>.png per view, result.json, report.md,
// report.html; all or nothing. Views with fewer than 4 markers found (or no labelling) are skipped
// with the reason.
#include <gflags/gflags.h>

#include <iostream>
#include <set>
#include <sstream>

#include "cli/command.h"
#include "cli/common_flags.h"
#include "detect/marker_views.h"
#include "problem/pose_solver.h"
#include "report/marker_views_report.h"
#include "report/plots.h"
#include "report/pose_report.h"
#include "util/file_util.h"
#include "util/image_codecs.h"
#include "util/plausible.h"
#include "util/yaml_reader.h"

DEFINE_string(fiducials, "", "CT marker centres with covariances (fiducials.csv as `carmba "
                             "ct-fiducials` writes it: id, x_mm, y_mm, z_mm, cov_xx..cov_zz).");

DEFINE_string(diameter_px, "", "Marker diameter range 'min,max' in px (instead of "
                               "--marker-diameter-mm).");
DEFINE_double(source_to_object_mm,
              0,
              "Source-to-object distance (mm) for images without a "
              "Distance Source to Patient tag.");

namespace {

using namespace carmba;

int RunPose() {
  const char* kCmd = "pose";
  if (FLAGS_images.empty()) return cli::FailUsage(kCmd, "--images is required");
  if (FLAGS_fiducials.empty()) return cli::FailUsage(kCmd, "--fiducials is required");
  if (FLAGS_camera.empty()) return cli::FailUsage(kCmd, "--camera is required");
  if (FLAGS_out.empty()) return cli::FailUsage(kCmd, "--out is required");
  {
    const Status s = cli::CheckOutDir();
    if (!s.ok()) return cli::Fail(kCmd, s);
  }
  ObjectViewsOptions options;
  if (!FLAGS_detection.empty()) {
    YamlMap root = YamlMap::Load(FLAGS_detection);
    if (!root.status().ok()) return cli::Fail(kCmd, root.status());
    ReadObjectViewsOptions(root, &options);
    const Status s = root.Finish();
    if (!s.ok()) return cli::Fail(kCmd, s);
  }
  // Unit slips (metres for millimetres) name the flag once, before any view is read.
  if (FLAGS_marker_diameter_mm != 0 &&
      !InRange(FLAGS_marker_diameter_mm, plausible::kMarkerDiameterMm)) {
    return cli::FailUsage(kCmd, "--marker-diameter-mm: expected " +
                                    FormatRange(plausible::kMarkerDiameterMm) + ", got " +
                                    FormatCompact(FLAGS_marker_diameter_mm) +
                                    " (a diameter in metres?)");
  }
  if (FLAGS_source_to_object_mm != 0 &&
      !InRange(FLAGS_source_to_object_mm, plausible::kSourceToObjectMm)) {
    return cli::FailUsage(kCmd, "--source-to-object-mm: expected " +
                                    FormatRange(plausible::kSourceToObjectMm) + ", got " +
                                    FormatCompact(FLAGS_source_to_object_mm) +
                                    " (a distance in metres?)");
  }
  if (FLAGS_marker_diameter_mm != 0) options.blobs.diameter_mm = FLAGS_marker_diameter_mm;
  if (FLAGS_source_to_object_mm != 0) options.source_to_object_mm = FLAGS_source_to_object_mm;
  if (!FLAGS_diameter_px.empty()) {
    double lo = 0, hi = 0;
    char comma = 0;
    std::istringstream is(FLAGS_diameter_px);
    if (!(is >> lo >> comma >> hi) || comma != ',' || !is.eof()) {
      return cli::FailUsage(
          kCmd, "--diameter-px: expected 'min,max' in px, got '" + FLAGS_diameter_px + "'");
    }
    options.blobs.diameter_px = {lo, hi};
  }
  std::string err;
  if (!options.Check(&err)) {
    return cli::Fail(kCmd, err + " (--marker-diameter-mm, --diameter-px or --detection)");
  }
  PlotOptions plot_options;
  plot_options.enabled = FLAGS_plots;
  PlotProcess plots(plot_options);  // imports matplotlib while the views are detected and solved
  cli::Step(kCmd, "reading the camera and the fiducials");
  auto camera = ReadCameraJson(FLAGS_camera);
  if (!camera.ok()) return cli::Fail(kCmd, camera.status());
  auto markers = ReadMarkersCsv(FLAGS_fiducials, "id", {"x_mm", "y_mm", "z_mm"}, 0,
                                "--fiducials (covariance columns cov_xx..cov_zz)");
  if (!markers.ok()) return cli::Fail(kCmd, markers.status());
  SolverConfig config;
  config.name = "pose_default (posit + bundle adjustment)";
  if (!FLAGS_config.empty()) {
    auto c = LoadSolverConfig(FLAGS_config);
    if (!c.ok()) return cli::Fail(kCmd, c.status());
    config = *c;
  }
  auto files = ListImageFiles(FLAGS_images);
  if (!files.ok()) return cli::Fail(kCmd, files.status().WithContext("--images"));
  cli::Step(kCmd, "detecting and labelling the markers in " + std::to_string(files->size()) +
                     " images");
  auto views = DetectAndLabelObjectViews(*files, *camera, *markers, options);
  if (!views.ok()) return cli::Fail(kCmd, views.status());

  Problem problem;
  problem.name = "pose";
  problem.path = FLAGS_images;
  problem.camera = *camera;
  problem.object_sigma_px = 1.0;  // every observation carries its own sigma
  problem.fiducials = *markers;
  problem.marker_diameter_mm = options.blobs.diameter_mm;
  problem.object_views = ToPoseViews(*views, options.sigma_floor_px);
  {
    const Status s = problem.Check();
    if (!s.ok()) return cli::Fail(kCmd, s);
  }
  cli::Step(kCmd, "solving " + std::to_string(problem.object_views.size()) + " views");
  auto solution = SolvePoseProblem(problem, config);
  if (!solution.ok()) return cli::Fail(kCmd, solution.status());
  plots.Draw(PosePlotData(problem, *solution));
  cli::Step(kCmd, "comparing with legacy POSIT");
  const PoseComparison comparison = ComparePoseMethods(problem, config, *solution);
  nlohmann::json j = PoseSolutionToJson(problem, *solution);
  j["comparison"] = PoseComparisonToJson(problem, comparison);
  j["marker_detection"] = ObjectViewsToJson(*views);
  ReportDoc doc = PoseReportDoc(problem, config, *solution, comparison);
  AppendObjectViews(&doc, *views);
  cli::Step(kCmd, "drawing the overlays");

  std::map<std::string, Pose6> solved;
  for (const ViewSolution& v : solution->views) solved[v.id] = v.cam_from_object;
  StagedOutputDir staged(FLAGS_out);
  Status s = staged.Begin();
  if (s.ok())
    s = WriteFileAtomic(JoinPath(staged.path(), "observations.csv"), MarkerObservationsCsv(*views));
  std::set<std::string> names;
  for (const ObjectView& v : *views) {
    if (!s.ok()) break;
    std::optional<Pose6> pose;
    if (solved.count(v.id)) pose = solved.at(v.id);
    const std::string first = OverlayFileName(v.id);
    std::string name = first;
    for (int k = 2; !names.insert(name).second; ++k) {
      name = first.substr(0, first.size() - 4) + "_" + std::to_string(k) + ".png";
    }
    const cv::Mat overlay = DrawMarkerOverlay(v, *camera, *markers, pose);
    if (!ImWrite(JoinPath(staged.path(), name), overlay)) {
      s = Status::Error(JoinPath(FLAGS_out, name) + ": cannot write the overlay");
    }
  }
  cli::Step(kCmd, "waiting for the plots");
  const ReportFiles report =
      RenderReport(doc, "carmba pose report: " + problem.name, plots.Result());
  cli::Step(kCmd, "writing the outputs");
  if (s.ok()) s = WriteFileAtomic(JoinPath(staged.path(), "report.md"), report.markdown);
  if (s.ok()) s = WriteFileAtomic(JoinPath(staged.path(), "report.html"), report.html);
  if (s.ok()) s = WriteFileAtomic(JoinPath(staged.path(), "result.json"), j.dump(2) + "\n");
  if (s.ok()) s = staged.Commit(/*replace_all=*/false);
  if (!s.ok()) return cli::Fail(kCmd, s);
  if (!report.warning.empty()) std::cerr << "carmba pose: warning: " << report.warning << std::endl;
  for (const ObjectView& v : *views) {
    if (!v.labelled) std::cerr << "carmba pose: skipped " << v.name << ": " << v.skipped << "\n";
  }
  if (!solution->converged) {
    std::cerr << "carmba pose: warning: the bundle adjustment did not converge ("
              << solution->termination << ")" << std::endl;
  }
  for (const auto& w : PoseWarnings(*solution)) {
    std::cerr << "carmba pose: warning: " << w << std::endl;
  }
  std::cout << "pose: " << problem.object_views.size() << " of " << views->size()
            << " views labelled, RMS " << solution->ba_result->rms_object_px << " px; wrote "
            << FLAGS_out << "/{observations.csv,result.json,report.md,report.html} and the overlays"
            << std::endl;
  return 0;
}

}  // namespace

CARMBA_COMMAND_FLAGS(pose, "images,camera,out,config,force,plots,marker_diameter_mm,detection");
CARMBA_REGISTER_COMMAND(
    pose,
    "Object poses from X-ray images: marker blobs, automatic labelling with the "
    "CT fiducials, bundle adjustment.",
    RunPose);
