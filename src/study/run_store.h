// The record of finished runs: DIR/runs.jsonl, one JSON object per line, appended as each run
// finishes (so a killed study loses at most the runs in flight), and DIR/study.json, which names
// the study and fingerprints its run list.
//
// A runs.jsonl line:
//   {"index":12,"key":"p|c|pixel_noise_px=0.3|trial=2","problem":"p","config":"c",
//    "sweep":{"pixel_noise_px":0.3},"trial":2,"seed":1234,"ok":true,"result":{...},
//    "time_s":0.0123,"cpu_s":0.0121}
// and for a failed run "ok":false,"error":"<one-line reason>" instead of "result".
//
// `result` is what the run function returned. The summary (study/summary.h) understands these
// optional members of it:
//   "errors":        {name: magnitude >= 0 against the truth}   e.g. rotation_deg, translation_mm,
//                                                                tre_mm, fx_px
//   "signed_errors": {name: estimate - truth}                   per scalar parameter
//   "sigmas":        {name: reported 1-sigma}                   same names as signed_errors
//   "values":        {name: number}                             e.g. rms_px, iterations
//   "converged":     bool
//   "residuals_px":  [numbers]                                  whitened or pixel residuals
//   "budget":        {source: contribution}                     predicted error budget
#pragma once

#include <cstdint>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "study/study_inputs.h"
#include "study/study_spec.h"
#include "util/status.h"

namespace carmba {

struct RunRecord {
  int index = 0;
  std::string key;
  std::string problem;
  std::string config;
  SweepPoint sweep;
  int trial = 0;
  uint64_t seed = 0;
  bool ok = false;
  std::string error;        // when !ok
  nlohmann::json result;    // when ok
  double time_s = 0;        // wall time of the run function
  double cpu_s = 0;         // thread CPU time of the run function
};

nlohmann::json RunRecordToJson(const RunRecord& r);
// Error when a member is missing or has the wrong type.
StatusOr<RunRecord> RunRecordFromJson(const nlohmann::json& j);

// The records of a runs.jsonl text. A line that does not parse as a complete record (the last
// line of a killed study) is skipped and counted in *bad_lines; a key seen twice keeps its first
// record and counts in *duplicates.
std::vector<RunRecord> ParseRunLog(const std::string& text, int* bad_lines, int* duplicates);

// Reads DIR/runs.jsonl (missing file -> no records).
StatusOr<std::vector<RunRecord>> ReadRunLog(const std::string& path,
                                            int* bad_lines,
                                            int* duplicates);

// Appends one line per record to a file opened with O_APPEND, each with a single write(2) under
// a mutex, so lines of concurrent runs never interleave and a finished run is in the kernel
// before the next starts.
class RunLogWriter {
 public:
  ~RunLogWriter();
  Status Open(const std::string& path);
  Status Append(const RunRecord& record);
  void Close();

 private:
  std::mutex mutex_;
  int fd_ = -1;
  std::string path_;
};

// Sorts by enumeration index (then key).
void SortRecords(std::vector<RunRecord>* records);

// DIR/study.json: {"name", "study_file", "runs_total", "shard": "K/N", "sweeps": [names],
//                  "problems": [names], "configs": [names]} and the study's identity
//                  (study/study_inputs.h): "fingerprint", "carmba_version", "runs_hash",
//                  "entries_hash", "inputs": [{"path", "hash", "used_by"}].
nlohmann::json StudyInfoJson(const StudySpec& spec,
                             const std::vector<RunSpec>& all_runs,
                             const std::vector<StudyInput>& inputs,
                             int shard_k,
                             int shard_n);

}  // namespace carmba
