// The --out contract, the same for every command that writes (util/file_util.h CheckOutputDir /
// CheckOutputFile / StagedOutputDir, cli/common_flags.h CheckOutDir / CheckOutFile):
//   - missing parent directories are created;
//   - an existing result (a non-empty output directory, an existing output file) is refused with
//     one line naming the path and --force, and left as it was;
//   - --force writes over it;
//   - a run that fails leaves neither output nor the parent directories it would have created.
// And progress: a bar on a terminal only, lines with --verbose in a pipe, nothing otherwise.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>

#include "synthetic/synthetic_views.h"
#include "cli_test_util.h"
#include "detect/observations.h"
#include "util/file_util.h"

namespace carmba::test {
namespace {

namespace fs = std::filesystem;

std::string ContentsOrMissing(const std::string& p) {
  auto s = ReadFile(p);
  return s.ok() ? *s : "<missing " + p + ">";
}

class OutContract : public ::testing::Test {
 protected:
  // Shared inputs, made once: simulated plate images and a simulated CT series.
  static void SetUpTestSuite() {
    data_ = new ScratchDir();
    const std::string err = SimulatePlateAndCt(*data_);
    ASSERT_EQ(err, "");
    data_->Write("camera.json",
                 R"({"image_size": [408, 408], "fx": 2061.4, "fy": 2254.6, "cx": 203.7,)"
                 R"( "cy": 205.1, "distortion": [0, 0, 0, 0, 0]})");
    data_->Write("markers.csv",
                 "id,x_mm,y_mm,z_mm\n1,0,0,0\n2,-58.85,1,14\n3,13.35,1,14\n4,-8.25,-20.5,24\n"
                 "5,-56.05,19,31\n");
    data_->Write("obs.csv",
                 "view,marker,u_px,v_px\na,1,230.0,210.0\na,2,54.1,214.5\na,3,269.0,214.7\n"
                 "a,4,183.1,145.2\na,5,63.0,267.2\n");
    data_->Write("problem.yaml",
                 "name: out_test\ncamera: camera.json\nsigma_px: 0.5\n"
                 "markers: {file: markers.csv, sigma_mm: 0.2}\n"
                 "observations: {file: obs.csv, format: long}\n");
    data_->Write("config.yaml", "name: c\ninitializer: posit\n");
    data_->Write("study.yaml",
                 "name: contract\ntrials: 1\nbase_seed: 3\nproblems:\n  - name: sim\n"
                 "    synthetic: {camera: " + kSource + "/data/thesis/camera.json, markers: "
                 "thesis}\nconfigs:\n  - {name: c, file: " + kSource +
                 "/configs/posit_ba_analytic.yaml}\n");
    ASSERT_TRUE(WriteSyntheticGridObservations(data_->File("grid_obs.csv")));
    // The study-merge contract's input (its plots are not looked at).
    auto r = RunCarmba("study --no-plots --study " + data_->File("study.yaml") +
                       " --shard 1/1 --out " + data_->File("shard1"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  static void TearDownTestSuite() {
    delete data_;
    data_ = nullptr;
  }

  // Runs `args(out)` into a fresh out under missing parents, again (refused), again with --force.
  // `probe` is a file of the result (relative to out for directories, or out itself).
  void ExpectContract(const std::string& cmd,
                      const std::function<std::string(const std::string&)>& args,
                      const std::string& out_name,
                      const std::string& probe) {
    SCOPED_TRACE(cmd);
    ScratchDir root;
    const std::string out = root.File("missing/parents/" + out_name);
    auto r = RunCarmba(cmd + " " + args(out));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const std::string probe_path = probe.empty() ? out : out + "/" + probe;
    ASSERT_TRUE(fs::exists(probe_path)) << probe_path;
    const std::string before = ContentsOrMissing(probe_path);

    r = RunCarmba(cmd + " " + args(out));
    EXPECT_EQ(r.exit_code, 1);
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_EQ(r.err.rfind("carmba " + cmd + ": error: --out " + out + ": ", 0), 0u) << r.err;
    EXPECT_NE(r.err.find("--force"), std::string::npos) << r.err;
    EXPECT_EQ(ContentsOrMissing(probe_path), before);

    r = RunCarmba(cmd + " " + args(out) + " --force");
    EXPECT_EQ(r.exit_code, 0) << r.err;
    EXPECT_TRUE(fs::exists(probe_path));
    for (const auto& e : fs::recursive_directory_iterator(root.path())) {
      const std::string n = e.path().filename().string();
      EXPECT_EQ(n.find(".carmba-"), std::string::npos) << e.path();
      EXPECT_EQ(n.find(".tmp."), std::string::npos) << e.path();
    }
  }

  static ScratchDir* data_;
};

ScratchDir* OutContract::data_ = nullptr;

TEST_F(OutContract, Calibrate) {
  ExpectContract(
      "calibrate",
      [](const std::string& out) {
        return "--no-mrcal --no-opencv --observations " + data_->File("grid_obs.csv") +
               " --out " + out;
      },
      "calib", "camera.json");
}

TEST_F(OutContract, Detect) {
  ExpectContract(
      "detect",
      [](const std::string& out) {
        return "--images '" + data_->File("plate") + "/calib_00[12].png' --out " + out;
      },
      "obs.csv", "");
}

TEST_F(OutContract, Solve) {
  ExpectContract(
      "solve",
      [](const std::string& out) {
        return "--problem " + data_->File("problem.yaml") + " --config " +
               data_->File("config.yaml") + " --out " + out;
      },
      "pose", "result.json");
}

TEST_F(OutContract, Simulate) {
  ExpectContract(
      "simulate",
      [](const std::string& out) {
        return "--scene " + kSource + "/configs/scenes/thesis_pose.yaml --out " + out;
      },
      "sim", "truth.json");
}

TEST_F(OutContract, Study) {
  ExpectContract(
      "study",
      [](const std::string& out) {
        return "--no-plots --study " + data_->File("study.yaml") + " --jobs 1 --out " + out;
      },
      "study",
      "summary.md");
}

TEST_F(OutContract, StudyMerge) {
  ExpectContract(
      "study-merge",
      [](const std::string& out) {
        return "--no-plots --shards " + data_->File("shard1") + " --out " + out;
      },
      "merged",
      "runs.jsonl");
}

TEST_F(OutContract, CtFiducials) {
  ExpectContract(
      "ct-fiducials",
      [](const std::string& out) {
        return "--no-plots --dicom " + data_->File("ct/ct") + " --expected 9 --out " + out;
      },
      "fiducials.csv",
      "");
}

// A run that fails after its --out was checked leaves no output and no new parent directory.
TEST_F(OutContract, FailedRunCreatesNothing) {
  ScratchDir root;
  root.Write("bad_config.yaml", "name: c\ninitializer: nonsense\n");
  auto r = RunCarmba("solve --problem " + data_->File("problem.yaml") + " --config " +
                     root.File("bad_config.yaml") + " --out " + root.File("a/b/out"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_FALSE(fs::exists(root.File("a"))) << r.err;
  r = RunCarmba("calibrate --no-mrcal --no-opencv --observations " + root.File("none.csv") +
                " --out " + root.File("c/d/out"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_FALSE(fs::exists(root.File("c"))) << r.err;
  r = RunCarmba("detect --images " + root.File("none") + " --out " + root.File("e/f/obs.csv"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_FALSE(fs::exists(root.File("e"))) << r.err;
}

// study: an existing study is continued with --resume or started over with --force.
TEST_F(OutContract, StudyResumeOrForce) {
  ScratchDir root;
  const std::string out = root.File("s");
  const std::string args =
      "study --no-plots --study " + data_->File("study.yaml") + " --jobs 1 --out " + out;
  ASSERT_EQ(RunCarmba(args).exit_code, 0);
  auto r = RunCarmba(args);
  EXPECT_NE(r.err.find("pass --resume to continue that study, --force to start it over"),
            std::string::npos)
      << r.err;
  r = RunCarmba(args + " --resume");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("already done"), std::string::npos);
  r = RunCarmba(args + " --force");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find(" 0 already done"), std::string::npos) << r.out;
  r = RunCarmba(args + " --force --resume");
  EXPECT_EQ(r.exit_code, 2);  // a usage error (cli/command.h kExitUsage)
  EXPECT_NE(r.err.find("give one of them"), std::string::npos) << r.err;
}

// Progress per image: nothing in a pipe, a line per image with --verbose, a bar on a terminal.
TEST_F(OutContract, CalibrateProgress) {
  ScratchDir root;
  const std::string base = "calibrate --no-mrcal --no-opencv --no-plots --images '" +
                           data_->File("plate") + "/*.png' --out ";
  auto r = RunCarmba(base + root.File("quiet"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // Only the calibration's warnings (correlated intrinsics), no progress.
  std::istringstream lines(r.err);
  for (std::string l; std::getline(lines, l);) {
    EXPECT_EQ(l.rfind("carmba calibrate: warning: ", 0), 0u) << l;
  }
  EXPECT_EQ(r.err.find("detecting"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find('\r'), std::string::npos) << r.err;
  r = RunCarmba(base + root.File("verbose") + " --verbose");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find('\r'), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("calibrate: detecting: 1/20 images done"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("calibrate: detecting: 20/20 images done"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("carmba calibrate: bundle adjustment over 20 views"), std::string::npos);
  if (!fs::exists("/usr/bin/script")) GTEST_SKIP() << "no /usr/bin/script to provide a terminal";
  // script(1) runs the command on a pseudo-terminal (stdout and stderr both go to it).
  const std::string cmd = "/usr/bin/script -qec \"" + std::string(CARMBA_BIN) + " " + base +
                          root.File("tty") + "\" /dev/null";
  const std::string log = root.File("tty.log");
  ASSERT_EQ(std::system((cmd + " > " + log + " 2>&1").c_str()), 0);
  const std::string tty = ContentsOrMissing(log);
  EXPECT_NE(tty.find("\rcalibrate: detecting ["), std::string::npos) << tty;
  EXPECT_NE(tty.find("] 20/20 images 100%"), std::string::npos) << tty;
}

}  // namespace
}  // namespace carmba::test
