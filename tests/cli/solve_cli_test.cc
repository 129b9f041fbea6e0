// End-to-end tests of `carmba solve`: the thesis job, and bad input one corruption at a time.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "cli_test_util.h"

namespace carmba::test {
namespace {

const std::string kSource = CARMBA_SOURCE_DIR;

TEST(SolveCli, ThesisJobWritesResultAndReport) {
  TempDir out;
  const auto r = RunCarmba("solve --problem=" + kSource + "/problems/thesis_pose.yaml --config=" +
                           kSource + "/configs/posit_ba_analytic.yaml --out=" + out.path());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::ifstream in(out.File("result.json"));
  ASSERT_TRUE(in.good());
  const nlohmann::json j = nlohmann::json::parse(in);
  ASSERT_EQ(j["views"].size(), 5u);
  for (const auto& v : j["views"]) {
    EXPECT_EQ(v["cam_from_object"]["R"].size(), 9u);
    EXPECT_EQ(v["cam_from_object"]["rvec"].size(), 3u);
    EXPECT_EQ(v["cam_from_object"]["t_mm"].size(), 3u);
    EXPECT_EQ(v["covariance_6x6"].size(), 6u);
    EXPECT_TRUE(v["rms_px"].is_number());
  }
  ASSERT_EQ(j["validation"].size(), 3u);
  for (const char* k : {"a", "b", "angle_view_dirs_deg", "sigma_view_dirs_deg",
                        "relative_rotation_deg", "sigma_relative_rotation_deg", "expected_deg"}) {
    EXPECT_TRUE(j["validation"][0].contains(k)) << k;
  }
  for (const char* k : {"rms_px", "sigma_aposteriori_px", "num_residuals"}) {
    EXPECT_TRUE(j["statistics"][k].is_number()) << k;
  }
  EXPECT_EQ(j["solver"]["config"], "posit_ba_analytic");
  EXPECT_TRUE(j["solver"]["iterations"].is_number());
  std::ifstream rep(out.File("report.md"));
  std::stringstream ss;
  ss << rep.rdbuf();
  EXPECT_NE(ss.str().find("| pair | expected | thesis | legacy POSIT | bundle adjustment"),
            std::string::npos);
}

// A small valid problem in a temporary directory; each test corrupts one thing.
class BadInput : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_.Write("camera.json",
               R"({"image_size": [408, 408], "fx": 2061.4, "fy": 2254.6, "cx": 203.7,)"
               R"( "cy": 205.1, "distortion": [0, 0, 0, 0, 0]})");
    markers_ =
        "id,x_mm,y_mm,z_mm\n1,0,0,0\n2,-58.85,1,14\n3,13.35,1,14\n4,-8.25,-20.5,24\n"
        "5,-56.05,19,31\n";
    // Two views of 5 markers (pixels from a pose 700 mm away).
    obs_ =
        "view,marker,u_px,v_px\n"
        "a,1,230.0,210.0\na,2,54.1,214.5\na,3,269.0,214.7\na,4,183.1,145.2\na,5,63.0,267.2\n"
        "b,1,231.0,211.0\nb,2,60.2,212.9\nb,3,268.7,216.0\nb,4,185.0,146.0\nb,5,68.0,265.0\n";
    problem_ =
        "name: bad_input_test\ncamera: camera.json\nsigma_px: 0.5\n"
        "markers: {file: markers.csv, sigma_mm: 0.2}\n"
        "observations: {file: obs.csv, format: long}\n";
    config_ = "name: c\ninitializer: posit\n";
  }
  void WriteAll() {
    dir_.Write("markers.csv", markers_);
    dir_.Write("obs.csv", obs_);
    dir_.Write("problem.yaml", problem_);
    dir_.Write("config.yaml", config_);
  }
  // Runs solve and checks: non-zero exit, exactly one line on stderr containing `expected`,
  // and no result.json or report.md left behind.
  void ExpectError(const std::string& expected) {
    WriteAll();
    const std::string out = dir_.File("out");
    const auto r = RunCarmba("solve --problem=" + dir_.File("problem.yaml") +
                             " --config=" + dir_.File("config.yaml") + " --out=" + out);
    EXPECT_NE(r.exit_code, 0);
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(expected), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(out + "/result.json"));
    EXPECT_FALSE(std::filesystem::exists(out + "/report.md"));
  }
  TempDir dir_;
  std::string markers_, obs_, problem_, config_;
};

