// Summaries of a study's runs per problem x config x sweep point: DIR/summary.csv,
// DIR/summary.md and DIR/timing.csv.
//
// Reproducibility contract: summary.csv and summary.md depend only on the set of run records
// (sorted by enumeration index, aggregated in that order, numbers printed with %.6g), so they are
// byte-identical for any --jobs, for a resumed study and for merged shards, provided the run
// function returns the same numbers for the same run. (The pose solver does up to the last bits:
// Ceres was observed to vary by ~1e-15 relative between identical calls; %.6g hides that except
// when a number falls exactly on a rounding boundary, a chance of about 1e-9 per printed number.)
// Wall-clock times vary from run to run; they are kept out of both (they go to timing.csv and to
// the last section of report.html, "Timing").
//
// summary.csv is long-format, one row per group and metric:
//   problem,config,<one column per swept variable>,runs,failed,kind,metric,n,mean,median,rms,
//   p95,max,pred_sigma,emp_sigma,consistency
// kind = error  : magnitudes against the truth ("errors" of a result): mean, median, rms, p95, max
//        signed : estimate - truth per parameter ("signed_errors"): mean = bias, median, rms,
//                 p95 and max of |e|, emp_sigma = sample standard deviation over the trials,
//                 pred_sigma = RMS of the reported sigmas ("sigmas"), consistency =
//                 emp_sigma / pred_sigma (1 = the reported uncertainty is honest, > 1 = it is
//                 overconfident)
//        value  : other numbers ("values", e.g. rms_px, iterations; "converged" as 0/1)
//        runs   : a group whose runs all failed has this one row (metric "-", n = 0)
// Empty fields are statistics that do not apply; "nan" where too few samples exist.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "util/format.h"
#include "report/report_doc.h"
#include "study/run_store.h"

namespace carmba {

struct MetricStats {
  std::string kind;  // error | signed | value
  std::string name;
  int n = 0;
  double mean = 0, median = 0, rms = 0, p95 = 0, max = 0;
  bool has_sigma = false;  // signed with reported sigmas
  double pred_sigma = 0, emp_sigma = 0, consistency = 0;
};

struct FailureGroup {
  std::string error;
  int count = 0;
  std::string first_key;
};

struct GroupSummary {
  std::string problem;
  std::string config;
  SweepPoint sweep;
  int first_index = 0;
  int runs = 0;
  int failed = 0;
  std::vector<MetricStats> metrics;   // sorted by kind, then name
  std::vector<FailureGroup> failures; // by first occurrence
  double time_mean_s = 0, time_max_s = 0, time_total_s = 0, cpu_total_s = 0;
  // Pooled "residuals_px" of the ok runs, and mean "budget" contributions, for the report.
  std::vector<double> residuals;
  std::vector<std::pair<std::string, double>> budget;

  const MetricStats* Find(const std::string& kind, const std::string& name) const;
};

// Groups the records (any order) and computes the statistics, deterministically.
std::vector<GroupSummary> Summarize(std::vector<RunRecord> records);

// The names of the swept variables, in the order of the first record that has them.
std::vector<std::string> SweepNames(const std::vector<GroupSummary>& groups);

std::string SummaryCsv(const std::vector<GroupSummary>& groups);
std::string TimingCsv(const std::vector<GroupSummary>& groups);

// summary.md and the tables of report.html (report/report_doc.h), and the data of its plots
// (scripts/report_plots.py: error against each swept variable, reported against empirical sigma,
// residual histograms, error budgets).
// `info` is DIR/study.json (name, runs_total, fingerprint).
ReportDoc SummaryDoc(const nlohmann::json& info, const std::vector<GroupSummary>& groups);
// The section "Timing" (report.html only): the shard, the runs' own times and, when `wall_s` and
// `jobs` are > 0, the invocation's wall time.
void AddTimingSection(const nlohmann::json& info,
                      const std::vector<GroupSummary>& groups,
                      double wall_s,
                      int jobs,
                      ReportDoc* doc);
nlohmann::json StudyPlotData(const std::vector<GroupSummary>& groups);

}  // namespace carmba
