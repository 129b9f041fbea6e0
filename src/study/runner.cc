#include "study/runner.h"

#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <exception>
#include <map>
#include <mutex>
#include <set>
#include <thread>

#include "report/plots.h"
#include "study/study_inputs.h"
#include "study/summary.h"
#include "util/file_util.h"
#include "util/plausible.h"

namespace carmba {
namespace {

double ThreadCpuSeconds() {
  timespec ts;
  if (clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts) != 0) return 0;
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

RunRecord Execute(const RunFunction& run, const RunSpec& spec) {
  RunRecord r;
  r.index = spec.index;
  r.key = spec.key;
  r.problem = spec.problem->name;
  r.config = spec.config->name;
  r.sweep = spec.sweep;
  r.trial = spec.trial;
  r.seed = spec.seed;
  const auto t0 = std::chrono::steady_clock::now();
  const double c0 = ThreadCpuSeconds();
  try {
    StatusOr<nlohmann::json> result = run(spec);
    if (result.ok()) {
      r.ok = true;
      r.result = std::move(result).value();
    } else {
      r.error = result.status().message();
      if (r.error.empty()) r.error = "run failed without a message";
    }
  } catch (const std::exception& e) {
    r.error = std::string("exception: ") + e.what();
  } catch (...) {
    r.error = "exception of unknown type";
  }
  r.cpu_s = ThreadCpuSeconds() - c0;
  r.time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // A one-line reason, always.
  std::replace(r.error.begin(), r.error.end(), '\n', ' ');
  return r;
}

// Rewrites `path` keeping only `records` (atomically).
Status RewriteRunLog(const std::string& path, const std::vector<RunRecord>& records) {
  std::string text;
  for (const auto& r : records) text += RunRecordToJson(r).dump() + "\n";
  return WriteFileAtomic(path, text);
}

StatusOr<nlohmann::json> ReadStudyInfo(const std::string& dir) {
  const std::string path = JoinPath(dir, "study.json");
  StatusOr<std::string> text = ReadFile(path);
  if (!text.ok()) return text.status();
  nlohmann::json j = nlohmann::json::parse(*text, nullptr, false);
  if (j.is_discarded() || !j.is_object() || !j.contains("fingerprint") ||
      !j["fingerprint"].is_string()) {
    return Status::Error(path + ": malformed, expected a JSON object with a 'fingerprint'");
  }
  return j;
}

// The distinct errors of the failed runs, most frequent first (ties: the earliest run first).
std::vector<FailureReason> CountFailureReasons(const std::vector<RunRecord>& sorted_records,
                                               int* failed) {
  std::vector<FailureReason> reasons;
  *failed = 0;
  for (const auto& r : sorted_records) {
    if (r.ok) continue;
    ++*failed;
    auto it = std::find_if(reasons.begin(), reasons.end(),
                           [&](const FailureReason& f) { return f.error == r.error; });
    if (it == reasons.end()) {
      reasons.push_back(FailureReason{r.error, 1});
    } else {
      ++it->count;
    }
  }
  std::stable_sort(
      reasons.begin(), reasons.end(), [](const FailureReason& a, const FailureReason& b) {
        return a.count > b.count;
      });
  return reasons;
}

}  // namespace

bool StudyRunOptions::Check(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (out_dir.empty()) return fail("output directory: expected a path, got nothing");
  if (!InRange(jobs, plausible::kJobs)) {
    return fail("jobs: expected " + FormatRange(plausible::kJobs) + " (0 = all cores), got " +
                std::to_string(jobs));
  }
  if (shard_n < 1 || shard_k < 1 || shard_k > shard_n) {
    return fail("shard: expected 1 <= K <= N, got " + std::to_string(shard_k) + "/" +
                std::to_string(shard_n));
  }
  return true;
}

double StudyRunStats::Overhead() const {
  if (wall_s <= 0 || jobs <= 0) return 0;
  return 1.0 - runs_time_s / (wall_s * jobs);
}

Status RunStudy(const StudySpec& spec,
                const RunFunction& run,
                const StudyRunOptions& options,
                StudyRunStats* stats) {
  StudyRunStats local;
  StudyRunStats& st = stats ? *stats : local;
  st = StudyRunStats();
  std::string error;
  if (!spec.Check(&error)) return Status::Error(error);
  if (!options.Check(&error)) return Status::Error(error);

  const std::vector<RunSpec> all_runs = EnumerateRuns(spec);
  const std::vector<RunSpec> runs = ShardRuns(all_runs, options.shard_k, options.shard_n);
  st.runs_in_shard = static_cast<int>(runs.size());
  const nlohmann::json info =
      StudyInfoJson(spec, all_runs, StudyInputFiles(spec), options.shard_k, options.shard_n);
  const std::string& dir = options.out_dir;
  const std::string log_path = JoinPath(dir, "runs.jsonl");
  const std::string info_path = JoinPath(dir, "study.json");

  CARMBA_RETURN_IF_ERROR(MakeDirs(dir));
  int bad = 0, dup = 0;
  StatusOr<std::vector<RunRecord>> existing = ReadRunLog(log_path, &bad, &dup);
  if (!existing.ok()) return existing.status();
  if (options.restart && !options.resume && (!existing->empty() || bad > 0)) {
    CARMBA_RETURN_IF_ERROR(RewriteRunLog(log_path, {}));
    existing = std::vector<RunRecord>();
    bad = dup = 0;
  }
  if (!options.resume && (!existing->empty() || bad > 0)) {
    return Status::Error(log_path + ": already holds " + std::to_string(existing->size()) +
                         " runs; pass --resume to continue that study, --force to start it "
                         "over, or choose a new --out");
  }
  if (options.resume && FileExists(info_path)) {
    StatusOr<nlohmann::json> old = ReadStudyInfo(dir);
    if (!old.ok()) return old.status();
    const std::string changed = DescribeStudyChange(*old, info);
    if (!changed.empty()) {
      return Status::Error(info_path + ": the study changed since these runs were recorded: " +
                           changed + "; expected the same study to resume (--force starts it "
                           "over, or choose a new --out)");
    }
    if (old->value("shard", std::string()) != info["shard"].get<std::string>()) {
      return Status::Error(info_path + ": the directory holds shard " +
                           old->value("shard", std::string("?")) + " of study '" +
                           old->value("name", std::string("?")) + "', not shard " +
                           info["shard"].get<std::string>() + "; expected the same shard");
    }
  }
  // Keep only records of this shard's runs; anything else means a different study.
  std::set<std::string> shard_keys;
  for (const auto& r : runs) shard_keys.insert(r.key);
  std::set<std::string> done;
  for (const auto& r : *existing) {
    if (!shard_keys.count(r.key)) {
      return Status::Error(log_path + ": holds run '" + r.key + "' which is not a run of shard " +
                           info["shard"].get<std::string>() + " of study '" + spec.name + "'");
    }
    done.insert(r.key);
  }
  st.dropped_lines = bad + dup;
  if (bad + dup > 0) CARMBA_RETURN_IF_ERROR(RewriteRunLog(log_path, *existing));
  CARMBA_RETURN_IF_ERROR(WriteFileAtomic(info_path, info.dump(2) + "\n"));

  std::vector<const RunSpec*> pending;
  for (const auto& r : runs) {
    if (!done.count(r.key)) pending.push_back(&r);
  }
  st.skipped = static_cast<int>(runs.size() - pending.size());

  RunLogWriter writer;
  CARMBA_RETURN_IF_ERROR(writer.Open(log_path));
  int jobs = options.jobs > 0 ? options.jobs
                              : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  jobs = std::max(1, std::min<int>(jobs, static_cast<int>(std::max<size_t>(1, pending.size()))));
  st.jobs = jobs;

  std::atomic<size_t> next{0};
  std::mutex mutex;  // guards the counters below, the progress line and the first write error
  int executed = 0, failed = 0;
  double runs_time = 0;
  Status write_error;
  const auto start = std::chrono::steady_clock::now();
  Progress progress("study " + spec.name, static_cast<int>(pending.size()), "runs",
                    options.progress);
  auto worker = [&]() {
    for (;;) {
      const size_t i = next.fetch_add(1);
      if (i >= pending.size()) return;
      {
        std::lock_guard<std::mutex> lock(mutex);
        if (!write_error.ok()) return;
      }
      RunRecord record = Execute(run, *pending[i]);
      const Status appended = writer.Append(record);
      std::lock_guard<std::mutex> lock(mutex);
      if (!appended.ok()) {
        if (write_error.ok()) write_error = appended;
        return;
      }
      ++executed;
      failed += record.ok ? 0 : 1;
      runs_time += record.time_s;
      progress.Tick(record.key);
    }
  };
  if (jobs == 1) {
    worker();
  } else {
    std::vector<std::thread> threads;
    for (int t = 0; t < jobs; ++t) threads.emplace_back(worker);
    for (auto& t : threads) t.join();
  }
  writer.Close();
  st.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  st.executed = executed;
  st.failed = failed;
  st.runs_time_s = runs_time;
  progress.Finish();
  CARMBA_RETURN_IF_ERROR(write_error);

  CARMBA_RETURN_IF_ERROR(
      WriteStudyOutputs(dir, options.write_report, st.wall_s, jobs, &st.report_warning,
                        options.plots));
  StatusOr<std::vector<RunRecord>> final_records = ReadRunLog(log_path, nullptr, nullptr);
  if (!final_records.ok()) return final_records.status();
  std::vector<RunRecord> sorted = std::move(final_records).value();
  SortRecords(&sorted);
  st.failure_reasons = CountFailureReasons(sorted, &st.failed_total);
  return Status::Ok();
}

std::string DescribeFailures(const StudyRunStats& stats, size_t max_reasons) {
  if (stats.failed_total == 0) return "";
  std::string s = std::to_string(stats.failed_total) + " of " +
                  std::to_string(stats.runs_in_shard) + " runs failed: ";
  const size_t shown = std::min(max_reasons, stats.failure_reasons.size());
  for (size_t i = 0; i < shown; ++i) {
    const FailureReason& f = stats.failure_reasons[i];
    std::string error = f.error;
    if (error.size() > 300) error = error.substr(0, 297) + "...";
    s += (i ? "; '" : "'") + error + "' (" + std::to_string(f.count) +
         (f.count == 1 ? " run)" : " runs)");
  }
  if (stats.failure_reasons.size() > shown) {
    s += "; and " + std::to_string(stats.failure_reasons.size() - shown) + " more reasons";
  }
  return s;
}

Status CheckFailures(const StudyRunStats& stats, double allowed_fraction, const std::string& dir) {
  if (stats.failed_total <= allowed_fraction * stats.runs_in_shard) return Status::Ok();
  std::string allowed = "no failed run allowed";
  if (allowed_fraction > 0) {
    allowed = "allowed: " + FormatCompact(allowed_fraction) + " of the runs";
  }
  return Status::Error(DescribeFailures(stats) + " (" + allowed +
                       ", --allow-failures or the study's allow_failures; every reason in " +
                       JoinPath(dir, "summary.md") + ", section Failures)");
}

Status WriteStudyOutputs(const std::string& dir,
                         bool write_report,
                         double wall_s,
                         int jobs,
                         std::string* report_warning,
                         bool plots) {
  StatusOr<nlohmann::json> info = ReadStudyInfo(dir);
  if (!info.ok()) return info.status();
  int bad = 0, dup = 0;
  StatusOr<std::vector<RunRecord>> records =
      ReadRunLog(JoinPath(dir, "runs.jsonl"), &bad, &dup);
  if (!records.ok()) return records.status();
  const std::vector<GroupSummary> groups = Summarize(std::move(records).value());
  // Build everything first, then write: an error leaves no new file behind.
  const std::string csv = SummaryCsv(groups);
  ReportDoc doc = SummaryDoc(*info, groups);
  const std::string md = doc.Markdown();
  AddTimingSection(*info, groups, wall_s, jobs, &doc);
  const std::string timing = TimingCsv(groups);
  std::string html;
  if (write_report) {
    PlotOptions plot_options;
    plot_options.enabled = plots;
    const ReportFiles report = RenderReport(
        doc, "carmba study " + info->value("name", std::string("?")), StudyPlotData(groups),
        plot_options);
    html = report.html;
    if (report_warning) *report_warning = report.warning;
  }
  CARMBA_RETURN_IF_ERROR(WriteFileAtomic(JoinPath(dir, "summary.csv"), csv));
  CARMBA_RETURN_IF_ERROR(WriteFileAtomic(JoinPath(dir, "summary.md"), md));
  CARMBA_RETURN_IF_ERROR(WriteFileAtomic(JoinPath(dir, "timing.csv"), timing));
  if (write_report) {
    CARMBA_RETURN_IF_ERROR(WriteFileAtomic(JoinPath(dir, "report.html"), html));
  }
  return Status::Ok();
}

Status MergeStudyShards(const std::vector<std::string>& shard_dirs,
                        const std::string& out_dir,
                        bool write_report,
                        bool allow_missing,
                        int* runs_merged,
                        int* runs_missing,
                        std::string* report_warning,
                        bool plots) {
  if (shard_dirs.empty()) return Status::Error("no shard directories given");
  nlohmann::json info;
  std::map<std::string, RunRecord> by_key;
  auto strip_timing = [](const RunRecord& r) {
    nlohmann::json j = RunRecordToJson(r);
    j.erase("time_s");
    j.erase("cpu_s");
    return j;
  };
  for (const auto& dir : shard_dirs) {
    StatusOr<nlohmann::json> shard_info = ReadStudyInfo(dir);
    if (!shard_info.ok()) return shard_info.status();
    if (info.is_null()) {
      info = *shard_info;
    } else if (const std::string changed = DescribeStudyChange(info, *shard_info);
               !changed.empty()) {
      return Status::Error(JoinPath(dir, "study.json") + ": not the study of " + shard_dirs[0] +
                           ": " + changed + "; expected shards of one study");
    }
    int bad = 0, dup = 0;
    StatusOr<std::vector<RunRecord>> records =
        ReadRunLog(JoinPath(dir, "runs.jsonl"), &bad, &dup);
    if (!records.ok()) return records.status();
    for (auto& r : *records) {
      auto it = by_key.find(r.key);
      if (it == by_key.end()) {
        by_key.emplace(r.key, std::move(r));
      } else if (strip_timing(it->second) != strip_timing(r)) {
        return Status::Error(JoinPath(dir, "runs.jsonl") + ": run '" + r.key +
                             "' differs from the same run in another shard; expected one result "
                             "per run");
      }
    }
  }
  std::vector<RunRecord> records;
  for (auto& kv : by_key) records.push_back(std::move(kv.second));
  SortRecords(&records);
  const int total = info.value("runs_total", 0);
  if (runs_merged) *runs_merged = static_cast<int>(records.size());
  const int missing = std::max(0, total - static_cast<int>(records.size()));
  if (runs_missing) *runs_missing = missing;
  if (missing > 0 && !allow_missing) {
    return Status::Error(std::to_string(missing) + " of the " + std::to_string(total) +
                         " runs of study '" + info.value("name", std::string("?")) +
                         "' are in none of the " + std::to_string(shard_dirs.size()) +
                         " shard directories; expected all shards (or allow missing runs)");
  }

  CARMBA_RETURN_IF_ERROR(MakeDirs(out_dir));
  const std::string log_path = JoinPath(out_dir, "runs.jsonl");
  int bad = 0, dup = 0;
  StatusOr<std::vector<RunRecord>> existing = ReadRunLog(log_path, &bad, &dup);
  if (!existing.ok()) return existing.status();
  if (!existing->empty()) {
    return Status::Error(log_path + ": already holds runs; expected an empty or new directory");
  }
  info["shard"] = "merged from " + std::to_string(shard_dirs.size()) + " directories";
  CARMBA_RETURN_IF_ERROR(RewriteRunLog(log_path, records));
  CARMBA_RETURN_IF_ERROR(WriteFileAtomic(JoinPath(out_dir, "study.json"), info.dump(2) + "\n"));
  return WriteStudyOutputs(out_dir, write_report, 0, 0, report_warning, plots);
}

}  // namespace carmba