TEST_F(BadInput, ValidProblemSolves) {
  WriteAll();
  const auto r = RunCarmba("solve --problem=" + dir_.File("problem.yaml") + " --config=" +
                           dir_.File("config.yaml") + " --out=" + dir_.File("out"));
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(std::filesystem::exists(dir_.File("out/result.json")));
}

TEST_F(BadInput, MissingFile) {
  problem_ = "name: x\ncamera: nowhere.json\nsigma_px: 0.5\n"
             "markers: {file: markers.csv, sigma_mm: 0.2}\n"
             "observations: {file: obs.csv, format: long}\n";
  ExpectError("nowhere.json: cannot open");
}

TEST_F(BadInput, MissingProblemFile) {
  WriteAll();
  const auto r = RunCarmba("solve --problem=" + dir_.File("none.yaml") + " --config=" +
                           dir_.File("config.yaml") + " --out=" + dir_.File("out"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("none.yaml: cannot open file"), std::string::npos) << r.err;
}

TEST_F(BadInput, WrongColumnCount) {
  obs_ += "b,6,1.0\n";
  ExpectError("obs.csv:12: expected 4 comma-separated fields");
}

TEST_F(BadInput, NonNumericValue) {
  markers_ = "id,x_mm,y_mm,z_mm\n1,0,zero,0\n2,-58.85,1,14\n3,13.35,1,14\n4,-8.25,-20.5,24\n";
  ExpectError("markers.csv:2: column 'y_mm': expected a finite number, got 'zero'");
}

TEST_F(BadInput, NaN) {
  obs_ = "view,marker,u_px,v_px\na,1,nan,210\na,2,54.1,214.5\na,3,269,214.7\na,4,183.1,145.2\n";
  ExpectError("obs.csv:2: column 'u_px': expected a finite number, got 'nan'");
}

TEST_F(BadInput, ThreePoints) {
  obs_ = "view,marker,u_px,v_px\na,1,230,210\na,2,54.1,214.5\na,3,269,214.7\n";
  ExpectError("view 'a' has 3 observed markers; a pose needs at least 4");
}

TEST_F(BadInput, CoplanarPointsForPosit) {
  markers_ = "id,x_mm,y_mm,z_mm\n1,0,0,0\n2,40,0,0\n3,0,40,0\n4,40,40,0\n5,20,10,0\n";
  ExpectError("coplanar");
}

TEST_F(BadInput, UnknownConfigKey) {
  config_ = "name: c\ninitializer: posit\nmax_iteratons: 5\n";
  ExpectError("config.yaml:3: unknown key 'max_iteratons'");
}

TEST_F(BadInput, WrongConfigType) {
  config_ = "name: c\nmax_iterations: many\n";
  ExpectError("config.yaml:2: key 'max_iterations': expected an integer, got 'many'");
}

TEST_F(BadInput, UnknownInitializer) {
  config_ = "name: c\ninitializer: magic\n";
  ExpectError("key 'initializer': expected one of legacy_posit|posit|epnp|sqpnp, got 'magic'");
}

TEST_F(BadInput, UnknownProblemKey) {
  problem_ += "sigma_pix: 3\n";
  ExpectError("problem.yaml:6: unknown key 'sigma_pix'");
}

TEST_F(BadInput, MarkerNotInList) {
  obs_ += "b,9,10,10\n";
  ExpectError("view 'b' observes marker 9 which is not among the markers");
}

TEST_F(BadInput, RepeatedKey) {
  problem_ += "sigma_px: 2.0\n";
  ExpectError("problem.yaml:6: key 'sigma_px' appears twice");
}

TEST_F(BadInput, EmptyViewList) {
  problem_ += "views: []\n";
  ExpectError("key 'views': expected a non-empty list of view ids");
}

TEST_F(BadInput, HexadecimalNumber) {
  markers_ = "id,x_mm,y_mm,z_mm\n1,0,0x10,0\n2,-58.85,1,14\n3,13.35,1,14\n4,-8.25,-20.5,24\n";
  ExpectError("markers.csv:2: column 'y_mm': expected a finite number, got '0x10'");
}

TEST_F(BadInput, DirectoryAsProblemOrConfig) {
  WriteAll();
  for (const std::string& args :
       {"--problem=" + dir_.path() + " --config=" + dir_.File("config.yaml"),
        "--problem=" + dir_.File("problem.yaml") + " --config=" + dir_.path()}) {
    const auto r = RunCarmba("solve " + args + " --out=" + dir_.File("out"));
    EXPECT_EQ(r.exit_code, 1) << args << "\n" << r.err;  // an error, not a crash (134)
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find("is a directory"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir_.File("out/result.json")));
  }
}

