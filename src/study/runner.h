// The study runner: executes a study's runs on a pool of local threads, records each finished
// run in DIR/runs.jsonl at once, resumes, shards, and writes the summaries and the report.
//
//   StudySpec spec = LoadStudySpec("configs/studies/noise_sweep.yaml").value();
//   StudyRunOptions options;  options.out_dir = "out/noise"; options.jobs = 2;
//   StudyRunStats stats;
//   Status s = RunStudy(spec, PoseStudyRunFunction(), options, &stats);
//
// Contract of the run function: it is called concurrently from several threads with distinct
// runs, must be deterministic given the RunSpec (all randomness from RunSpec::seed), must run
// single-threaded, and reports bad data as an error Status (recorded; the study goes on).
// An exception escaping it is caught and recorded as the run's error too.
//
// Files in DIR:
//   study.json    the study's name and run-list fingerprint (written first, atomically)
//   runs.jsonl    one line per finished run (study/run_store.h); grows while the study runs
//   summary.csv, summary.md, timing.csv, report.html   written atomically at the end
// Without `resume`, a DIR whose runs.jsonl already has runs is refused. With `resume`, the runs
// already in runs.jsonl are skipped; a partial last line (a kill during a write) and duplicate
// lines are dropped (the file is rewritten atomically without them) and those runs run again.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "study/run_store.h"
#include "study/study_spec.h"
#include "util/progress.h"
#include "util/status.h"

namespace carmba {

using RunFunction = std::function<StatusOr<nlohmann::json>(const RunSpec&)>;

struct StudyRunOptions {
  std::string out_dir;     // required
  int jobs = 0;            // worker threads; 0 = std::thread::hardware_concurrency()
  bool resume = false;     // skip runs already recorded in out_dir/runs.jsonl
  bool restart = false;    // discard the runs already recorded there and start over
  int shard_k = 1;         // run shard K of N (see ShardRuns)
  int shard_n = 1;
  // Progress per finished run on stderr (util/progress.h; the command chooses the style).
  ProgressStyle progress = ProgressStyle::kNone;
  bool write_report = true;  // report.html besides the summaries
  bool plots = true;         // report.html's plots (false: --no-plots, no Python)

  bool Check(std::string* error) const;
};

// One distinct reason of failed runs and how many runs failed with it.
struct FailureReason {
  std::string error;
  int count = 0;
};

struct StudyRunStats {
  int runs_in_shard = 0;    // runs this invocation is responsible for
  int skipped = 0;          // already recorded (resume)
  int executed = 0;         // run now
  int failed = 0;           // of those executed
  int failed_total = 0;     // failed runs in runs.jsonl at the end
  // The distinct reasons of those, most frequent first (ties: the earliest run first).
  std::vector<FailureReason> failure_reasons;
  int dropped_lines = 0;    // partial or duplicate lines removed on resume
  int jobs = 0;
  double wall_s = 0;        // wall time of the execution phase
  double runs_time_s = 0;   // sum of the executed runs' own wall times
  // 1 - runs_time_s / (wall_s * jobs): the share of the workers' time not spent in the runs
  // (scheduling, JSON, appending, waiting for the last run). Only meaningful when
  // executed >> jobs.
  double Overhead() const;
  // Non-empty when report.html was written without (some) plots: why (report/plots.h).
  std::string report_warning;
};

// "12 of 240 runs failed: 'p.yaml: cannot open' (10 runs); 'k: bad' (2 runs)", with the first
// `max_reasons` distinct reasons (and how many more there are); "" when no run failed.
std::string DescribeFailures(const StudyRunStats& stats, size_t max_reasons = 3);

// Error (DescribeFailures, then where all reasons are: DIR/summary.md) when the failed runs are
// more than `allowed_fraction` (0..1) of the runs in the shard: a study that exits 0 succeeded.
Status CheckFailures(const StudyRunStats& stats, double allowed_fraction, const std::string& dir);

Status RunStudy(const StudySpec& spec,
                const RunFunction& run,
                const StudyRunOptions& options,
                StudyRunStats* stats);

// Writes summary.csv, summary.md, timing.csv and (optionally) report.html of DIR from its
// study.json and runs.jsonl. `wall_s`/`jobs` only feed the timing section (0 = unknown).
// report.html holds summary.md's tables and matplotlib plots (report/plots.h); when the plots
// could not be drawn, `report_warning` (if given) says why.
Status WriteStudyOutputs(const std::string& dir,
                         bool write_report,
                         double wall_s,
                         int jobs,
                         std::string* report_warning = nullptr,
                         bool plots = true);

// Combines shard directories (each with study.json and runs.jsonl of the same study fingerprint)
// into `out_dir`: runs.jsonl sorted by enumeration index, study.json, summaries and report.
// Errors: no shards, a directory without study.json, differing fingerprints, a run recorded
// with different contents in two shards, out_dir holding runs already, and runs of the study
// missing from all shards unless `allow_missing`. Nothing is written on error.
Status MergeStudyShards(const std::vector<std::string>& shard_dirs,
                        const std::string& out_dir,
                        bool write_report,
                        bool allow_missing,
                        int* runs_merged,
                        int* runs_missing,
                        std::string* report_warning = nullptr,
                        bool plots = true);

}  // namespace carmba
