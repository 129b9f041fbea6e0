#include "study/study_spec.h"

#include <cmath>
#include <cstdio>
#include <map>
#include <set>

#include "util/csv.h"
#include "util/file_util.h"
#include "util/plausible.h"
#include "util/yaml_reader.h"

namespace carmba {
namespace {

// YAML -> JSON: numbers become numbers, true/false booleans, the rest strings.
nlohmann::json YamlToJson(const YAML::Node& n) {
  if (!n || n.IsNull()) return nullptr;
  if (n.IsSequence()) {
    nlohmann::json a = nlohmann::json::array();
    for (const auto& e : n) a.push_back(YamlToJson(e));
    return a;
  }
  if (n.IsMap()) {
    nlohmann::json o = nlohmann::json::object();
    for (const auto& kv : n) o[kv.first.Scalar()] = YamlToJson(kv.second);
    return o;
  }
  const std::string& s = n.Scalar();
  if (n.Tag() != "!") {  // unquoted scalar
    if (s == "true") return true;
    if (s == "false") return false;
    char* end = nullptr;
    const long long i = std::strtoll(s.c_str(), &end, 10);
    if (!s.empty() && end && *end == '\0') return i;
    double d;
    if (ParseFiniteDouble(s, &d)) return d;
  }
  return s;
}

bool ValidName(const std::string& s) {
  return !s.empty() && s.find_first_of("|=,\n\r\t") == std::string::npos;
}

std::string BaseNameNoExt(const std::string& path) {
  std::string b = path.substr(path.find_last_of('/') == std::string::npos
                                  ? 0
                                  : path.find_last_of('/') + 1);
  const auto dot = b.find_last_of('.');
  return dot == std::string::npos ? b : b.substr(0, dot);
}

std::string FormatKeyNumber(double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.12g", v);
  return buf;
}

uint64_t SplitMix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

}  // namespace

bool StudySpec::Check(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = path + ": " + m;
    return false;
  };
  if (trials < 1) return fail("key 'trials': expected an integer >= 1");
  if (!InRange(allow_failures, kFailureFraction)) {
    return fail("key 'allow_failures': expected a fraction " +
                FormatRange(kFailureFraction) + ", got " + FormatCompact(allow_failures));
  }
  if (problems.empty()) return fail("key 'problems': expected at least one problem");
  if (configs.empty()) return fail("key 'configs': expected at least one config");
  std::set<std::string> names;
  for (const auto& p : problems) {
    if (!ValidName(p.name)) {
      return fail("problem name '" + p.name + "': expected a non-empty name without | = ,");
    }
    if (!names.insert(p.name).second) return fail("problem name '" + p.name + "' is repeated");
    if (p.file.empty() == p.synthetic.is_null()) {
      return fail("problem '" + p.name + "': expected exactly one of 'file' and 'synthetic'");
    }
  }
  names.clear();
  for (const auto& c : configs) {
    if (!ValidName(c.name)) {
      return fail("config name '" + c.name + "': expected a non-empty name without | = ,");
    }
    if (!names.insert(c.name).second) return fail("config name '" + c.name + "' is repeated");
    if (c.file.empty()) return fail("config '" + c.name + "': key 'file' is missing");
  }
  names.clear();
  for (const auto& s : sweeps) {
    if (!ValidName(s.name)) return fail("sweep '" + s.name + "': invalid name");
    if (!names.insert(s.name).second) return fail("sweep '" + s.name + "' is repeated");
    if (s.values.empty()) return fail("sweep '" + s.name + "': expected a non-empty list");
    for (double v : s.values) {
      if (!std::isfinite(v)) return fail("sweep '" + s.name + "': expected finite numbers");
    }
  }
  return true;
}

double RunSpec::SweepValue(const std::string& name, double fallback) const {
  for (const auto& kv : sweep) {
    if (kv.first == name) return kv.second;
  }
  return fallback;
}