// Not converged (max_iterations 0): the results are written, with a warning on stderr and in the
// report.
TEST_F(BadInput, NotConvergedIsWarned) {
  config_ = "name: c\ninitializer: posit\nmax_iterations: 0\n";
  WriteAll();
  const auto r = RunCarmba("solve --problem=" + dir_.File("problem.yaml") + " --config=" +
                           dir_.File("config.yaml") + " --out=" + dir_.File("out"));
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("did not converge"), std::string::npos) << r.err;
  std::ifstream rep(dir_.File("out/report.md"));
  std::stringstream ss;
  ss << rep.rdbuf();
  EXPECT_NE(ss.str().find("did not converge"), std::string::npos);
}

// refine: false compares both handednesses after the bundle adjustment, so no false warning; the
// report does not call the initializer's values "bundle adjustment".
TEST(SolveCli, UnrefinedConfigHasNoFalseHandednessWarning) {
  TempDir out;
  const auto r = RunCarmba("solve --problem=" + kSource + "/problems/thesis_pose.yaml" +
                           " --config=" + kSource + "/configs/legacy_posit_only.yaml" +
                           " --out=" + out.path());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find("handedness"), std::string::npos) << r.err;
  std::ifstream rep(out.File("report.md"));
  std::stringstream ss;
  ss << rep.rdbuf();
  EXPECT_NE(ss.str().find("does not refine"), std::string::npos);
  EXPECT_EQ(ss.str().find("| bundle adjustment (view dirs)"), std::string::npos);
}

TEST_F(BadInput, NumThreadsBelowOneNamesTheLine) {
  config_ = "name: c\nnum_threads: 0\n";
  ExpectError("config.yaml:2: key 'num_threads': expected an integer >= 1");
}

TEST_F(BadInput, NonPositiveSigma) {
  problem_ = "name: x\ncamera: camera.json\nsigma_px: -1\n"
             "markers: {file: markers.csv, sigma_mm: 0.2}\n"
             "observations: {file: obs.csv, format: long}\n";
  ExpectError("key 'sigma_px': expected a positive number");
}

TEST(Cli, HelpListsCommandsAndFlags) {
  const auto r = RunCarmba("help");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.out.find("solve"), std::string::npos);
  const auto h = RunCarmba("solve --help");
  EXPECT_EQ(h.exit_code, 0);
  EXPECT_NE(h.out.find("--problem"), std::string::npos);
  EXPECT_NE(h.out.find("--config"), std::string::npos);
  EXPECT_NE(h.out.find("--out"), std::string::npos);
  const auto u = RunCarmba("frobnicate");
  EXPECT_NE(u.exit_code, 0);
  EXPECT_NE(u.err.find("unknown command 'frobnicate'"), std::string::npos);
}

}  // namespace
}  // namespace carmba::test
