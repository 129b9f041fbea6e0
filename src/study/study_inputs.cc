#include "study/study_inputs.h"

#include <yaml-cpp/yaml.h>

#include <cinttypes>
#include <cstdio>
#include <fstream>
#include <map>

#include "util/file_util.h"
#include "util/version.h"

namespace carmba {
namespace {

constexpr int kMaxYamlDepth = 4;

std::string Hex64(uint64_t h) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%016" PRIx64, h);
  return buf;
}

bool IsYaml(const std::string& path) {
  const auto dot = path.find_last_of('.');
  if (dot == std::string::npos) return false;
  const std::string ext = path.substr(dot);
  return ext == ".yaml" || ext == ".yml";
}

bool HasGlobChars(const std::string& s) { return s.find_first_of("*?[") != std::string::npos; }

// Collects input files by path; the first entry naming a file is its `used_by`.
class InputCollector {
 public:
  explicit InputCollector(bool hash = true) : hash_(hash) {}

  // `text` as written in an entry or a YAML file under `base_dir`: the files it names on disk.
  void AddNamed(const std::string& base_dir, const std::string& text, const std::string& used_by,
                int depth) {
    if (text.empty() || text.size() > 4096 || text.find('\n') != std::string::npos) return;
    if (text == "." || text == ".." || text == "/") return;  // never a data directory
    const std::string path = JoinPath(base_dir, text);
    if (!HasGlobChars(text) && !FileExists(path)) return;
    if (!HasGlobChars(text) && !IsDirectory(path)) {
      AddFile(path, used_by, depth);
      return;
    }
    StatusOr<std::vector<std::string>> files = ListFiles(path);
    if (!files.ok()) return;
    for (const auto& f : *files) AddFile(f, used_by, depth);
  }

  // A file an entry reads for certain (missing or not).
  void AddFile(const std::string& path, const std::string& used_by, int depth) {
    if (inputs_.count(path)) return;
    inputs_[path] = StudyInput{path, hash_ ? FileContentHash(path) : "", used_by};
    if (IsYaml(path) && depth < kMaxYamlDepth) ScanYaml(path, used_by, depth + 1);
  }

  // Every string inside a JSON value (a `synthetic` or `options` mapping).
  void AddStrings(const std::string& base_dir, const nlohmann::json& j,
                  const std::string& used_by) {
    if (j.is_string()) {
      AddNamed(base_dir, j.get<std::string>(), used_by, 0);
    } else if (j.is_array() || j.is_object()) {
      for (const auto& e : j) AddStrings(base_dir, e, used_by);
    }
  }

  std::vector<StudyInput> Sorted() const {
    std::vector<StudyInput> out;
    for (const auto& kv : inputs_) out.push_back(kv.second);
    return out;
  }

 private:
  void ScanYaml(const std::string& path, const std::string& used_by, int depth) {
    YAML::Node root;
    try {
      root = YAML::LoadFile(path);
    } catch (const std::exception&) {
      return;  // hashed as it is; its runs report the error
    }
    ScanNode(DirName(path), root, used_by, depth);
  }

  void ScanNode(const std::string& dir, const YAML::Node& n, const std::string& used_by,
                int depth) {
    if (!n) return;
    if (n.IsScalar()) {
      AddNamed(dir, n.Scalar(), used_by, depth);
    } else if (n.IsSequence()) {
      for (const auto& e : n) ScanNode(dir, e, used_by, depth);
    } else if (n.IsMap()) {
      for (const auto& kv : n) ScanNode(dir, kv.second, used_by, depth);
    }
  }

  bool hash_;
  std::map<std::string, StudyInput> inputs_;
};

// The study's entries as they determine what runs do (names, resolved paths, mappings).
nlohmann::json EntriesJson(const StudySpec& spec) {
  nlohmann::json problems = nlohmann::json::array(), configs = nlohmann::json::array();
  for (const auto& p : spec.problems) {
    problems.push_back({{"name", p.name}, {"file", p.file}, {"synthetic", p.synthetic},
                        {"options", p.options}, {"base_dir", p.base_dir}, {"trials", p.trials}});
  }
  for (const auto& c : spec.configs) {
    configs.push_back({{"name", c.name}, {"file", c.file}, {"options", c.options}});
  }
  return {{"problems", problems}, {"configs", configs}};
}

std::string RunListHash(const std::vector<RunSpec>& runs) {
  std::string all;
  for (const auto& r : runs) all += r.key + "#" + std::to_string(r.seed) + "\n";
  return Hex64(Fnv1a64(all));
}

std::string Str(const nlohmann::json& j, const char* key) {
  return j.contains(key) && j[key].is_string() ? j[key].get<std::string>() : std::string();
}

std::map<std::string, nlohmann::json> InputsByPath(const nlohmann::json& info) {
  std::map<std::string, nlohmann::json> out;
  if (!info.contains("inputs") || !info["inputs"].is_array()) return out;
  for (const auto& i : info["inputs"]) {
    if (i.is_object()) out[Str(i, "path")] = i;
  }
  return out;
}

}  // namespace

