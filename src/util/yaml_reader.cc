#include "util/yaml_reader.h"

#include <cmath>
#include <regex>
#include <set>

#include "util/accepted_keys.h"

#include "util/csv.h"
#include "util/file_util.h"
#include "util/text_match.h"

namespace carmba {

YamlMap::YamlMap(const YAML::Node& node, std::string file, std::string prefix)
    : node_(node), file_(std::move(file)), prefix_(std::move(prefix)) {
  if (node_ && !node_.IsNull() && !node_.IsMap()) {
    status_ = Status::Error(file_ + ":" + std::to_string(node_.Mark().line + 1) + ": " +
                            (prefix_.empty() ? std::string("top level")
                                             : "key '" + prefix_ + "'") +
                            ": expected a mapping of keys to values");
    return;
  }
  // yaml-cpp keeps both entries of a repeated key and node[key] returns the first: a repeated key
  // would silently lose the later value.
  if (node_ && node_.IsMap()) {
    std::set<std::string> keys;
    for (const auto& kv : node_) {
      if (!kv.first.IsScalar()) continue;
      if (!keys.insert(kv.first.Scalar()).second) {
        status_ = Status::Error(file_ + ":" + std::to_string(kv.first.Mark().line + 1) +
                                ": key '" + KeyPath(kv.first.Scalar()) +
                                "' appears twice, expected each key once");
        return;
      }
    }
  }
}

YamlMap YamlMap::Load(const std::string& path) {
  YAML::Node root;
  std::string error;
  if (IsDirectory(path)) {
    error = path + ": is a directory, expected a YAML file";
  } else {
    try {
      root = YAML::LoadFile(path);
    } catch (const YAML::BadFile&) {
      error = path + ": cannot open file";
    } catch (const YAML::Exception& e) {
      error = path + ":" + std::to_string(e.mark.line + 1) + ": YAML syntax error: " + e.msg;
    } catch (const std::exception& e) {  // e.g. std::ios_base::failure from the stream
      error = path + ": cannot read file (" + e.what() + ")";
    }
  }
  YamlMap m(root, path);
  if (!error.empty()) {
    m.status_ = Status::Error(error);
  } else if (!root || root.IsNull()) {
    m.status_ = Status::Error(path + ": empty file, expected a YAML mapping");
  }
  return m;
}

std::string YamlMap::KeyPath(const std::string& key) const {
  return prefix_.empty() ? key : prefix_ + "." + key;
}

std::string YamlMap::Where(const std::string& key) const {
  int line = -1;
  if (node_ && node_.IsMap() && node_[key]) line = node_[key].Mark().line + 1;
  if (line < 0 && node_) line = node_.Mark().line + 1;
  std::string w = file_;
  if (line > 0) w += ":" + std::to_string(line);
  return w + ": key '" + KeyPath(key) + "'";
}

void YamlMap::Fail(const std::string& key, const std::string& what) {
  if (status_.ok()) status_ = Status::Error(Where(key) + ": " + what);
}

bool YamlMap::Has(const std::string& key) const {
  return node_ && node_.IsMap() && node_[key] && !node_[key].IsNull();
}

std::optional<YAML::Node> YamlMap::Node(const std::string& key,
                                        bool required,
                                        const char* expected) {
  known_.insert(key);
  if (!Has(key)) {
    if (required && status_.ok()) {
      Fail(key, std::string("missing, expected ") + expected);
      missing_ = true;
      NoteMisspellingsOf(key);
    }
    return std::nullopt;
  }
  return node_[key];
}

void YamlMap::NoteMisspellingsOf(const std::string& missing) {
  if (!node_ || !node_.IsMap()) return;
  for (const auto& kv : node_) {
    if (!kv.first.IsScalar() || known_.count(kv.first.Scalar())) continue;
    const std::string k = kv.first.Scalar();
    if (ClosestMatch(k, {missing}).empty()) continue;
    misspelt_.push_back(Status::Error(file_ + ":" + std::to_string(kv.first.Mark().line + 1) +
                                      ": unknown key '" + KeyPath(k) + "'; did you mean '" +
                                      missing + "'? (a required key)"));
    misspelt_keys_.push_back(k);
  }
}

Status YamlMap::status() const {
  // A parser stopping at a missing key: a key it never asked for that resembles the missing one
  // is the likely cause (a key asked for after all, e.g. fy after fx, is not).
  for (size_t i = 0; missing_ && i < misspelt_.size(); ++i) {
    if (!known_.count(misspelt_keys_[i])) return misspelt_[i];
  }
  return status_;
}

namespace {
std::string Show(const YAML::Node& n) {
  if (n.IsScalar()) return "'" + n.Scalar() + "'";
  if (n.IsSequence()) return "a list";
  if (n.IsMap()) return "a mapping";
  return "nothing";
}
}  // namespace

void YamlMap::Get(const std::string& key, double* out, bool required) {
  const auto on = Node(key, required, "a number");
  if (!on) return;
  const YAML::Node& n = *on;
  double v;
  if (!n.IsScalar() || !ParseFiniteDouble(n.Scalar(), &v)) {
    Fail(key, "expected a finite number, got " + Show(n));
    return;
  }
  *out = v;
}

void YamlMap::Get(const std::string& key, int* out, bool required) {
  const auto on = Node(key, required, "an integer");
  if (!on) return;
  const YAML::Node& n = *on;
  double v;
  if (!n.IsScalar() || !ParseFiniteDouble(n.Scalar(), &v) || v != std::floor(v) ||
      std::fabs(v) > 2e9) {
    Fail(key, "expected an integer, got " + Show(n));
    return;
  }
  *out = static_cast<int>(v);
}

void YamlMap::Get(const std::string& key, bool* out, bool required) {
  const auto on = Node(key, required, "true or false");
  if (!on) return;
  const YAML::Node& n = *on;
  if (n.IsScalar()) {
    const std::string& s = n.Scalar();
    if (s == "true" || s == "True" || s == "yes") {
      *out = true;
      return;
    }
    if (s == "false" || s == "False" || s == "no") {
      *out = false;
      return;
    }
  }
  Fail(key, "expected true or false, got " + Show(n));
}

void YamlMap::Get(const std::string& key, std::string* out, bool required) {
  const auto on = Node(key, required, "a string");
  if (!on) return;
  const YAML::Node& n = *on;
  if (!n.IsScalar()) {
    Fail(key, "expected a string, got " + Show(n));
    return;
  }
  *out = n.Scalar();
}

void YamlMap::Get(const std::string& key, std::vector<double>* out, bool required) {
  const auto on = Node(key, required, "a list of numbers");
  if (!on) return;
  const YAML::Node& n = *on;
  if (!n.IsSequence()) {
    Fail(key, "expected a list of numbers, got " + Show(n));
    return;
  }
  std::vector<double> v;
  for (size_t i = 0; i < n.size(); ++i) {
    double x;
    if (!n[i].IsScalar() || !ParseFiniteDouble(n[i].Scalar(), &x)) {
      Fail(key, "element " + std::to_string(i) + ": expected a finite number, got " + Show(n[i]));
      return;
    }
    v.push_back(x);
  }
  *out = v;
}

void YamlMap::Get(const std::string& key, std::vector<int>* out, bool required) {
  std::vector<double> v;
  const bool had = Has(key);
  Get(key, &v, required);
  if (!had || !status_.ok()) return;
  std::vector<int> r;
  for (size_t i = 0; i < v.size(); ++i) {
    // Beyond an int the conversion is undefined (found by fuzz_xray_scene under UBSan).
    if (v[i] != std::floor(v[i]) || std::fabs(v[i]) > 2e9) {
      Fail(key, "element " + std::to_string(i) + ": expected an integer within +-2e9");
      return;
    }
    r.push_back(static_cast<int>(v[i]));
  }
  *out = r;
}

void YamlMap::Get(const std::string& key, std::vector<std::string>* out, bool required) {
  const auto on = Node(key, required, "a list of strings");
  if (!on) return;
  const YAML::Node& n = *on;
  std::vector<std::string> v;
  if (n.IsScalar()) {
    v.push_back(n.Scalar());
  } else if (n.IsSequence()) {
    for (size_t i = 0; i < n.size(); ++i) {
      if (!n[i].IsScalar()) {
        Fail(key, "element " + std::to_string(i) + ": expected a string, got " + Show(n[i]));
        return;
      }
      v.push_back(n[i].Scalar());
    }
  } else {
    Fail(key, "expected a list of strings, got " + Show(n));
    return;
  }
  *out = v;
}

void YamlMap::GetEnum(const std::string& key,
                      const std::vector<std::string>& choices,
                      std::string* out,
                      bool required) {
  std::string s = *out;
  const bool had = Has(key);
  Get(key, &s, required);
  if (!had || !status_.ok()) return;
  for (const auto& c : choices) {
    if (s == c) {
      *out = s;
      return;
    }
  }
  std::string list;
  for (const auto& c : choices) list += (list.empty() ? "" : "|") + c;
  Fail(key, "expected one of " + list + ", got '" + s + "'");
}

void YamlMap::GetPositive(const std::string& key, double* out, bool required) {
  double v = *out;
  const bool had = Has(key);
  Get(key, &v, required);
  if (!had || !status_.ok()) return;
  if (!(v > 0)) {
    Fail(key, "expected a positive number, got " + node_[key].Scalar());
    return;
  }
  *out = v;
}

void YamlMap::GetNonNegative(const std::string& key, double* out, bool required) {
  double v = *out;
  const bool had = Has(key);
  Get(key, &v, required);
  if (!had || !status_.ok()) return;
  if (!(v >= 0)) {
    Fail(key, "expected a non-negative number, got " + node_[key].Scalar());
    return;
  }
  *out = v;
}

void YamlMap::GetInRange(const std::string& key,
                         double* out,
                         const PlausibleRange& range,
                         bool required) {
  double v = *out;
  const bool had = Has(key);
  Get(key, &v, required);
  if (!had || !status_.ok()) return;
  if (!InRange(v, range)) {
    Fail(key, "expected " + FormatRange(range) + ", got " + FormatCompact(v));
    return;
  }
  *out = v;
}

void YamlMap::GetInRange(const std::string& key,
                         int* out,
                         const PlausibleRange& range,
                         bool required) {
  int v = *out;
  const bool had = Has(key);
  Get(key, &v, required);
  if (!had || !status_.ok()) return;
  if (!InRange(v, range)) {
    Fail(key, "expected an integer " + FormatRange(range) + ", got " + std::to_string(v));
    return;
  }
  *out = v;
}

YamlMap& YamlMap::Map(const std::string& key, bool required) {
  const auto n = Node(key, required, "a mapping");
  children_.push_back(std::make_unique<YamlMap>(n ? *n : YAML::Node(), file_, KeyPath(key)));
  return *children_.back();
}

std::vector<YamlMap*> YamlMap::MapList(const std::string& key, bool required) {
  std::vector<YamlMap*> out;
  const auto on = Node(key, required, "a list of mappings");
  if (!on) return out;
  const YAML::Node& n = *on;
  if (!n.IsSequence()) {
    Fail(key, "expected a list of mappings, got " + Show(n));
    return out;
  }
  for (size_t i = 0; i < n.size(); ++i) {
    children_.push_back(
        std::make_unique<YamlMap>(n[i], file_, KeyPath(key) + "[" + std::to_string(i) + "]"));
    out.push_back(children_.back().get());
  }
  return out;
}

YAML::Node YamlMap::Raw(const std::string& key) {
  known_.insert(key);
  return Has(key) ? node_[key] : YAML::Node();
}

Status YamlMap::UnknownKey() const {
  if (node_ && node_.IsMap()) {
    for (const auto& kv : node_) {
      // A complex key (`? [a, b]`, `? {a: 1}`) is no key of ours; as<std::string>() would throw.
      if (!kv.first.IsScalar()) {
        return Status::Error(file_ + ":" + std::to_string(kv.first.Mark().line + 1) +
                             ": " + (prefix_.empty() ? std::string("top level")
                                                     : "key '" + prefix_ + "'") +
                             ": expected keys that are names, got " + Show(kv.first) +
                             " as a key");
      }
      const std::string k = kv.first.Scalar();
      if (!known_.count(k)) {
        std::string list;
        for (const auto& kk : known_) list += (list.empty() ? "" : ", ") + kk;
        const std::string close =
            ClosestMatch(k, std::vector<std::string>(known_.begin(), known_.end()));
        return Status::Error(file_ + ":" + std::to_string(kv.first.Mark().line + 1) +
                             ": unknown key '" + KeyPath(k) + "'" +
                             (close.empty() ? "" : "; did you mean '" + close + "'?") +
                             " (known keys: " + list + ")");
      }
    }
  }
  return Status::Ok();
}

Status YamlMap::Finish() {
  // An unknown key comes before a missing one (the typo is the cause); any other error first.
  if (!status_.ok() && !missing_) return status_;
  if (Status u = UnknownKey(); !u.ok()) return status_ = u;
  if (!status_.ok()) return status_;
  for (auto& c : children_) {
    Status s = c->Finish();
    if (!s.ok()) return status_ = s;
  }
  if (status_.ok() && AcceptedKeyRecordingEnabled()) {
    static const std::regex kIndex("\\[[0-9]+\\]");
    for (const auto& k : known_) {
      RecordAcceptedKey(file_,
                        std::regex_replace(KeyPath(user_named_.empty() ? k : user_named_), kIndex,
                                           "[]"));
    }
  }
  return status_;
}

}  // namespace carmba
