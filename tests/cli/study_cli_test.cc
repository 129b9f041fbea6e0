// End-to-end tests of `carmba study` and `carmba study-merge` with the pose solver: a study killed
// by a signal and resumed, --jobs 1 vs --jobs 2, shards merged, failed runs (the study goes on,
// then exits 1 unless allowed), bad study files, resume and merge refusing a changed study, and
// the shipped studies parse and run.
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "scratch.h"
#include "util/file_util.h"

extern char** environ;

namespace carmba {
namespace {

const std::string kSrc = CARMBA_SOURCE_DIR;
const std::string kBin = CARMBA_BIN;

std::string Read(const std::string& path) {
  StatusOr<std::string> s = ReadFile(path);
  return s.ok() ? *s : "<missing " + path + ">";
}

struct Result {
  int code = -1;
  std::string out, err;
};

// Runs a shell command and captures its exit code, stdout and stderr.
Result Shell(const std::string& command, const std::string& dir) {
  const std::string cmd = command + " > '" + dir + "/cmd.out' 2> '" + dir + "/cmd.err'";
  Result r;
  const int status = std::system(cmd.c_str());
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.out = Read(dir + "/cmd.out");
  r.err = Read(dir + "/cmd.err");
  return r;
}

// Runs `carmba args...`.
Result Carmba(const std::string& args, const std::string& dir) {
  return Shell("'" + kBin + "' " + args, dir);
}

// `carmba study` without the plots (the tests below do not look at them; ShippedStudiesRun does).
const std::string kStudyNoPlots = "study --no-plots --study=";

// The shipped solver config `name`. The equality tests need bitwise-reproducible solves; the pose
// solver keeps all parameter blocks in one buffer (Ceres orders blocks by address), so the shipped
// dense-Schur configs are reproducible across threads and processes.
std::string ShippedConfig(const std::string& name) { return kSrc + "/configs/" + name + ".yaml"; }

// A study of the simulated thesis object: 2 configs x 2 pixel noises x `trials`.
std::string WriteStudy(const std::string& dir, int trials, const std::string& extra_problems = "",
                       const std::string& extra_configs = "") {
  const std::string path = dir + "/study.yaml";
  const std::string posit = ShippedConfig("posit_ba_analytic");
  const std::string sqpnp = ShippedConfig("sqpnp_ba_analytic");
  std::ofstream(path) << "name: cli_study\ntrials: " << trials
                      << "\nbase_seed: 3\nproblems:\n"
                         "  - name: sim\n    synthetic:\n      camera: "
                      << kSrc << "/data/thesis/camera.json\n      markers: thesis\n"
                      << extra_problems << "configs:\n  - {name: posit_ba, file: " << posit
                      << "}\n  - {name: sqpnp_ba, file: " << sqpnp << "}\n"
                      << extra_configs << "sweeps:\n  pixel_noise_px: [0.2, 1.0]\n";
  return path;
}

// summary.csv and summary.md, whole: neither holds a wall-clock number (study/summary.h).
std::string Summaries(const std::string& out) {
  return Read(out + "/summary.csv") + "\n----\n" + Read(out + "/summary.md");
}

std::vector<std::string> Keys(const std::string& out) {
  std::vector<std::string> keys;
  std::istringstream in(Read(out + "/runs.jsonl"));
  std::string line;
  while (std::getline(in, line)) {
    nlohmann::json j = nlohmann::json::parse(line, nullptr, false);
    keys.push_back(j.is_discarded() ? "<bad line>" : j.value("key", "<no key>"));
  }
  std::sort(keys.begin(), keys.end());
  return keys;
}

int CountLines(const std::string& path) {
  const std::string s = Read(path);
  return static_cast<int>(std::count(s.begin(), s.end(), '\n'));
}

TEST(StudyCliTest, KilledStudyResumesWithEveryRunOnce) {
  const test::ScratchDir scratch("study_cli");  // removed when it goes
  const std::string& dir = scratch.path();
  const std::string study = WriteStudy(dir, 150);  // 600 runs of a few ms
  const std::string out = dir + "/killed";
  std::vector<std::string> args = {kBin, "study", "--study=" + study, "--out=" + out, "--jobs=2"};
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  ASSERT_EQ(::posix_spawn(&pid, kBin.c_str(), nullptr, nullptr, argv.data(), environ), 0);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (CountLines(out + "/runs.jsonl") < 150 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, WNOHANG), 0) << "the study ended before it was killed";
  ASSERT_EQ(::kill(pid, SIGTERM), 0);
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  EXPECT_TRUE(WIFSIGNALED(status));
  const int done = CountLines(out + "/runs.jsonl");
  EXPECT_GE(done, 150);
  EXPECT_LT(done, 600);
  EXPECT_FALSE(FileExists(out + "/summary.md"));

