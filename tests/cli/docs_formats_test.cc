// src/docs/formats.md is checked against carmba's readers (issue 13): every example block with a
// `file=` name is written to a scratch directory and read by the real reader; the keys each
// reader asked for while reading them (util/accepted_keys.h) must equal the keys of the format's
// table, both ways; and every key name passed to a reader call in src/ must appear in a table.
// The readers of the CLI (calibration problem and config, joint scene) run in the built command,
// which writes what it recorded to $CARMBA_ACCEPTED_KEYS.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <filesystem>
#include <regex>

#include "cli/cli_test_util.h"
#include "cli/markdown_doc.h"
#include "ct/ct_simulate.h"
#include "detect/grid_detector.h"
#include "detect/marker_views.h"
#include "joint/joint_solver.h"
#include "problem/pose_solver.h"
#include "sim/xray_scene.h"
#include "study/study_spec.h"
#include "util/accepted_keys.h"
#include "util/yaml_reader.h"

namespace carmba {
namespace {

namespace fs = std::filesystem;
using test::JoinSet;
using test::Minus;

const std::string kFormatsDoc = std::string(CARMBA_SOURCE_DIR) + "/src/docs/formats.md";

// Tables of output files: compared with real outputs by DocsOwnData (docs_own_data_test.cc).
// json-result-joint-flex by FlexCli (flex_cli_test.cc).
const std::set<std::string> kOutputTables = {"json-camera", "json-result-pose", "json-result-joint",
                                             "json-geometry", "json-result-joint-flex"};

// Reads an example with the reader of its kind, in this process. Returns false for kinds read by
// the command (or by another example, as the CSVs and camera.json).
bool ReadInProcess(const std::string& kind, const std::string& path, Status* status) {
  if (kind == "problem" || kind == "problem-older-pose" || kind == "problem-older-calibration") {
    *status = LoadProblem(path).status();
  } else if (kind == "solver-config") {
    *status = LoadSolverConfig(path).status();
  } else if (kind == "xray-scene") {
    *status = sim::LoadXrayScene(path).status();
  } else if (kind == "ct-scene") {
    YamlMap m = YamlMap::Load(path);
    CtScene scene;
    *status = m.status().ok() ? ParseCtScene(m, &scene) : m.status();
  } else if (kind == "study") {
    *status = LoadStudySpec(path).status();
  } else if (kind == "grid-detection") {
    DetectionOptions d;
    *status = LoadDetectionOptions(path, &d);
  } else if (kind == "marker-detection") {
    YamlMap m = YamlMap::Load(path);
    ObjectViewsOptions o;
    if (m.status().ok()) ReadObjectViewsOptions(m, &o);
    *status = m.status().ok() ? m.Finish() : m.status();
  } else {
    return false;
  }
  return true;
}

class DocsFormats : public ::testing::Test {
 protected:
  void SetUp() override {
    doc_ = test::ReadMarkdownDoc(kFormatsDoc);
    ASSERT_FALSE(doc_.blocks.empty()) << kFormatsDoc << ": no fenced blocks (is the file there?)";
    for (const auto& b : doc_.blocks) {
      if (!b.file.empty()) dir_.Write(b.file, b.text);
    }
  }

  // Keys recorded for the example files, by file name (the readers name files by the path they
  // were given; the examples all sit in dir_).
  std::map<std::string, std::set<std::string>> KeysByExampleFile(
      const std::map<std::string, std::set<std::string>>& recorded) const {
    std::map<std::string, std::set<std::string>> out;
    for (const auto& [file, keys] : recorded) {
      const fs::path p(file);
      if (fs::weakly_canonical(p.parent_path()) != fs::weakly_canonical(dir_.path())) continue;
      out[p.filename().string()].insert(keys.begin(), keys.end());
    }
    return out;
  }

