// `carmba study`: run an accuracy study (configs/studies/*.yaml) of pose problems x solver
// configurations x sweep points x seeded trials, in parallel, recording every finished run in
// --out/runs.jsonl at once; then summary.csv, summary.md, timing.csv and report.html
// (study/runner.h, study/pose_study.h). Failed runs are recorded with their reason and the study
// goes on; at the end it exits 1 (a data failure) when more runs failed than allowed
// (--allow-failures, or the study's allow_failures; default none), saying how many failed and
// the most frequent reasons, so a Slurm array task of a failing shard fails too.
#include <gflags/gflags.h>
#include <unistd.h>

#include <cstdio>
#include <iostream>

#include "cli/command.h"
#include "cli/common_flags.h"
#include "study/pose_study.h"
#include "study/runner.h"
#include "util/file_util.h"
#include "util/plausible.h"

DEFINE_string(study, "", "Study YAML (configs/studies/NAME.yaml): problems, configs, sweeps, "
                         "trials, base_seed.");
DEFINE_bool(resume, false, "Continue the study in --out: skip the runs already in runs.jsonl.");
DEFINE_double(allow_failures, 0, "Share of the runs that may fail (0..1) before the study exits "
                                  "1; overrides the study's allow_failures. Default: none.");
DEFINE_string(shard, "1/1", "Run shard K/N of the runs only (e.g. 3/8; a Slurm array task runs "
                            "one shard); combine with 'carmba study-merge'.");

namespace {

int RunStudyCommand() {
  using namespace carmba;
  // --study and --out are required (checked before this runs: cli/command.h). An existing
  // study in --out is continued with --resume, or started over with --force.
  if (const Status s = cli::CheckOutDir(
          /*also_allowed=*/FLAGS_resume,
          "pass --resume to continue that study, --force to start it over"); !s.ok()) {
    return cli::Fail("study", s);
  }
  if (FLAGS_resume && FLAGS_force) {
    return cli::FailUsage("study", "--resume continues the study in --out, --force starts it over: "
                              "give one of them");
  }
  StudyRunOptions options;
  options.out_dir = FLAGS_out;
  {
    std::string err;
    if (!cli::CheckJobsFlag(&err)) return cli::FailUsage("study", err);
  }
  options.jobs = FLAGS_jobs;
  options.resume = FLAGS_resume;
  options.restart = FLAGS_force;
  options.plots = FLAGS_plots;
  options.progress = ChooseProgressStyle(::isatty(STDERR_FILENO) == 1, FLAGS_verbose);
  Status s = ParseShard(FLAGS_shard, &options.shard_k, &options.shard_n);
  if (!s.ok()) return cli::FailUsage("study", s);
  std::string error;
  if (!options.Check(&error)) return cli::FailUsage("study", "--" + error);
  StatusOr<StudySpec> spec = LoadStudySpec(FLAGS_study);
  if (!spec.ok()) return cli::Fail("study", spec.status());
  const bool allow_flag = !gflags::GetCommandLineFlagInfoOrDie("allow_failures").is_default;
  if (allow_flag && !InRange(FLAGS_allow_failures, kFailureFraction)) {
    return cli::Fail("study", "--allow-failures: expected a fraction " +
                                  FormatRange(kFailureFraction) + ", got " +
                                  FormatCompact(FLAGS_allow_failures));
  }
  const double allowed = allow_flag ? FLAGS_allow_failures : spec->allow_failures;
  StudyRunStats stats;
  cli::Step("study", "running the study (runs, then the summaries and report.html)");
  s = RunStudy(*spec, PoseStudyRunFunction(), options, &stats);
  if (!s.ok()) return cli::Fail("study", s);
  std::printf(
      "study %s (shard %d/%d): %d runs, %d already done, %d run now with %d jobs in %.3g s, "
      "%d failed now, %d failed in total\n",
      spec->name.c_str(),
      options.shard_k,
      options.shard_n,
      stats.runs_in_shard,
      stats.skipped,
      stats.executed,
      stats.jobs,
      stats.wall_s,
      stats.failed,
      stats.failed_total);
  if (stats.executed > 0) {
    std::printf("runner overhead: %.2f%% (runs' own time %.4g s over wall %.4g s x %d jobs)\n",
                100 * stats.Overhead(), stats.runs_time_s, stats.wall_s, stats.jobs);
  }
  std::printf("wrote %s\n", JoinPath(FLAGS_out, "summary.md").c_str());
  if (!stats.report_warning.empty()) {
    std::cerr << "carmba study: warning: " << stats.report_warning << std::endl;
  }
  if (stats.dropped_lines > 0) {
    std::cerr << "carmba study: warning: dropped " << stats.dropped_lines
              << " partial or duplicate lines of runs.jsonl (their runs ran again)" << std::endl;
  }
  if (const Status failures = CheckFailures(stats, allowed, FLAGS_out); !failures.ok()) {
    return cli::Fail("study", failures);
  }
  if (stats.failed_total > 0) {
    std::cerr << "carmba study: warning: " << DescribeFailures(stats) << " (allowed: "
              << FormatCompact(allowed) << " of the runs; every reason in "
              << JoinPath(FLAGS_out, "summary.md") << ", section Failures)" << std::endl;
  }
  return 0;
}

}  // namespace

CARMBA_REGISTER_COMMAND(study,
                        "Run an accuracy study: problems x configs x sweeps x seeded trials.",
                        RunStudyCommand);
CARMBA_COMMAND_FLAGS(study, "out,jobs,force,plots");
CARMBA_REQUIRED_FLAGS(study, "study,out");
