// `carmba solve`: solve a pose problem with a solver configuration; writes result.json and
// report.md into --out (created if needed). On any error nothing is written.
#include <gflags/gflags.h>

#include <unistd.h>

#include <filesystem>
#include <iostream>

#include "cli/command.h"
#include "cli/common_flags.h"
#include "joint/joint_problem.h"
#include "problem/pose_problem.h"
#include "report/pose_report.h"
#include "util/file_util.h"


namespace {

// A joint problem (plate and/or object views): the engine's joint bundle adjustment.
int RunJoint() {
  using namespace carmba;
  auto problem = LoadJointProblem(FLAGS_problem);
  if (!problem.ok()) return cli::Fail("solve", problem.status());
  auto config = LoadSolverConfig(FLAGS_config);
  if (!config.ok()) return cli::Fail("solve", config.status());
  auto solution = SolveJointProblem(*problem, *config);
  if (!solution.ok()) return cli::Fail("solve", solution.status());
  // The mrcal cross-check (a failure is reported, not an error of the solve).
  const std::string work = FLAGS_out + ".mrcal.tmp." + std::to_string(::getpid());
  auto mrcal = JointMrcalCrossCheck(*problem, *solution, work);
  {
    std::error_code ec;
    std::filesystem::remove_all(work, ec);
  }
  nlohmann::json j = JointSolutionToJson(*problem, *config, *solution);
  if (mrcal.ok()) {
    j["mrcal_crosscheck"] = *mrcal;
  } else {
    j["mrcal_crosscheck"] = {{"error", mrcal.status().message()}};
  }
  std::string report = JointReportMarkdown(*problem, *config, *solution) +
                      JointMrcalMarkdown(j["mrcal_crosscheck"]);
  // Both files or neither; other files in an existing --out are kept.
  StagedOutputDir staged(FLAGS_out);
  Status s = staged.Begin();
  if (s.ok()) s = WriteFileAtomic(JoinPath(staged.path(), "result.json"), j.dump(2) + "\n");
  if (s.ok() && j.contains("intrinsics_model") && !problem->angles.empty()) {
    // The intrinsics against the C-arm angle (linked from the report); a missing matplotlib is
    // reported, not an error of the solve.
    const Status plot = WriteIntrinsicsPlot(JoinPath(staged.path(), "result.json"),
                                            JoinPath(staged.path(), "intrinsics_vs_angle.png"));
    if (!plot.ok()) {
      report += "\nThe plot intrinsics_vs_angle.png was not written: " + plot.message() + "\n";
      std::cerr << "carmba solve: warning: " << plot.message() << std::endl;
    }
  }
  if (s.ok()) s = WriteFileAtomic(JoinPath(staged.path(), "report.md"), report);
  if (s.ok()) s = staged.Commit(/*replace_all=*/false);
  if (!s.ok()) return cli::Fail("solve", s);
  if (!solution->result.converged) {
    std::cerr << "carmba solve: warning: the bundle adjustment did not converge ("
              << solution->result.termination << "): the results are not at a minimum" << std::endl;
  }
  std::cout << "solved " << problem->name << " (joint) with " << config->name << ": "
            << problem->plate.views.size() << " plate views, " << problem->object_views.size()
            << " object views, RMS " << solution->result.rms_plate_px << " / "
            << solution->result.rms_object_px << " px, " << solution->result.iterations
            << " iterations; wrote " << FLAGS_out << "/result.json and " << FLAGS_out
            << "/report.md" << std::endl;
  return 0;
}

int RunSolve() {
  using namespace carmba;
  if (FLAGS_problem.empty()) return cli::Fail("solve", "--problem is required");
  if (FLAGS_config.empty()) return cli::Fail("solve", "--config is required");
  if (FLAGS_out.empty()) return cli::Fail("solve", "--out is required");
  {
    const Status s = CheckOutputDir(FLAGS_out, "--out");
    if (!s.ok()) return cli::Fail("solve", s);
  }
  if (IsJointProblemFile(FLAGS_problem)) return RunJoint();
  auto problem = LoadPoseProblem(FLAGS_problem);
  if (!problem.ok()) return cli::Fail("solve", problem.status());
  auto config = LoadSolverConfig(FLAGS_config);
  if (!config.ok()) return cli::Fail("solve", config.status());
  auto solution = SolvePoseProblem(*problem, *config);
  if (!solution.ok()) return cli::Fail("solve", solution.status());
  const PoseComparison comparison = ComparePoseMethods(*problem, *config, *solution);
  nlohmann::json j = PoseSolutionToJson(*problem, *solution);
  j["comparison"] = PoseComparisonToJson(*problem, comparison);
  const std::string report = PoseReportMarkdown(*problem, *config, *solution, comparison);

  // Both files or neither (a failed second write used to leave report.md behind); other files in
  // an existing --out are kept.
  StagedOutputDir staged(FLAGS_out);
  Status s = staged.Begin();
  if (s.ok()) s = WriteFileAtomic(JoinPath(staged.path(), "report.md"), report);
  if (s.ok()) s = WriteFileAtomic(JoinPath(staged.path(), "result.json"), j.dump(2) + "\n");
  if (s.ok()) s = staged.Commit(/*replace_all=*/false);
  if (!s.ok()) return cli::Fail("solve", s);
  if (config->refine && solution->termination != "CONVERGENCE") {
    std::cerr << "carmba solve: warning: the bundle adjustment did not converge ("
              << solution->termination << "; max_iterations " << config->max_iterations
              << "): the results are not at a minimum" << std::endl;
  }
  if (!comparison.handedness_warning.empty()) {
    std::cerr << "carmba solve: warning: " << comparison.handedness_warning << std::endl;
  }
  std::cout << "solved " << problem->name << " with " << config->name << ": "
            << solution->views.size() << " views, RMS " << solution->rms_px << " px, "
            << solution->iterations << " iterations; wrote " << FLAGS_out << "/result.json and "
            << FLAGS_out << "/report.md" << std::endl;
  return 0;
}

}  // namespace

CARMBA_COMMAND_FLAGS(solve, "problem,config,out");
CARMBA_REGISTER_COMMAND(solve,
                        "Solve a pose problem (POSIT + bundle adjustment + covariance).",
                        RunSolve);