  test::MarkdownDoc doc_;
  test::ScratchDir dir_;
};

TEST_F(DocsFormats, ExamplesReadAndKeyTablesMatchTheReaders) {
  EnableAcceptedKeyRecording();
  ClearAcceptedKeys();
  // The command: a simulation of the example joint scene (which names the example X-ray and CT
  // scenes; the calibration problem example reads its plate images), and a calibration from the
  // older calibration problem example (which names the example config).
  const std::string keys_file = dir_.File("accepted_keys.tsv");
  auto run = [&](const std::string& args) {
    ::setenv("CARMBA_ACCEPTED_KEYS", keys_file.c_str(), 1);
    const auto r = test::RunCarmba(args);
    ::unsetenv("CARMBA_ACCEPTED_KEYS");
    return r;
  };
  const auto sim =
      run("simulate --scene " + dir_.File("joint_scene.yaml") + " --out " + dir_.File("sim_out"));
  EXPECT_EQ(sim.exit_code, 0) << sim.err;
  std::set<std::string> cli_kinds;
  for (const auto& b : doc_.blocks) {
    if (b.file.empty() || b.kind.empty()) continue;
    Status s;
    if (ReadInProcess(b.kind, dir_.File(b.file), &s)) {
      EXPECT_TRUE(s.ok()) << "formats.md:" << b.line << " (" << b.file << "): " << s.message();
    } else if (b.kind.rfind("csv-", 0) != 0 && b.kind != "camera-json-input") {
      cli_kinds.insert(b.kind);
    }
  }
  std::map<std::string, std::set<std::string>> recorded = AcceptedKeys();
  {
    const auto r = run("calibrate --problem " + dir_.File("calib_problem_older.yaml") +
                       " --no-plots --no-mrcal --no-opencv --out " + dir_.File("calib_out"));
    EXPECT_EQ(r.exit_code, 0) << r.err;
    EXPECT_EQ(cli_kinds, (std::set<std::string>{"calib-config", "joint-scene"}))
        << "example kinds that no reader in this test reads";
  }
  {
    std::istringstream in(test::ReadTextFile(keys_file));
    std::string line;
    while (std::getline(in, line)) {
      const auto tab = line.find('\t');
      if (tab != std::string::npos) recorded[line.substr(0, tab)].insert(line.substr(tab + 1));
    }
  }
  const auto by_file = KeysByExampleFile(recorded);

  std::set<std::string> kinds_with_examples;
  for (const auto& b : doc_.blocks) {
    if (!b.kind.empty()) kinds_with_examples.insert(b.kind);
  }
  for (const auto& [kind, rows] : doc_.tables) {
    if (kOutputTables.count(kind) || kind == "study-synthetic") continue;
    SCOPED_TRACE("formats.md:" + std::to_string(doc_.table_lines.at(kind)) + " table " + kind);
    EXPECT_TRUE(kinds_with_examples.count(kind)) << "no example block of kind " << kind;
    std::set<std::string> documented(rows.begin(), rows.end());
    EXPECT_EQ(documented.size(), rows.size()) << "a key listed twice";
    std::set<std::string> accepted;
    for (const auto& b : doc_.blocks) {
      if (b.kind != kind || b.file.empty()) continue;
      const auto it = by_file.find(b.file);
      EXPECT_TRUE(it != by_file.end()) << b.file << " was not read by any reader";
      if (it == by_file.end()) continue;
      for (std::string k : it->second) {
        // Wide observations: the columns u_<view>, v_<view> are named by the views.
        if (kind == "csv-observations-wide" && k != "marker") k = k.substr(0, 2) + "<view>";
        accepted.insert(k);
      }
    }
    const std::set<std::string> undocumented = Minus(accepted, documented);
    const std::set<std::string> not_accepted = Minus(documented, accepted);
    EXPECT_TRUE(undocumented.empty()) << "accepted by the reader, missing from the table: "
                                      << JoinSet(undocumented);
    EXPECT_TRUE(not_accepted.empty())
        << "in the table, never asked for by the reader of the examples (a key no reader accepts, "
           "or an example that leaves out a key read only when present): "
        << JoinSet(not_accepted);
  }
  for (const auto& kind : kinds_with_examples) {
    EXPECT_TRUE(doc_.tables.count(kind)) << "example kind " << kind << " has no key table";
  }
}

// The shipped problem, config, scene and study files use only documented keys (those whose data
// are present are read fully: thesis_joint.yaml needs `carmba simulate` output first).
TEST_F(DocsFormats, ShippedFilesUseOnlyDocumentedKeys) {
  EnableAcceptedKeyRecording();
  ClearAcceptedKeys();
  std::map<std::string, std::string> kind_of;  // path -> kind
  int read = 0;
  auto try_read = [&](const std::string& kind, const std::string& path) {
    Status s;
    ReadInProcess(kind, path, &s);
    if (s.ok()) {
      kind_of[path] = kind;
      ++read;
    }
  };
  for (const char* sub : {"problems", "configs", "configs/scenes", "configs/studies"}) {
    for (const auto& e : fs::directory_iterator(std::string(CARMBA_SOURCE_DIR) + "/" + sub)) {
      if (e.path().extension() != ".yaml") continue;
      const std::string path = e.path().string(), dir = std::string(sub);
      const std::string text = test::ReadTextFile(path);
      if (dir == "problems") {
        try_read("problem", path);
      } else if (dir == "configs") {
        try_read("solver-config", path);  // calibration configs are refused: the CLI reads them
      } else if (dir == "configs/scenes") {
        if (text.find("kind: xray") != std::string::npos) try_read("xray-scene", path);
        if (text.find("kind: ct") != std::string::npos) try_read("ct-scene", path);
      } else {
        try_read("study", path);
      }
    }
  }
  EXPECT_GE(read, 15) << "too few shipped files read";
  for (const auto& [path, keys] : AcceptedKeys()) {
    const auto it = kind_of.find(path);
    if (it == kind_of.end()) continue;
    const auto& rows = doc_.tables.at(it->second);
    const std::set<std::string> documented(rows.begin(), rows.end());
    EXPECT_TRUE(Minus(keys, documented).empty())
        << path << " (" << it->second << "): keys missing from formats.md: "
        << JoinSet(Minus(keys, documented));
  }
}

// The last dotted component of a documented key: `views[].primary_deg` -> primary_deg.
std::string Leaf(std::string key) {
  const auto dot = key.find_last_of('.');
  if (dot != std::string::npos) key = key.substr(dot + 1);
  const auto br = key.find('[');
  return br == std::string::npos ? key : key.substr(0, br);
}

// Every key name a reader call in src/ passes as a literal (YamlMap::Get/Map/..., the study's
// JSON reader, the CT scene's Opt helpers) appears in a YAML table, and every documented name is
// such a literal: catches a key added to a branch that no example reaches.
TEST_F(DocsFormats, EveryKeyNameInTheReadersIsDocumented) {
  const std::regex call(
      R"re((?:\b(?:Get|GetEnum|GetInRange|GetPositive|GetNonNegative|Map|MapList|Raw|Has|)re"
      R"re(Number|Numbers|String|Vector3|Find)\(\s*|)re"
      R"re(\b(?:Opt|OptIn|GetVec|CheckEach)\(\s*\*?\w+,\s*)"([A-Za-z_][A-Za-z0-9_]*)")re");
  std::set<std::string> in_source;
  for (const auto& e : fs::recursive_directory_iterator(std::string(CARMBA_SOURCE_DIR) + "/src")) {
    if (e.path().extension() != ".cc") continue;
    const std::string text = test::ReadTextFile(e.path().string());
    // Files with a key reader: YAML (util/yaml_reader.h) or the study's JSON mappings.
    if (text.find("YamlMap") == std::string::npos && text.find("JsonMap") == std::string::npos) {
      continue;
    }
    if (e.path().filename() == "yaml_reader.cc") continue;
    for (std::sregex_iterator it(text.begin(), text.end(), call), end; it != end; ++it) {
      in_source.insert((*it)[1]);
    }
  }
  ASSERT_GT(in_source.size(), 100u) << "the scan of src/ found too few reader calls";
  std::set<std::string> documented;
  for (const auto& [kind, rows] : doc_.tables) {
    // YAML (and the study's JSON-in-YAML) tables; camera.json's reader is checked above.
    if (kOutputTables.count(kind) || kind.rfind("csv-", 0) == 0 || kind == "camera-json-input") {
      continue;
    }
    for (const auto& k : rows) {
      const std::string leaf = Leaf(k);
      if (!leaf.empty() && leaf[0] != '<') documented.insert(leaf);
    }
  }
  const std::set<std::string> undocumented = Minus(in_source, documented);
  const std::set<std::string> unknown = Minus(documented, in_source);
  EXPECT_TRUE(undocumented.empty()) << "key names read in src/ but in no table of formats.md: "
                                    << JoinSet(undocumented);
  EXPECT_TRUE(unknown.empty()) << "documented key names that no reader call in src/ names: "
                               << JoinSet(unknown);
}

}  // namespace
}  // namespace carmba