StatusOr<StudySpec> LoadStudySpec(const std::string& path) {
  YamlMap m = YamlMap::Load(path);
  CARMBA_RETURN_IF_ERROR(m.status());
  StudySpec spec;
  spec.path = path;
  spec.name = BaseNameNoExt(path);
  // Optional keys are read with Get (absent: left untouched), never behind Has(): Has() does not
  // make a key known, so a misspelt key's message would leave it out of the known keys.
  m.Get("name", &spec.name);
  m.Get("trials", &spec.trials, /*required=*/true);
  int base_seed = 0;
  m.Get("base_seed", &base_seed);
  if (base_seed < 0) m.Fail("base_seed", "expected a non-negative integer");
  spec.base_seed = static_cast<uint64_t>(base_seed);
  m.GetInRange("allow_failures", &spec.allow_failures, kFailureFraction);
  const std::string dir = DirName(path);
  for (YamlMap* p : m.MapList("problems", /*required=*/true)) {
    StudyProblem problem;
    p->Get("name", &problem.name, /*required=*/true);
    std::string file;
    p->Get("file", &file);
    if (!file.empty()) problem.file = JoinPath(dir, file);
    if (const YAML::Node synthetic = p->Raw("synthetic"); synthetic && !synthetic.IsNull()) {
      problem.synthetic = YamlToJson(synthetic);
      if (!problem.synthetic.is_object()) p->Fail("synthetic", "expected a mapping");
    }
    if (const YAML::Node options = p->Raw("options"); options && !options.IsNull()) {
      problem.options = YamlToJson(options);
      if (!problem.options.is_object()) p->Fail("options", "expected a mapping");
    }
    problem.base_dir = dir;
    const bool has_trials = p->Has("trials");
    p->Get("trials", &problem.trials);
    if (has_trials && p->status().ok() && problem.trials < 1) {
      p->Fail("trials", "expected an integer >= 1");
    }
    spec.problems.push_back(std::move(problem));
  }
  for (YamlMap* c : m.MapList("configs", /*required=*/true)) {
    StudyConfig config;
    c->Get("name", &config.name, /*required=*/true);
    std::string file;
    c->Get("file", &file, /*required=*/true);
    if (!file.empty()) config.file = JoinPath(dir, file);
    if (const YAML::Node options = c->Raw("options"); options && !options.IsNull()) {
      config.options = YamlToJson(options);
      if (!config.options.is_object()) c->Fail("options", "expected a mapping");
    }
    spec.configs.push_back(std::move(config));
  }
  if (const YAML::Node sweeps = m.Raw("sweeps"); sweeps && !sweeps.IsNull()) {
    if (!sweeps.IsMap()) {
      m.Fail("sweeps", "expected a mapping of variable names to lists of numbers");
    } else {
      YamlMap& sm = m.Map("sweeps");
      sm.SetUserNamedKeys("<variable>");
      for (const auto& kv : sweeps) {
        StudySweep s;
        s.name = kv.first.Scalar();
        sm.Get(s.name, &s.values, /*required=*/true);
        if (sm.status().ok() && s.values.empty()) sm.Fail(s.name, "expected a non-empty list");
        // The variables the pose and calibration studies know (study/pose_study.h), each within
        // its plausible range; a noise of 0 (noise-free views) is allowed.
        static const std::map<std::string, PlausibleRange> kSweepRanges = {
            {"pixel_noise_px", plausible::kPixelSigmaPx},
            {"ct_noise_mm", plausible::kCtSigmaMm},
            {"num_views", plausible::kViews},
            {"k1", plausible::kDistortion}};
        const auto range = kSweepRanges.find(s.name);
        for (size_t i = 0; sm.status().ok() && range != kSweepRanges.end() && i < s.values.size();
             ++i) {
          const double v = s.values[i];
          const bool noise = s.name.find("noise") != std::string::npos;
          if (!(noise && v == 0) && !InRange(v, range->second)) {
            sm.Fail(s.name, "element " + std::to_string(i) + ": expected " +
                                (noise ? std::string("0 or ") : std::string()) +
                                FormatRange(range->second) + ", got " + FormatCompact(v));
          }
        }
        spec.sweeps.push_back(std::move(s));
      }
    }
  }
  CARMBA_RETURN_IF_ERROR(m.Finish());
  std::string error;
  if (!spec.Check(&error)) return Status::Error(error);
  return spec;
}