  // Without --resume the directory is refused; with it the study completes.
  Result r = Carmba(kStudyNoPlots + study + " --out=" + out + " --jobs=2", dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("pass --resume"), std::string::npos) << r.err;
  r = Carmba(kStudyNoPlots + study + " --out=" + out + " --jobs=2 --resume", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  const std::vector<std::string> keys = Keys(out);
  ASSERT_EQ(keys.size(), 600u);
  EXPECT_EQ(std::set<std::string>(keys.begin(), keys.end()).size(), 600u);

  r = Carmba(kStudyNoPlots + study + " --out=" + dir + "/clean --jobs=2", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(Summaries(out), Summaries(dir + "/clean"));
  EXPECT_EQ(Keys(out), Keys(dir + "/clean"));
}

TEST(StudyCliTest, JobsAndMergedShardsGiveIdenticalSummaries) {
  const test::ScratchDir scratch("study_cli");  // removed when it goes
  const std::string& dir = scratch.path();
  const std::string study = WriteStudy(dir, 15);
  const std::string s = kStudyNoPlots + study + " --out=" + dir;
  for (const std::string& a : {s + "/j1 --jobs=1",
                               s + "/j2 --jobs=2",
                               s + "/shard1 --jobs=2 --shard=1/2",
                               s + "/shard2 --jobs=1 --shard=2/2"}) {
    const Result r = Carmba(a, dir);
    ASSERT_EQ(r.code, 0) << a << "\n" << r.err;
  }
  EXPECT_EQ(Summaries(dir + "/j1"), Summaries(dir + "/j2"));
  EXPECT_EQ(Keys(dir + "/j1"), Keys(dir + "/j2"));
  EXPECT_EQ(CountLines(dir + "/shard1/runs.jsonl"), 30);
  Result r = Carmba("study-merge --out=" + dir + "/merged --shards='" + dir + "/shard*'", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("merged 60 runs from 2 shard directories"), std::string::npos) << r.out;
  EXPECT_EQ(Summaries(dir + "/merged"), Summaries(dir + "/j1"));
  EXPECT_EQ(Keys(dir + "/merged"), Keys(dir + "/j1"));
  EXPECT_TRUE(FileExists(dir + "/merged/report.html"));
  // The summaries carry real pose statistics: errors and reported vs empirical sigma.
  const std::string csv = Read(dir + "/j1/summary.csv");
  EXPECT_NE(csv.find(",error,rotation_deg,15,"), std::string::npos) << csv;
  EXPECT_NE(csv.find(",signed,v0_rx_deg,15,"), std::string::npos) << csv;
  // One shard alone is incomplete: refused unless asked for.
  r = Carmba("study-merge --out=" + dir + "/half --shards=" + dir + "/shard1", dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("30 of the 60 runs"), std::string::npos) << r.err;
  EXPECT_FALSE(FileExists(dir + "/half/summary.md"));
  r = Carmba("study-merge --out=" + dir + "/half --shards=" + dir + "/nowhere*", dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("matches no directory"), std::string::npos) << r.err;
}

TEST(StudyCliTest, MissingProblemAndInvalidConfigKeyFailOnlyTheirRuns) {
  const test::ScratchDir scratch("study_cli");  // removed when it goes
  const std::string& dir = scratch.path();
  std::ofstream(dir + "/typo.yaml") << "name: typo\ninitializer: posit\nmax_iteration: 10\n";
  const std::string study =
      WriteStudy(dir, 3, "  - {name: lost, file: no_such_problem.yaml}\n",
                 "  - {name: typo, file: typo.yaml}\n");
  Result r = Carmba(kStudyNoPlots + study + " --out=" + dir + "/out --jobs=2", dir);
  // A study with failed runs is a failed study (exit 1, data failure), after writing its
  // summaries; the message counts them and gives the reasons, most frequent first.
  ASSERT_EQ(r.code, 1) << r.err;
  // 2 problems x 3 configs x 2 noises x 3 trials = 36 runs; lost: 18 fail, typo on sim: 6 fail.
  EXPECT_NE(r.out.find("36 runs"), std::string::npos) << r.out;
  EXPECT_NE(r.err.find("24 of 36 runs failed: '"), std::string::npos) << r.err;
  // The lost problem fails with each good config (12 runs), the typo config with each problem
  // (12 runs; its error comes first in the lost problem's runs too). Ties: the earliest run's
  // reason first (sim|typo comes before lost|...).
  const size_t typo_reason = r.err.find("max_iteration'; did you mean 'max_iterations'?");
  const size_t lost_reason = r.err.find("no_such_problem.yaml: cannot open file' (12 runs)");
  EXPECT_NE(typo_reason, std::string::npos) << r.err;
  EXPECT_NE(lost_reason, std::string::npos) << r.err;
  EXPECT_LT(typo_reason, lost_reason) << r.err;
  EXPECT_NE(r.err.find("no failed run allowed"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  // An expected failure rate: 24/36 = 0.67 is within 0.7, not within 0.5.
  r = Carmba(kStudyNoPlots + study + " --out=" + dir + "/out --resume --allow-failures=0.7",
             dir);
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("warning: 24 of 36 runs failed"), std::string::npos) << r.err;
  r = Carmba(kStudyNoPlots + study + " --out=" + dir + "/out --resume --allow-failures=0.5",
             dir);
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_NE(r.err.find("allowed: 0.5 of the runs"), std::string::npos) << r.err;
  r = Carmba(kStudyNoPlots + study + " --out=" + dir + "/out --resume --allow-failures=2", dir);
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_NE(r.err.find("--allow-failures: expected a fraction 0 .. 1, got 2"), std::string::npos)
      << r.err;
  // The same allowance as a key of the study file.
  std::ofstream(dir + "/allowed.yaml") << "allow_failures: 0.7\n" << Read(study);
  r = Carmba(kStudyNoPlots + dir + "/allowed.yaml --out=" + dir + "/allowed --jobs=2", dir);
  EXPECT_EQ(r.code, 0) << r.err;
  const std::string md = Read(dir + "/out/summary.md");
  EXPECT_NE(md.find("no_such_problem.yaml"), std::string::npos) << md;
  EXPECT_NE(md.find("max_iteration"), std::string::npos) << md;
  const std::string csv = Read(dir + "/out/summary.csv");
  EXPECT_NE(csv.find("sim,posit_ba,0.2,3,0,error,rotation_deg,3,"), std::string::npos) << csv;
  EXPECT_NE(csv.find("sim,typo,0.2,3,3,runs,-,0"), std::string::npos) << csv;
}

TEST(StudyCliTest, BadStudyFilesFailWithOneLineAndNoOutput) {
  const test::ScratchDir scratch("study_cli");  // removed when it goes
  const std::string& dir = scratch.path();
  std::ofstream(dir + "/bad.yaml") << "trials: 2\nproblems: []\nconfigs:\n  - {name: c, file: c}\n";
  Result r = Carmba(kStudyNoPlots + dir + "/bad.yaml --out=" + dir + "/out", dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("bad.yaml: key 'problems': expected at least one problem"),
            std::string::npos)
      << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1);
  EXPECT_FALSE(FileExists(dir + "/out"));
  // Usage errors (a bad flag value, a missing flag) exit 2 (cli/command.h kExitUsage).
  r = Carmba(kStudyNoPlots + WriteStudy(dir, 1) + " --out=" + dir + "/out --shard=3/2", dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("expected K/N"), std::string::npos) << r.err;
  r = Carmba("study --out=" + dir + "/out", dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("--study is required"), std::string::npos) << r.err;
  // A sweep the pose runs do not understand fails every run, naming it.
  std::ofstream(dir + "/sweep.yaml")
      << "trials: 1\nproblems:\n  - name: sim\n    synthetic: {camera: " << kSrc
      << "/data/thesis/camera.json, markers: thesis}\nconfigs:\n  - {name: c, file: " << kSrc
      << "/configs/posit_ba_analytic.yaml}\nsweeps:\n  exposure_ms: [1, 2]\n";
  r = Carmba(kStudyNoPlots + dir + "/sweep.yaml --out=" + dir + "/sweep", dir);
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_NE(r.err.find("2 of 2 runs failed"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("sweep variable 'exposure_ms' is not understood"), std::string::npos)
      << r.err;
  EXPECT_NE(Read(dir + "/sweep/summary.md").find("sweep variable 'exposure_ms' is not understood"),
            std::string::npos);
  // A misspelt top-level key is named, with the key meant among the known ones.
  std::string typo = Read(dir + "/sweep.yaml");
  typo.replace(typo.find("sweeps:"), 7, "sweps:");
  std::ofstream(dir + "/sweps.yaml") << typo;
  r = Carmba(kStudyNoPlots + dir + "/sweps.yaml --out=" + dir + "/sweps", dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("unknown key 'sweps'; did you mean 'sweeps'?"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find(", sweeps, "), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("base_seed"), std::string::npos) << r.err;
  EXPECT_FALSE(FileExists(dir + "/sweps"));
}

// A study of the simulated thesis object with a copy of a shipped config in `dir` (c.yaml) and
// a copy of the camera (camera.json), which the tests edit.
std::string WriteEditableStudy(const std::string& dir) {
  std::ofstream(dir + "/c.yaml") << Read(ShippedConfig("posit_ba_analytic"));
  std::ofstream(dir + "/camera.json") << Read(kSrc + "/data/thesis/camera.json");
  std::ofstream(dir + "/edit.yaml")
      << "trials: 3\nproblems:\n  - name: sim\n    synthetic: {camera: camera.json, markers: "
         "thesis}\nconfigs:\n  - {name: c, file: c.yaml}\nsweeps:\n  pixel_noise_px: [0.2, 1]\n";
  return dir + "/edit.yaml";
}

// --resume continues only the same study: an edited config or data file is named and refused,
// whatever the run list.
TEST(StudyCliTest, ResumeRefusesAStudyWhoseFilesChanged) {
  const test::ScratchDir scratch("study_cli");  // removed when it goes
  const std::string& dir = scratch.path();
  const std::string study = WriteEditableStudy(dir);
  const std::string s = kStudyNoPlots + study + " --out=" + dir + "/out";
  Result r = Carmba(s, dir);
  ASSERT_EQ(r.code, 0) << r.err;
  const std::string runs = Read(dir + "/out/runs.jsonl");
  r = Carmba(s + " --resume", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("6 already done, 0 run now"), std::string::npos) << r.out;
  std::ofstream(dir + "/c.yaml", std::ios::app) << "# edited\n";
  r = Carmba(s + " --resume", dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("the study changed since these runs were recorded: " + dir +
                       "/c.yaml (config 'c') has different content"),
            std::string::npos)
      << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_EQ(Read(dir + "/out/runs.jsonl"), runs);
  std::ofstream(dir + "/c.yaml") << Read(ShippedConfig("posit_ba_analytic"));
  r = Carmba(s + " --resume", dir);
  EXPECT_EQ(r.code, 0) << r.err;
  // A data file a synthetic problem reads (its camera) counts the same.
  std::ofstream(dir + "/camera.json", std::ios::app) << "\n";
  r = Carmba(s + " --resume", dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find(dir + "/camera.json (problem 'sim') has different content"),
            std::string::npos)
      << r.err;
  const std::string info = Read(dir + "/out/study.json");
  EXPECT_NE(info.find("\"carmba_version\""), std::string::npos) << info;
}

// study-merge refuses shards solved with different configs, naming the config.
TEST(StudyCliTest, MergeRefusesShardsOfDifferentConfigs) {
  const test::ScratchDir scratch("study_cli");  // removed when it goes
  const std::string& dir = scratch.path();
  const std::string study = WriteEditableStudy(dir);
  const std::string s = kStudyNoPlots + study + " --out=" + dir;
  Result r = Carmba(s + "/shard-1 --shard=1/2", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  std::string config = Read(dir + "/c.yaml");
  const size_t pos = config.find("max_iterations:");
  ASSERT_NE(pos, std::string::npos) << config;
  config.replace(pos, config.find('\n', pos) - pos, "max_iterations: 7");
  std::ofstream(dir + "/c.yaml") << config;
  r = Carmba(s + "/shard-2 --shard=2/2", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  r = Carmba("study-merge --out=" + dir + "/merged --shards='" + dir + "/shard-*'", dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find(dir + "/shard-2/study.json: not the study of " + dir + "/shard-1: " + dir +
                       "/c.yaml (config 'c') has different content; expected shards of one study"),
            std::string::npos)
      << r.err;
  EXPECT_FALSE(FileExists(dir + "/merged"));
}

// The progress bar (runs done, ETA; util/progress.h) goes to stderr only when stderr is a
// terminal; in a pipe there is none, and --verbose gives one line per run instead.
TEST(StudyCliTest, ProgressLineOnlyOnATerminal) {
  const test::ScratchDir scratch("study_cli");  // removed when it goes
  const std::string& dir = scratch.path();
  const std::string study = WriteStudy(dir, 5);
  Result r = Carmba(kStudyNoPlots + study + " --out=" + dir + "/plain --jobs=2", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(r.err.find("runs"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find('\r'), std::string::npos) << r.err;
  r = Carmba(kStudyNoPlots + study + " --out=" + dir + "/verbose --jobs=2 --verbose", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("20/20 runs done"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find('\r'), std::string::npos) << r.err;
  if (!FileExists("/usr/bin/script")) GTEST_SKIP() << "no /usr/bin/script to provide a terminal";
  // script(1) runs the command on a pseudo-terminal.
  r = Shell("/usr/bin/script -qec \"'" + kBin + "' study --no-plots --study=" + study +
                " --out=" + dir + "/tty --jobs=2\" /dev/null",
            dir);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("] 20/20 runs 100%"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\r"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("ETA"), std::string::npos) << r.out;
}

// The shipped studies parse, and one trial of each runs without failures.
TEST(StudyCliTest, ShippedStudiesRun) {
  for (const char* name : {"thesis_solvers", "noise_sweep", "calibration_sweep"}) {
    const std::string path = kSrc + "/configs/studies/" + name + ".yaml";
    // A copy with one trial per problem, in a temporary directory: its relative paths (relative
    // to configs/studies/) are made absolute.
    const test::ScratchDir scratch("study_cli");  // removed when it goes
    const std::string& dir = scratch.path();
    std::string one;
    std::istringstream in(Read(path));
    std::string line;
    while (std::getline(in, line)) {
      if (line.rfind("trials:", 0) == 0) line = "trials: 1";
      if (line.find("    trials:") == 0) continue;
      for (const auto& [rel, abs] : {std::pair<std::string, std::string>{"../../", kSrc + "/"},
                                     {"../", kSrc + "/configs/"}}) {
        for (size_t pos; (pos = line.find(" " + rel)) != std::string::npos;) {
          line.replace(pos + 1, rel.size(), abs);
        }
      }
      one += line + "\n";
    }
    const std::string copy = dir + "/" + name + ".yaml";
    std::ofstream(copy) << one;
    const Result r = Carmba("study --study=" + copy + " --out=" + dir + "/out --jobs=2", dir);
    ASSERT_EQ(r.code, 0) << r.err << "\n" << one;
    EXPECT_NE(r.out.find(", 0 failed in total"), std::string::npos) << r.out << r.err;
    EXPECT_TRUE(FileExists(dir + "/out/report.html"));
  }
}

}  // namespace
}  // namespace carmba
