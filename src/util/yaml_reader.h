// Strict reading of YAML mappings for problem, config, scene and study files.
//
// Every key read is recorded; Finish() reports the first unknown key, with the closest known key
// ("did you mean"). A required key that is missing while an unknown key resembles it reports the
// unknown key instead ("unknown key 'sigma_pz'; did you mean 'sigma_px'?"), since a parser may stop
// at the missing key before Finish() sees the rest. The keys a parser asks for are
// also what util/accepted_keys.h records, for the check of src/docs/formats.md. Wrong types,
// missing required keys and non-finite numbers are errors naming the file, the line and the dotted
// key path, and what was expected, e.g.
//   configs/x.yaml:7: key 'solver.max_iterations': expected an integer, got 'many'
//
//   YamlMap m(root, path);
//   m.Get("max_iterations", &options.max_iterations);
//   YamlMap solver = m.Map("solver");
//   ...
//   CARMBA_RETURN_IF_ERROR(m.Finish());
#pragma once

#include <yaml-cpp/yaml.h>

#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "util/enum_names.h"
#include "util/plausible.h"
#include "util/status.h"

namespace carmba {

class YamlMap {
 public:
  // `node` must be a map (or null/absent: then every key is absent). `file` names the source.
  YamlMap(const YAML::Node& node, std::string file, std::string prefix = "");

  // Loads a file; the error (missing file, YAML syntax) goes into status().
  static YamlMap Load(const std::string& path);

  bool Has(const std::string& key) const;
  // Optional values: left untouched when absent. Required ones record an error when absent.
  void Get(const std::string& key, double* out, bool required = false);
  void Get(const std::string& key, int* out, bool required = false);
  void Get(const std::string& key, bool* out, bool required = false);
  void Get(const std::string& key, std::string* out, bool required = false);
  void Get(const std::string& key, std::vector<double>* out, bool required = false);
  void Get(const std::string& key, std::vector<int>* out, bool required = false);
  void Get(const std::string& key, std::vector<std::string>* out, bool required = false);
  // A string that must be one of `choices`.
  void GetEnum(const std::string& key,
               const std::vector<std::string>& choices,
               std::string* out,
               bool required = false);
  // An enum value by one of its names (util/enum_names.h).
  template <typename E, size_t N>
  void GetEnum(const std::string& key,
               const EnumName<E> (&names)[N],
               E* out,
               bool required = false) {
    std::string s = NameOf(names, *out);
    GetEnum(key, NamesOf(names), &s, required);
    ParseName(names, s, out);
  }
  // A positive / non-negative number (after Get).
  void GetPositive(const std::string& key, double* out, bool required = false);
  void GetNonNegative(const std::string& key, double* out, bool required = false);
  // A number / an integer within a plausible range (util/plausible.h); the error names the line,
  // the key, the range and the value (%g), e.g.
  //   config.yaml:4: key 'loss.scale_px': expected 1e-06 .. 10000 px, got 1e+300
  void GetInRange(const std::string& key,
                  double* out,
                  const PlausibleRange& range,
                  bool required = false);
  void GetInRange(const std::string& key,
                  int* out,
                  const PlausibleRange& range,
                  bool required = false);

  // A nested map (absent -> an empty map). Its errors and unknown keys are reported by this
  // map's Finish().
  YamlMap& Map(const std::string& key, bool required = false);
  // A sequence of maps.
  std::vector<YamlMap*> MapList(const std::string& key, bool required = false);
  // The raw node (marks the key as known); a Null node when absent -- test with Has().
  YAML::Node Raw(const std::string& key);

  // This map's keys are names the user chooses (e.g. materials); util/accepted_keys.h records them
  // as `placeholder` (e.g. "<material>").
  void SetUserNamedKeys(const std::string& placeholder) { user_named_ = placeholder; }

  // Records an error at `key` (for checks done by the caller).
  void Fail(const std::string& key, const std::string& what);
  // The first error so far, including nested maps and unknown keys.
  Status Finish();
  // The first error so far. When it is a missing required key and a key never asked for resembles
  // it, that key instead: "unknown key 'sigma_pz'; did you mean 'sigma_px'? (a required key)".
  Status status() const;
  const std::string& file() const { return file_; }
  std::string KeyPath(const std::string& key) const;

 private:
  std::string Where(const std::string& key) const;
  // A required key `missing` is absent: notes the keys of this map not asked for so far that are
  // likely misspellings of it (util/text_match.h ClosestMatch), for status().
  void NoteMisspellingsOf(const std::string& missing);
  // The first key of this map no parser asked for (Ok if none).
  Status UnknownKey() const;
  std::optional<YAML::Node> Node(const std::string& key, bool required, const char* expected);

  YAML::Node node_;
  std::string file_;
  std::string prefix_;
  std::set<std::string> known_;
  std::string user_named_;
  std::vector<std::unique_ptr<YamlMap>> children_;
  Status status_;
  bool missing_ = false;  // status_ is a missing required key
  std::vector<Status> misspelt_;           // their errors, for status()
  std::vector<std::string> misspelt_keys_;  // keys resembling the missing one
};

}  // namespace carmba
