// src/docs/own-data.md runs as written (issues 13 and 23): the commands of its `sh` blocks are
// taken from the file and run verbatim, in order, each in its own shell, in an empty mkdtemp
// directory, from step 0 (which makes mydata/ with the simulator). The environment is the one the
// doc asks the reader to export: CARMBA_DIR the source tree, PATH starting with the built
// command's directory; nothing in the commands is rewritten. Its `yaml` blocks are saved as the
// files the text before them names ("Save it as `pose.yaml`"). Each command must exit 0 and leave
// its --out; every `out/...` and `mydata/...` path the text names must exist at the end. Then the
// outputs are checked: the intrinsics against the simulation's truth, and the keys of
// camera.json, both result.json files and geometry.json against formats.md's tables.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>
#include <sstream>
#include <vector>

#include "cli_test_util.h"
#include "markdown_doc.h"
#include "scratch.h"

namespace carmba {
namespace {

namespace fs = std::filesystem;
using test::JoinSet;

const std::string kOwnDataSrc = CARMBA_SOURCE_DIR;
const std::string kOwnDataDoc = kOwnDataSrc + "/src/docs/own-data.md";

// The programs the walk-through may run: carmba and the shell's file basics (a doc edit that
// adds anything else is a deliberate change of this test).
const std::set<std::string> kPrograms = {"carmba", "mkdir", "ln", "cp"};

// The lines of `path`, 1-based (line 0 empty).
std::vector<std::string> Lines(const std::string& path) {
  std::vector<std::string> lines = {""};
  std::ifstream in(path);
  for (std::string l; std::getline(in, l);) lines.push_back(l);
  return lines;
}

// The shell commands of an `sh` block: its lines, a trailing backslash joining the next,
// blank lines and comments dropped.
std::vector<std::string> Commands(const std::string& block) {
  std::vector<std::string> out;
  std::istringstream in(block);
  std::string cmd;
  for (std::string l; std::getline(in, l);) {
    if (cmd.empty() && (l.find_first_not_of(" \t") == std::string::npos || l[0] == '#')) continue;
    if (!l.empty() && l.back() == '\\') {
      cmd += l.substr(0, l.size() - 1);
      continue;
    }
    out.push_back(cmd + l);
    cmd.clear();
  }
  if (!cmd.empty()) out.push_back(cmd);
  return out;
}

// The words of a command (split at blanks; the walk-through quotes only globs and paths).
std::vector<std::string> Words(const std::string& cmd) {
  std::vector<std::string> w;
  std::istringstream in(cmd);
  for (std::string x; in >> x;) w.push_back(x);
  return w;
}

// The value of `--out` (`--out X` or `--out=X`), "" when there is none.
std::string OutFlag(const std::vector<std::string>& words) {
  for (size_t i = 0; i < words.size(); ++i) {
    if (words[i] == "--out" && i + 1 < words.size()) return words[i + 1];
    if (words[i].rfind("--out=", 0) == 0) return words[i].substr(6);
  }
  return "";
}

// The `out/...` and `mydata/...` paths (no globs) named in backticks in the text outside the
// fenced blocks: the files and directories the walk-through promises.
std::set<std::string> PromisedPaths(const std::vector<std::string>& lines,
                                    const test::MarkdownDoc& doc) {
  std::vector<bool> fenced(lines.size(), false);
  for (const auto& b : doc.blocks) {
    for (int n = b.line; n <= b.end_line && n < static_cast<int>(lines.size()); ++n)
      fenced[n] = true;
  }
  std::set<std::string> out;
  const std::regex path("`((out|mydata)/[A-Za-z0-9_./-]*)`");
  for (size_t n = 1; n < lines.size(); ++n) {
    if (fenced[n]) continue;
    for (std::sregex_iterator m(lines[n].begin(), lines[n].end(), path), end; m != end; ++m) {
      out.insert((*m)[1]);
    }
  }
  return out;
}

// The prose between the block before `b` (or the top) and `b`.
std::string TextBefore(const std::vector<std::string>& lines, const test::MarkdownDoc& doc,
                       size_t b) {
  const int from = b == 0 ? 1 : doc.blocks[b - 1].end_line + 1;
  std::string text;
  for (int n = from; n < doc.blocks[b].line; ++n) text += lines[n] + "\n";
  return text;
}

// The environment the doc asks for: CARMBA_DIR and the built command first on PATH.
void ExportWalkThroughEnvironment() {
  const std::string bin_dir = fs::path(CARMBA_BIN).parent_path().string();
  const char* path = std::getenv("PATH");
  ::setenv("CARMBA_DIR", kOwnDataSrc.c_str(), 1);
  ::setenv("PATH", (bin_dir + ":" + (path ? path : "/usr/bin:/bin")).c_str(), 1);
}

TEST(DocsOwnData, WalkThroughRunsAsWritten) {
  const test::MarkdownDoc doc = test::ReadMarkdownDoc(kOwnDataDoc);
  const std::vector<std::string> lines = Lines(kOwnDataDoc);
  const test::MarkdownDoc formats = test::ReadMarkdownDoc(kOwnDataSrc + "/src/docs/formats.md");
  const test::ScratchDir dir("docs_own_data");   // the reader's empty directory
  const test::ScratchDir logs("docs_own_data_log");  // each command's stdout and stderr
  ExportWalkThroughEnvironment();
  ASSERT_EQ(std::system(("command -v carmba >" + logs.File("which")).c_str()), 0);
  ASSERT_EQ(test::ReadTextFile(logs.File("which")), std::string(CARMBA_BIN) + "\n");

  std::set<std::string> subcommands;
  for (size_t i = 0; i < doc.blocks.size(); ++i) {
    const test::DocBlock& b = doc.blocks[i];
    const std::string where = "own-data.md:" + std::to_string(b.line) + ": ";
    if (b.lang == "yaml") {
      ASSERT_FALSE(b.file.empty()) << where << "a yaml block without file=";
      ASSERT_NE(TextBefore(lines, doc, i).find("`" + b.file + "`"), std::string::npos)
          << where << "the text before the block does not say to save it as `" << b.file << "`";
      dir.Write(b.file, b.text);
      continue;
    }
    ASSERT_EQ(b.lang, "sh") << where << "a block the reader would not know what to do with";
    for (const std::string& cmd : Commands(b.text)) {
      const std::vector<std::string> words = Words(cmd);
      ASSERT_TRUE(kPrograms.count(words[0]))
          << where << "the walk-through runs " << JoinSet(kPrograms) << ", not: " << cmd;
      if (words[0] == "carmba" && words.size() > 1) subcommands.insert(words[1]);
      const std::string shell = "cd '" + dir.path() + "' && (\n" + cmd + "\n) >" +
                                logs.File("stdout") + " 2>" + logs.File("stderr");
      const int status = std::system(shell.c_str());
      ASSERT_EQ(status, 0) << where << cmd << "\n" << test::ReadTextFile(logs.File("stderr"));
      const std::string out = OutFlag(words);
      if (!out.empty()) {
        EXPECT_TRUE(fs::exists(dir.File(out))) << where << cmd << ": no " << out;
      }
    }
  }
  for (const char* c : {"simulate", "detect", "calibrate", "ct-fiducials", "solve"}) {
    EXPECT_TRUE(subcommands.count(c)) << "the walk-through no longer runs carmba " << c;
  }
  const std::set<std::string> promised = PromisedPaths(lines, doc);
  EXPECT_GE(promised.size(), 10u) << JoinSet(promised);
  for (const std::string& p : promised) {
    EXPECT_TRUE(fs::exists(dir.File(p))) << "own-data.md names `" << p << "`, not written";
  }

  // The outputs the walk-through names, and their keys as formats.md lists them.
  const std::map<std::string, std::string> outputs = {
      {"json-camera", "out/calib/camera.json"},
      {"json-result-pose", "out/pose/result.json"},
      {"json-result-joint", "out/joint/result.json"},
      {"json-geometry", "out/pose/geometry.json"}};
  for (const auto& [kind, file] : outputs) {
    SCOPED_TRACE(file + " against formats.md table " + kind);
    const nlohmann::json j = test::ReadJsonFile(dir.File(file));
    ASSERT_TRUE(j.is_object()) << "not a JSON object";
    ASSERT_TRUE(formats.tables.count(kind));
    const auto& rows = formats.tables.at(kind);
    const std::set<std::string> documented(rows.begin(), rows.end());
    std::set<std::string> written;
    test::FlattenJsonKeys(j, "", 2, &written);
    EXPECT_TRUE(test::Minus(written, documented).empty())
        << "written, not in the table: " << JoinSet(test::Minus(written, documented));
    EXPECT_TRUE(test::Minus(documented, written).empty())
        << "in the table, not written: " << JoinSet(test::Minus(documented, written));
  }

  // The answers: intrinsics within 4 sigma of the simulation's truth, every object pose with
  // positive finite sigmas, an error budget.
  const nlohmann::json truth = test::ReadJsonFile(dir.File("mydata/truth.json"));
  const nlohmann::json joint = test::ReadJsonFile(dir.File("out/joint/result.json"));
  const nlohmann::json camera = test::ReadJsonFile(dir.File("out/calib/camera.json"));
  constexpr double kSigmas = 4;  // a correct 1-sigma is exceeded by 4 with probability 6e-5
  for (const char* p : {"fx", "fy", "cx", "cy"}) {
    const double t = truth.at("camera").at(p).get<double>();
    const double jv = joint.at("intrinsics").at(p).get<double>();
    const double js = joint.at("intrinsics").at("sigmas").at(p).get<double>();
    EXPECT_LT(std::abs(jv - t), kSigmas * js) << "joint " << p;
    const double cv = camera.at(p).get<double>();
    const double cs = camera.at("sigmas").at(p).get<double>();
    EXPECT_LT(std::abs(cv - t), kSigmas * cs) << "calibrate " << p;
  }
  const nlohmann::json pose = test::ReadJsonFile(dir.File("out/pose/result.json"));
  EXPECT_EQ(pose.at("views").size(), truth.at("object_views").size());
  for (const auto& v : pose.at("views")) {
    for (const auto& s : v.at("sigma_translation_mm")) {
      EXPECT_TRUE(s.get<double>() > 0 && std::isfinite(s.get<double>())) << v.at("id");
    }
  }
  EXPECT_FALSE(joint.at("error_budget").empty());
}

}  // namespace
}  // namespace carmba