std::string FileContentHash(const std::string& path) {
  if (IsDirectory(path)) return "missing";
  std::ifstream in(path, std::ios::binary);
  if (!in) return "missing";
  uint64_t h = 0xcbf29ce484222325ULL;
  char buf[1 << 16];
  while (in) {
    in.read(buf, sizeof(buf));
    const std::streamsize n = in.gcount();
    for (std::streamsize i = 0; i < n; ++i) {
      h ^= static_cast<unsigned char>(buf[i]);
      h *= 0x100000001b3ULL;
    }
  }
  return Hex64(h);
}

std::vector<std::string> FilesNamedInYaml(const std::string& yaml_path) {
  InputCollector c(/*hash=*/false);
  c.AddFile(yaml_path, "", 0);
  std::vector<std::string> files;
  for (const StudyInput& in : c.Sorted()) {
    if (in.path != yaml_path) files.push_back(in.path);
  }
  return files;
}

std::vector<StudyInput> StudyInputFiles(const StudySpec& spec) {
  InputCollector c;
  for (const auto& p : spec.problems) {
    const std::string used_by = "problem '" + p.name + "'";
    if (!p.file.empty()) c.AddFile(p.file, used_by, 0);
    c.AddStrings(p.base_dir, p.synthetic, used_by);
    c.AddStrings(p.base_dir, p.options, used_by);
  }
  const std::string study_dir = DirName(spec.path);
  for (const auto& cfg : spec.configs) {
    const std::string used_by = "config '" + cfg.name + "'";
    if (!cfg.file.empty()) c.AddFile(cfg.file, used_by, 0);
    c.AddStrings(study_dir, cfg.options, used_by);
  }
  return c.Sorted();
}

nlohmann::json StudyIdentityJson(const StudySpec& spec,
                                 const std::vector<RunSpec>& all_runs,
                                 const std::vector<StudyInput>& inputs) {
  nlohmann::json j;
  j["carmba_version"] = kCarmbaVersion;
  j["runs_hash"] = RunListHash(all_runs);
  j["entries_hash"] = Hex64(Fnv1a64(EntriesJson(spec).dump()));
  nlohmann::json list = nlohmann::json::array();
  std::string all = j["carmba_version"].get<std::string>() + "\n" +
                    j["runs_hash"].get<std::string>() + "\n" +
                    j["entries_hash"].get<std::string>() + "\n";
  for (const auto& in : inputs) {
    list.push_back({{"path", in.path}, {"hash", in.hash}, {"used_by", in.used_by}});
    all += in.path + "\t" + in.hash + "\n";
  }
  j["inputs"] = list;
  j["fingerprint"] = Hex64(Fnv1a64(all)) + "-" + std::to_string(all_runs.size());
  return j;
}

std::string DescribeStudyChange(const nlohmann::json& was, const nlohmann::json& now) {
  if (Str(was, "fingerprint") == Str(now, "fingerprint")) return "";
  const auto old_inputs = InputsByPath(was), new_inputs = InputsByPath(now);
  for (const auto& [path, in] : new_inputs) {
    const auto it = old_inputs.find(path);
    if (it == old_inputs.end()) {
      return path + " (" + Str(in, "used_by") + ") is read now but was not before";
    }
    if (Str(it->second, "hash") != Str(in, "hash")) {
      return path + " (" + Str(in, "used_by") + ") has different content";
    }
  }
  for (const auto& [path, in] : old_inputs) {
    if (!new_inputs.count(path)) {
      return path + " (" + Str(in, "used_by") + ") was read before but is not now";
    }
  }
  if (Str(was, "carmba_version") != Str(now, "carmba_version")) {
    return "carmba version " + Str(was, "carmba_version") + " differs from " +
           Str(now, "carmba_version");
  }
  if (Str(was, "entries_hash") != Str(now, "entries_hash")) {
    return "the study file's problem or config entries differ (paths, synthetic or options)";
  }
  if (Str(was, "runs_hash") != Str(now, "runs_hash")) {
    return "the run list differs (names, sweeps, trials or base_seed)";
  }
  return "fingerprint " + Str(was, "fingerprint") + " differs from " + Str(now, "fingerprint");
}

}  // namespace carmba