std::vector<SweepPoint> SweepPoints(const StudySpec& spec) {
  std::vector<SweepPoint> points(1);
  for (const auto& s : spec.sweeps) {
    std::vector<SweepPoint> next;
    for (const auto& p : points) {
      for (double v : s.values) {
        SweepPoint q = p;
        q.emplace_back(s.name, v);
        next.push_back(std::move(q));
      }
    }
    points = std::move(next);
  }
  return points;
}

std::string SweepPointLabel(const SweepPoint& point) {
  if (point.empty()) return "-";
  std::string s;
  for (const auto& kv : point) {
    if (!s.empty()) s += ",";
    s += kv.first + "=" + FormatKeyNumber(kv.second);
  }
  return s;
}

uint64_t Fnv1a64(const std::string& s) {
  uint64_t h = 0xcbf29ce484222325ULL;
  for (unsigned char c : s) {
    h ^= c;
    h *= 0x100000001b3ULL;
  }
  return h;
}

uint64_t DeriveSeed(uint64_t base_seed, const std::string& data_key) {
  return SplitMix64(SplitMix64(base_seed) ^ Fnv1a64(data_key));
}

std::vector<RunSpec> EnumerateRuns(const StudySpec& spec) {
  const std::vector<SweepPoint> points = SweepPoints(spec);
  std::vector<RunSpec> runs;
  runs.reserve(spec.problems.size() * spec.configs.size() * points.size() *
               static_cast<size_t>(spec.trials));
  for (size_t p = 0; p < spec.problems.size(); ++p) {
    for (size_t c = 0; c < spec.configs.size(); ++c) {
      for (size_t s = 0; s < points.size(); ++s) {
        const std::string label = SweepPointLabel(points[s]);
        const int trials = spec.problems[p].trials > 0 ? spec.problems[p].trials : spec.trials;
        for (int t = 0; t < trials; ++t) {
          RunSpec r;
          r.index = static_cast<int>(runs.size());
          r.problem_index = static_cast<int>(p);
          r.config_index = static_cast<int>(c);
          r.sweep_index = static_cast<int>(s);
          r.problem = &spec.problems[p];
          r.config = &spec.configs[c];
          r.sweep = points[s];
          r.trial = t;
          const std::string trial = "trial=" + std::to_string(t);
          r.key = spec.problems[p].name + "|" + spec.configs[c].name + "|" + label + "|" + trial;
          r.seed = DeriveSeed(spec.base_seed, spec.problems[p].name + "|" + label + "|" + trial);
          runs.push_back(std::move(r));
        }
      }
    }
  }
  return runs;
}

std::vector<RunSpec> ShardRuns(const std::vector<RunSpec>& runs, int k, int n) {
  std::vector<RunSpec> out;
  for (const auto& r : runs) {
    if (r.index % n == k - 1) out.push_back(r);
  }
  return out;
}

Status ParseShard(const std::string& text, int* k, int* n) {
  int kk = 0, nn = 0;
  char extra = 0;
  if (std::sscanf(text.c_str(), "%d/%d%c", &kk, &nn, &extra) != 2 || nn < 1 || kk < 1 ||
      kk > nn) {
    return Status::Error("--shard '" + text + "': expected K/N with 1 <= K <= N, e.g. 2/8");
  }
  *k = kk;
  *n = nn;
  return Status::Ok();
}

}  // namespace carmba
