// --no-plots and --no-mrcal skip the Python parts and say so in the report; the numbers do not
// change; --verbose names every step with its wall time and ends with the total.
#include <gtest/gtest.h>

#include <fstream>
#include <regex>
#include <sstream>
#include <string>

#include "cli_test_util.h"

namespace carmba::test {
namespace {


// Every line of `err` that is not a warning is a step ("carmba CMD: what"), a step's time
// ("carmba CMD: what: 0.123 s") or the total, and the last line is the total.
void ExpectTimedSteps(const std::string& cmd, const std::string& err, int min_steps) {
  const std::regex timed("carmba " + cmd + ": .+: [0-9]+\\.[0-9]{3} s");
  const std::regex total("carmba " + cmd + ": total [0-9]+\\.[0-9]{3} s");
  std::istringstream in(err);
  int timed_steps = 0;
  std::string line, last;
  while (std::getline(in, line)) {
    if (line.empty() || line.rfind("carmba " + cmd + ": warning: ", 0) == 0) continue;
    if (line.rfind(cmd + ": ", 0) == 0) continue;  // a progress line ("solve: initial poses: ...")
    EXPECT_EQ(line.rfind("carmba " + cmd + ": ", 0), 0u) << line;
    if (std::regex_match(line, timed)) ++timed_steps;
    last = line;
  }
  EXPECT_GE(timed_steps, min_steps) << err;
  EXPECT_TRUE(std::regex_match(last, total)) << last;
}

// result.json without its run times (they differ from run to run).
nlohmann::json WithoutTimes(nlohmann::json j) {
  if (j.is_object()) {
    for (auto it = j.begin(); it != j.end();) {
      const std::string& k = it.key();
      if (k == "time_s" || k == "seconds" || k.find("_seconds") != std::string::npos) {
        it = j.erase(it);
      } else {
        *it = WithoutTimes(*it);
        ++it;
      }
    }
  } else if (j.is_array()) {
    for (auto& v : j) v = WithoutTimes(v);
  }
  return j;
}

TEST(SkipAndSteps, SolveWithoutPlotsGivesTheSameResultAndSaysSo) {
  ScratchDir dir;
  const std::string base = "solve --problem " + kSource + "/problems/thesis_pose.yaml --config " +
                           kSource + "/configs/posit_ba_analytic.yaml --out ";
  auto with = RunCarmba(base + dir.File("with"));
  ASSERT_EQ(with.exit_code, 0) << with.err;
  auto without = RunCarmba(base + dir.File("without") + " --no-plots --verbose");
  ASSERT_EQ(without.exit_code, 0) << without.err;
  EXPECT_EQ(WithoutTimes(ReadJsonFile(dir.File("with/result.json"))),
            WithoutTimes(ReadJsonFile(dir.File("without/result.json"))));
  const std::string html = ReadTextFile(dir.File("without/report.html"));
  EXPECT_NE(html.find("Plots not drawn (--no-plots)"), std::string::npos);
  EXPECT_EQ(html.find("data:image/png;base64"), std::string::npos);
  EXPECT_EQ(without.err.find("warning: report.html"), std::string::npos) << without.err;
  ExpectTimedSteps("solve", without.err, 4);
}

TEST(SkipAndSteps, JointSolveWithoutMrcalSaysSo) {
  ScratchDir dir;
  const std::string scene = dir.File("scene");
  ASSERT_EQ(SimulateJointScene("thesis_joint.yaml", scene), "");
  std::string problem = ReadTextFile(kSource + "/problems/thesis_joint.yaml");
  const std::string shipped = "../out/sim/joint";
  for (size_t p = problem.find(shipped); p != std::string::npos; p = problem.find(shipped, p)) {
    problem.replace(p, shipped.size(), scene);
  }
  dir.Write("problem.yaml", problem);
  auto r = RunCarmba("solve --problem " + dir.File("problem.yaml") + " --config " + kSource +
                     "/configs/joint_radial.yaml --out " + dir.File("out") +
                     " --no-mrcal --no-plots --verbose");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = ReadJsonFile(dir.File("out/result.json"));
  EXPECT_EQ(j.at("mrcal_crosscheck").at("error"), "disabled (--no-mrcal)");
  EXPECT_NE(ReadTextFile(dir.File("out/report.md")).find("Not run: disabled (--no-mrcal)."),
            std::string::npos);
  EXPECT_EQ(r.err.find("mrcal cross-check"), std::string::npos) << r.err;
  ExpectTimedSteps("solve", r.err, 3);
}

TEST(SkipAndSteps, CalibrateWithoutPlotsAndMrcalRunsNoPython) {
  ScratchDir dir;
  ASSERT_TRUE(WriteSyntheticGridObservations(dir.File("obs.csv")));
  // A python that does not exist: nothing may try to start it.
  auto r = RunCarmba("calibrate --observations " + dir.File("obs.csv") +
                     " --mrcal-python /nonexistent/python3 --no-plots --no-mrcal --verbose --out " +
                     dir.File("out"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir.File("out/mrcal")));
  EXPECT_EQ(r.err.find("nonexistent"), std::string::npos) << r.err;
  EXPECT_NE(ReadTextFile(dir.File("out/report.html")).find("Plots not drawn (--no-plots)"),
            std::string::npos);
  ExpectTimedSteps("calibrate", r.err, 3);
}

// Commands without a cross-check or plots print their steps too.
TEST(SkipAndSteps, ExportGeometryNamesItsSteps) {
  ScratchDir dir;
  auto r = RunCarmba("solve --problem " + kSource + "/problems/thesis_pose.yaml --config " +
                     kSource + "/configs/posit_ba_analytic.yaml --no-plots --out " +
                     dir.File("solve"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = RunCarmba("export-geometry --result " + dir.File("solve") +
                " --format json --verbose --out " + dir.File("export"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ExpectTimedSteps("export-geometry", r.err, 3);
}

}  // namespace
}  // namespace carmba::test
