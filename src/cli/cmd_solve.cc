// `carmba solve`: solve a problem (problem/problem.h) with a solver configuration: a pose problem
// (object views only) by the pose front end (problem/pose_solver.h), any other by the joint one
// (joint/joint_solver.h). Writes result.json, report.md,
// report.html (with plots, report/plots.h) and geometry.json (per view the projection matrix CT mm
// -> undistorted px, export/view_geometry.h) into --out (created with its parents if needed; an
// existing result only with --force). On any error nothing is written.
#include <gflags/gflags.h>
#include <unistd.h>

#include <iostream>

#include "calib/crosscheck.h"
#include "cli/command.h"
#include "cli/common_flags.h"
#include "export/view_geometry.h"
#include "joint/joint_solver.h"
#include "problem/pose_solver.h"
#include "report/joint_report.h"
#include "report/plots.h"
#include "report/pose_report.h"
#include "util/file_util.h"
#include "util/python_worker.h"
#include "util/temp_paths.h"

namespace {

// geometry.json's text, or empty with `why` when a view's image size is unknown (a joint problem
// whose plate observations carry no image size): the projection matrices need it.
std::string GeometryText(const carmba::GeometrySet& g, std::string* why) {
  for (const auto& v : g.views) {
    if (v.camera.width <= 0 || v.camera.height <= 0) {
      *why = "view '" + v.id + "': image size unknown";
      return "";
    }
  }
  return carmba::GeometryToJson(g).dump(2) + "\n";
}

// Writes geometry.json into the staging directory when it can be built (else a warning).
carmba::Status WriteGeometry(const std::string& dir, const carmba::GeometrySet& g) {
  std::string why;
  const std::string text = GeometryText(g, &why);
  if (text.empty()) {
    std::cerr << "carmba solve: warning: no geometry.json: " << why << std::endl;
    return carmba::Status::Ok();
  }
  return carmba::WriteFileAtomic(carmba::JoinPath(dir, "geometry.json"), text);
}

// A joint problem (plate views, or object views with an intrinsics prior): the engine's joint
// bundle adjustment. The plots are drawn while the mrcal cross-check runs.
int RunJoint(const carmba::Problem& problem,
             const carmba::SolverConfig& config,
             carmba::PlotProcess& plots) {
  using namespace carmba;
  MrcalCrossCheckOptions mrcal_options;
  mrcal_options.python = FLAGS_mrcal_python;
  std::unique_ptr<PythonWorker> mrcal_python;
  if (FLAGS_mrcal) {  // its imports overlap the solve
    mrcal_python = StartMrcalPython(mrcal_options.python);
    mrcal_options.warm = mrcal_python.get();
  }
  cli::Step("solve",
            "solving the joint bundle adjustment (" + std::to_string(problem.plate.views.size()) +
                " plate views, " + std::to_string(problem.object_views.size()) + " object views)");
  auto solution = SolveJointProblem(problem, config);
  if (!solution.ok()) return cli::Fail("solve", solution.status());
  cli::Step("solve", "the report and its plot data");
  nlohmann::json j = JointSolutionToJson(problem, config, *solution);
  nlohmann::json plot_data = JointPlotData(*solution);
  AddFlexPlotData(j, &plot_data);  // the intrinsics against the C-arm angle (flex)
  plots.Draw(plot_data);
  if (FLAGS_mrcal) {
    cli::Step("solve", "mrcal cross-check");
    // The mrcal cross-check (a failure is reported, not an error of the solve).
    // Removed when it goes out of scope and on SIGINT/SIGTERM (util/temp_paths.h).
    const ScopedTempPath work(FLAGS_out + ".mrcal.tmp." + std::to_string(::getpid()));
    mrcal_options.work_dir = work.path();
    j["mrcal_crosscheck"] = JointMrcalCrossCheckJson(problem, *solution, mrcal_options);
  } else {
    j["mrcal_crosscheck"] = {{"error", "disabled (--no-mrcal)"}};
  }
  ReportDoc doc = JointReportDoc(problem, config, *solution);
  doc.Append(JointMrcalDoc(j["mrcal_crosscheck"]));
  cli::Step("solve", "waiting for the plots");
  const ReportFiles report =
      RenderReport(doc, "carmba joint report: " + problem.name, plots.Result());
  cli::Step("solve", "writing the outputs");
  // All files or none; other files in an existing --out are kept.
  StagedOutputDir staged(FLAGS_out);
  Status s = staged.Begin();
  if (s.ok()) s = WriteFileAtomic(JoinPath(staged.path(), "report.md"), report.markdown);
  if (s.ok()) s = WriteFileAtomic(JoinPath(staged.path(), "report.html"), report.html);
  if (s.ok()) s = WriteFileAtomic(JoinPath(staged.path(), "result.json"), j.dump(2) + "\n");
  if (s.ok()) s = WriteGeometry(staged.path(), JointSolutionGeometry(problem, *solution));
  if (s.ok()) s = staged.Commit(/*replace_all=*/false);
  if (!s.ok()) return cli::Fail("solve", s);
  if (!report.warning.empty())
    std::cerr << "carmba solve: warning: " << report.warning << std::endl;
  for (const auto& w : JointWarnings(*solution)) {
    std::cerr << "carmba solve: warning: " << w << std::endl;
  }
  if (!solution->result.converged()) {
    std::cerr << "carmba solve: warning: the bundle adjustment did not converge ("
              << solution->result.TerminationText() << "): the results are not at a minimum"
              << std::endl;
  }
  std::cout << "solved " << problem.name << " (joint) with " << config.name << ": "
            << problem.plate.views.size() << " plate views, " << problem.object_views.size()
            << " object views, RMS " << solution->result.rms_plate_px << " / "
            << solution->result.rms_object_px << " px, " << solution->result.iterations
            << " iterations; wrote " << FLAGS_out << "/result.json and " << FLAGS_out
            << "/report.md (and report.html)" << std::endl;
  return 0;
}

// A pose problem (object views only, the intrinsics held at camera.json): the pose front end.
int RunPose(const carmba::Problem& problem,
            const carmba::SolverConfig& config,
            carmba::PlotProcess& plots) {
  using namespace carmba;
  StatusOr<PoseSolution> solution = Status::Error("not solved");
  cli::Step("solve", "solving " + std::to_string(problem.object_views.size()) + " views");
  {
    auto progress = cli::MakeProgress(
        "solve: initial poses", static_cast<int>(problem.object_views.size()), "views");
    solution = SolvePoseProblem(problem, config, progress->Callback());
  }
  if (!solution.ok()) return cli::Fail("solve", solution.status());
  plots.Draw(PosePlotData(problem, *solution));
  cli::Step("solve", "comparing with legacy POSIT");
  const PoseComparison comparison = ComparePoseMethods(problem, config, *solution);
  const nlohmann::json j = PoseResultJson(problem, *solution, comparison);
  const ReportDoc doc = PoseReportDoc(problem, config, *solution, comparison);
  cli::Step("solve", "waiting for the plots");
  const ReportFiles report =
      RenderReport(doc, "carmba pose report: " + problem.name, plots.Result());
  cli::Step("solve", "writing the outputs");

  // All files or none (a failed second write used to leave report.md behind); other files in
  // an existing --out are kept.
  StagedOutputDir staged(FLAGS_out);
  Status s = staged.Begin();
  if (s.ok()) s = WriteFileAtomic(JoinPath(staged.path(), "report.md"), report.markdown);
  if (s.ok()) s = WriteFileAtomic(JoinPath(staged.path(), "report.html"), report.html);
  if (s.ok()) s = WriteFileAtomic(JoinPath(staged.path(), "result.json"), j.dump(2) + "\n");
  if (s.ok()) s = WriteGeometry(staged.path(), PoseSolutionGeometry(problem, *solution));
  if (s.ok()) s = staged.Commit(/*replace_all=*/false);
  if (!s.ok()) return cli::Fail("solve", s);
  if (!solution->converged) {
    std::cerr << "carmba solve: warning: the bundle adjustment did not converge ("
              << solution->termination << "; max_iterations " << config.max_iterations
              << "): the results are not at a minimum" << std::endl;
  }
  if (!report.warning.empty())
    std::cerr << "carmba solve: warning: " << report.warning << std::endl;
  if (!comparison.handedness_warning.empty()) {
    std::cerr << "carmba solve: warning: " << comparison.handedness_warning << std::endl;
  }
  for (const auto& w : PoseWarnings(*solution)) {
    std::cerr << "carmba solve: warning: " << w << std::endl;
  }
  std::cout << "solved " << problem.name << " with " << config.name << ": "
            << solution->views.size() << " views, RMS " << solution->ba_result->rms_object_px
            << " px, " << solution->ba_result->iterations << " iterations; wrote " << FLAGS_out
            << "/result.json and " << FLAGS_out << "/report.md (and report.html)" << std::endl;
  return 0;
}

int RunSolve() {
  using namespace carmba;
  // --problem, --config and --out are required (checked before this runs: cli/command.h).
  if (const Status s = cli::CheckOutDir(); !s.ok()) return cli::Fail("solve", s);
  PlotOptions plot_options;
  plot_options.enabled = FLAGS_plots;
  PlotProcess plots(plot_options);  // starts importing matplotlib while the problem is solved
  cli::Step("solve", "loading the problem " + FLAGS_problem);
  auto problem = LoadProblem(FLAGS_problem);
  if (!problem.ok()) return cli::Fail("solve", problem.status());
  auto config = LoadSolverConfig(FLAGS_config);
  if (!config.ok()) return cli::Fail("solve", config.status());
  return problem->IsPoseProblem() ? RunPose(*problem, *config, plots)
                                  : RunJoint(*problem, *config, plots);
}

}  // namespace

CARMBA_COMMAND_FLAGS(solve, "problem,config,out,force,plots,mrcal,mrcal_python");
CARMBA_REQUIRED_FLAGS(solve, "problem,config,out");
CARMBA_REGISTER_COMMAND(solve,
                        "Solve a problem (problem/problem.h: object views only = a pose problem, "
                        "POSIT + bundle adjustment + covariance; with plate views or an intrinsics "
                        "prior = the joint bundle adjustment); writes result.json, "
                        "report.md and geometry.json (per view the 3x4 projection matrix from CT "
                        "mm to pixels of the undistorted image; carmba export-geometry converts "
                        "it for RTK / plastimatch).",
                        RunSolve);
