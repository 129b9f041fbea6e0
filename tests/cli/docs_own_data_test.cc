// src/docs/own-data.md is run as written (issue 13): the data of its step 0 are simulated
// (`carmba simulate` of the joint scene, which writes plate/, object/observations.csv and ct/ in
// that layout, and the design of its 9 markers), its `yaml` blocks are written to the files they
// name and every line of its `sh` blocks is run in order in that directory, `carmba` being the
// built command (and `mkdir -p`). The outputs are then checked: the intrinsics against the simulation's truth,
// and the keys of camera.json, both result.json files and geometry.json against formats.md's
// tables.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "cli/cli_test_util.h"
#include "cli/markdown_doc.h"

namespace carmba {
namespace {

namespace fs = std::filesystem;
using test::JoinSet;

const std::string kSrc = CARMBA_SOURCE_DIR;

// The marker design of the simulated object: data/thesis/markers_table_5_1.csv's object frame.
std::string MarkerDesignCsv() {
  std::ifstream in(kSrc + "/data/thesis/markers_table_5_1.csv");
  std::string line, out = "id,x_mm,y_mm,z_mm\n";
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#' || line.rfind("marker", 0) == 0) continue;
    std::vector<std::string> f;
    std::stringstream ss(line);
    for (std::string x; std::getline(ss, x, ',');) f.push_back(x);
    if (f.size() == 7) out += f[0] + "," + f[4] + "," + f[5] + "," + f[6] + "\n";
  }
  return out;
}

TEST(DocsOwnData, WalkThroughRunsOnSimulatedData) {
  const test::MarkdownDoc doc = test::ReadMarkdownDoc(kSrc + "/src/docs/own-data.md");
  const test::MarkdownDoc formats = test::ReadMarkdownDoc(kSrc + "/src/docs/formats.md");
  test::TempDir dir;
  fs::create_directory_symlink(kSrc + "/configs", dir.File("configs"));
  {
    const auto r = test::RunCarmba("simulate --scene " + kSrc +
                                   "/configs/scenes/thesis_joint.yaml --out " +
                                   dir.File("mydata"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  dir.Write("mydata/markers_design.csv", MarkerDesignCsv());

  int commands = 0;
  for (const auto& b : doc.blocks) {
    if (b.lang == "yaml") {
      ASSERT_FALSE(b.file.empty()) << "own-data.md:" << b.line << ": a yaml block without file=";
      dir.Write(b.file, b.text);
      continue;
    }
    if (b.lang != "sh") continue;
    std::istringstream lines(b.text);
    for (std::string line; std::getline(lines, line);) {
      if (line.empty() || line[0] == '#') continue;
      const bool is_carmba = line.rfind("carmba ", 0) == 0;
      ASSERT_TRUE(is_carmba || line.rfind("mkdir -p ", 0) == 0)
          << "own-data.md:" << b.line << ": the walk-through's commands are carmba commands and "
          << "mkdir -p (the test runs them all): " << line;
      const std::string run = is_carmba ? std::string(CARMBA_BIN) + line.substr(6) : line;
      const std::string cmd =
          "cd '" + dir.path() + "' && " + run + " >/dev/null 2>" + dir.File("stderr");
      const int status = std::system(cmd.c_str());
      std::ifstream err(dir.File("stderr"));
      std::stringstream es;
      es << err.rdbuf();
      ASSERT_EQ(status, 0) << "own-data.md:" << b.line << ": " << line << "\n" << es.str();
      ++commands;
    }
  }
  EXPECT_GE(commands, 5) << "detect, calibrate, ct-fiducials and two solves";

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
