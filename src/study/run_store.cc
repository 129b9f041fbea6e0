#include "study/run_store.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <sstream>

#include "util/file_util.h"

namespace carmba {

nlohmann::json RunRecordToJson(const RunRecord& r) {
  nlohmann::json j;
  j["index"] = r.index;
  j["key"] = r.key;
  j["problem"] = r.problem;
  j["config"] = r.config;
  nlohmann::json sweep = nlohmann::json::array();  // [[name, value], ...] keeps the sweep order
  for (const auto& kv : r.sweep) sweep.push_back({kv.first, kv.second});
  j["sweep"] = sweep;
  j["trial"] = r.trial;
  j["seed"] = r.seed;
  j["ok"] = r.ok;
  if (r.ok) {
    j["result"] = r.result;
  } else {
    j["error"] = r.error;
  }
  j["time_s"] = r.time_s;
  j["cpu_s"] = r.cpu_s;
  return j;
}

StatusOr<RunRecord> RunRecordFromJson(const nlohmann::json& j) {
  if (!j.is_object()) return Status::Error("expected a JSON object");
  RunRecord r;
  try {
    r.index = j.at("index").get<int>();
    r.key = j.at("key").get<std::string>();
    r.problem = j.at("problem").get<std::string>();
    r.config = j.at("config").get<std::string>();
    for (const auto& kv : j.at("sweep")) {
      r.sweep.emplace_back(kv.at(0).get<std::string>(), kv.at(1).get<double>());
    }
    r.trial = j.at("trial").get<int>();
    r.seed = j.at("seed").get<uint64_t>();
    r.ok = j.at("ok").get<bool>();
    if (r.ok) {
      r.result = j.at("result");
    } else {
      r.error = j.at("error").get<std::string>();
    }
    r.time_s = j.at("time_s").get<double>();
    r.cpu_s = j.at("cpu_s").get<double>();
  } catch (const nlohmann::json::exception& e) {
    return Status::Error(std::string("malformed run record: ") + e.what());
  }
  return r;
}

std::vector<RunRecord> ParseRunLog(const std::string& text, int* bad_lines, int* duplicates) {
  std::vector<RunRecord> records;
  std::set<std::string> seen;
  int bad = 0, dup = 0;
  size_t pos = 0;
  while (pos < text.size()) {
    size_t end = text.find('\n', pos);
    const bool complete = end != std::string::npos;
    if (!complete) end = text.size();
    const std::string line = text.substr(pos, end - pos);
    pos = end + 1;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    if (!complete) {  // no newline: the write was cut short
      ++bad;
      continue;
    }
    nlohmann::json j = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
    if (j.is_discarded()) {
      ++bad;
      continue;
    }
    StatusOr<RunRecord> r = RunRecordFromJson(j);
    if (!r.ok()) {
      ++bad;
      continue;
    }
    if (!seen.insert(r->key).second) {
      ++dup;
      continue;
    }
    records.push_back(std::move(r).value());
  }
  if (bad_lines) *bad_lines = bad;
  if (duplicates) *duplicates = dup;
  return records;
}

StatusOr<std::vector<RunRecord>> ReadRunLog(const std::string& path,
                                            int* bad_lines,
                                            int* duplicates) {
  if (!FileExists(path)) {
    if (bad_lines) *bad_lines = 0;
    if (duplicates) *duplicates = 0;
    return std::vector<RunRecord>();
  }
  StatusOr<std::string> text = ReadFile(path);
  if (!text.ok()) return text.status();
  return ParseRunLog(*text, bad_lines, duplicates);
}

RunLogWriter::~RunLogWriter() { Close(); }

Status RunLogWriter::Open(const std::string& path) {
  Close();
  fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd_ < 0) {
    return Status::Error(path + ": cannot open for appending (" + std::strerror(errno) + ")");
  }
  path_ = path;
  return Status::Ok();
}

Status RunLogWriter::Append(const RunRecord& record) {
  const std::string line = RunRecordToJson(record).dump() + "\n";
  std::lock_guard<std::mutex> lock(mutex_);
  if (fd_ < 0) return Status::Error(path_ + ": run log is not open");
  size_t done = 0;
  while (done < line.size()) {
    const ssize_t w = ::write(fd_, line.data() + done, line.size() - done);
    if (w < 0) {
      if (errno == EINTR) continue;
      return Status::Error(path_ + ": write failed (" + std::strerror(errno) + ")");
    }
    done += static_cast<size_t>(w);
  }
  return Status::Ok();
}

void RunLogWriter::Close() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

void SortRecords(std::vector<RunRecord>* records) {
  std::sort(records->begin(), records->end(), [](const RunRecord& a, const RunRecord& b) {
    return a.index != b.index ? a.index < b.index : a.key < b.key;
  });
}

nlohmann::json StudyInfoJson(const StudySpec& spec,
                             const std::vector<RunSpec>& all_runs,
                             const std::vector<StudyInput>& inputs,
                             int shard_k,
                             int shard_n) {
  nlohmann::json j = StudyIdentityJson(spec, all_runs, inputs);
  j["name"] = spec.name;
  j["study_file"] = spec.path;
  j["runs_total"] = all_runs.size();
  j["trials"] = spec.trials;
  j["base_seed"] = spec.base_seed;
  j["shard"] = std::to_string(shard_k) + "/" + std::to_string(shard_n);
  nlohmann::json sweeps = nlohmann::json::array();
  for (const auto& s : spec.sweeps) sweeps.push_back({{"name", s.name}, {"values", s.values}});
  j["sweeps"] = sweeps;
  nlohmann::json problems = nlohmann::json::array(), configs = nlohmann::json::array();
  for (const auto& p : spec.problems) problems.push_back(p.name);
  for (const auto& c : spec.configs) configs.push_back(c.name);
  j["problems"] = problems;
  j["configs"] = configs;
  return j;
}

}  // namespace carmba
