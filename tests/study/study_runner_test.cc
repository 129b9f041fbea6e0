// The study runner against a real, cheap run function (mean_study.h): enumeration and seeds,
// the run log, --jobs independence, shards and merging, kill + resume, failures that do not stop
// a study, and the statistics of the summaries.
#include <gtest/gtest.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <thread>

#include "mean_study.h"
#include "study/runner.h"
#include "study/study_inputs.h"
#include "study/summary.h"
#include "scratch.h"
#include "util/file_util.h"

namespace carmba {
namespace {

void Write(const std::string& path, const std::string& text) {
  std::ofstream(path) << text;
}

std::string Read(const std::string& path) {
  StatusOr<std::string> s = ReadFile(path);
  return s.ok() ? *s : std::string("<missing " + path + ">");
}

int CountLines(const std::string& path) {
  const std::string s = Read(path);
  return static_cast<int>(std::count(s.begin(), s.end(), '\n'));
}

// A study directory with two problems, two estimators, a noise sweep and `trials` trials.
struct Fixture {
  test::ScratchDir scratch{"study"};  // removed with the fixture
  std::string dir = scratch.path();
  std::string study_path;
  explicit Fixture(int trials,
                   int repeat = 1,
                   const std::string& extra_problem = "",
                   const std::string& extra_config = "") {
    Write(dir + "/p_small.yaml", "true_mean: 3.0\nsamples: 20\n");
    Write(dir + "/p_large.yaml", "true_mean: -1.5\nsamples: 80\n");
    Write(dir + "/c_mean.yaml", "estimator: mean\nrepeat: " + std::to_string(repeat) + "\n");
    Write(dir + "/c_median.yaml", "estimator: median\nrepeat: " + std::to_string(repeat) + "\n");
    study_path = dir + "/study.yaml";
    Write(study_path,
          "name: mean_study\ntrials: " + std::to_string(trials) +
              "\nbase_seed: 7\n"
              "problems:\n  - {name: small, file: p_small.yaml}\n"
              "  - {name: large, file: p_large.yaml}\n" +
              extra_problem +
              "configs:\n  - {name: mean, file: c_mean.yaml}\n"
              "  - {name: median, file: c_median.yaml}\n" +
              extra_config + "sweeps:\n  noise_sd: [0.5, 2]\n");
  }
  StudySpec Spec() const {
    StatusOr<StudySpec> s = LoadStudySpec(study_path);
    EXPECT_TRUE(s.ok()) << s.status().message();
    return s.ok() ? *s : StudySpec();
  }
};

// Runs the study of testing::MeanRun; report.html without its plots (no matplotlib process) unless
// `plots` (ReportHasEveryPlotKind draws them).
Status RunMean(const StudySpec& spec, const std::string& out, int jobs, bool resume = false,
               int shard_k = 1, int shard_n = 1, StudyRunStats* stats = nullptr,
               bool plots = false) {
  StudyRunOptions o;
  o.out_dir = out;
  o.plots = plots;
  o.jobs = jobs;
  o.resume = resume;
  o.shard_k = shard_k;
  o.shard_n = shard_n;
  return RunStudy(spec, testing::MeanRun, o, stats);
}

// summary.csv and summary.md, whole: neither holds a wall-clock number (study/summary.h).
std::string Summaries(const std::string& out) {
  return Read(out + "/summary.csv") + "\n----\n" + Read(out + "/summary.md");
}

std::multiset<std::string> Keys(const std::string& out) {
  std::multiset<std::string> keys;
  std::istringstream in(Read(out + "/runs.jsonl"));
  std::string line;
  while (std::getline(in, line)) {
    keys.insert(nlohmann::json::parse(line).at("key").get<std::string>());
  }
  return keys;
}

TEST(StudySpecTest, LoadsAndEnumeratesDeterministically) {
  Fixture f(3);
  const StudySpec spec = f.Spec();
  ASSERT_EQ(spec.problems.size(), 2u);
  EXPECT_EQ(spec.problems[0].file, f.dir + "/p_small.yaml");  // relative to the study file
  const std::vector<RunSpec> runs = EnumerateRuns(spec);
  ASSERT_EQ(runs.size(), 2u * 2u * 2u * 3u);
  EXPECT_EQ(runs[0].key, "small|mean|noise_sd=0.5|trial=0");
  EXPECT_EQ(runs[3].key, "small|mean|noise_sd=2|trial=0");
  std::set<std::string> keys;
  std::set<uint64_t> seeds;
  for (const auto& r : runs) {
    keys.insert(r.key);
    seeds.insert(r.seed);
  }
  EXPECT_EQ(keys.size(), runs.size());
  // Paired design: the two configs share the data seeds (2 problems x 2 noises x 3 trials).
  EXPECT_EQ(seeds.size(), runs.size() / 2);
  EXPECT_EQ(runs[0].seed, runs[6].seed);  // small|mean|0.5|0 and small|median|0.5|0
  EXPECT_NE(runs[0].seed, runs[1].seed);
  // Seeds do not depend on anything but the base seed and the key.
  EXPECT_EQ(EnumerateRuns(f.Spec())[5].seed, runs[5].seed);
  const nlohmann::json identity = StudyIdentityJson(spec, runs, StudyInputFiles(spec));
  EXPECT_EQ(StudyIdentityJson(f.Spec(), EnumerateRuns(f.Spec()), StudyInputFiles(f.Spec())),
            identity);
}

TEST(StudySpecTest, ShardsPartitionTheRuns) {
  Fixture f(5);
  const StudySpec spec = f.Spec();
  const std::vector<RunSpec> runs = EnumerateRuns(spec);
  std::multiset<std::string> all;
  for (int k = 1; k <= 3; ++k) {
    for (const auto& r : ShardRuns(runs, k, 3)) all.insert(r.key);
  }
  EXPECT_EQ(all.size(), runs.size());
  EXPECT_EQ(std::set<std::string>(all.begin(), all.end()).size(), runs.size());
  int k = 0, n = 0;
  EXPECT_TRUE(ParseShard("2/8", &k, &n).ok());
  EXPECT_EQ(k, 2);
  EXPECT_EQ(n, 8);
  EXPECT_NE(ParseShard("9/8", &k, &n).message().find("expected K/N with 1 <= K <= N"),
            std::string::npos);
  EXPECT_FALSE(ParseShard("1/2x", &k, &n).ok());
  EXPECT_FALSE(ParseShard("0/2", &k, &n).ok());
}

// Bad study files, one corruption at a time, each with the expected message.
TEST(StudySpecTest, RejectsBadStudyFiles) {
  const test::ScratchDir scratch("study");  // removed when it goes
  const std::string& dir = scratch.path();
  const std::string base =
      "trials: 2\nproblems:\n  - {name: a, file: a.yaml}\nconfigs:\n  - {name: c, file: c.yaml}\n";
  struct Case {
    std::string text, expected;
  } cases[] = {
      {base + "colour: red\n", "unknown key"},
      {"problems:\n  - {name: a, file: a.yaml}\nconfigs:\n  - {name: c, file: c.yaml}\n",
       "key 'trials': missing"},
      {base + "sweeps:\n  noise_sd: []\n", "noise_sd"},
      {base + "sweeps:\n  noise_sd: [1, x]\n", "noise_sd"},
      {"trials: 0\n" + base.substr(base.find("problems")), "expected an integer >= 1"},
      {"trials: 2\nproblems:\n  - {name: a, file: a.yaml}\n  - {name: a, file: b.yaml}\n"
       "configs:\n  - {name: c, file: c.yaml}\n",
       "problem name 'a' is repeated"},
      {"trials: 2\nproblems:\n  - {name: a}\nconfigs:\n  - {name: c, file: c.yaml}\n",
       "exactly one of 'file' and 'synthetic'"},
      {"trials: 2\nproblems:\n  - {name: 'a|b', file: a.yaml}\nconfigs:\n  - {name: c, file: "
       "c.yaml}\n",
       "without | = ,"},
      {"trials: 2\nproblems:\n  - {name: a, file: a.yaml}\nconfigs:\n  - {name: c}\n",
       "key 'configs[0].file': missing"},
  };
  for (const auto& c : cases) {
    Write(dir + "/s.yaml", c.text);
    StatusOr<StudySpec> s = LoadStudySpec(dir + "/s.yaml");
    ASSERT_FALSE(s.ok()) << c.text;
    EXPECT_NE(s.status().message().find(c.expected), std::string::npos)
        << s.status().message() << "\nexpected: " << c.expected;
    EXPECT_NE(s.status().message().find("s.yaml"), std::string::npos) << s.status().message();
  }
  EXPECT_NE(LoadStudySpec(dir + "/none.yaml").status().message().find("cannot open"),
            std::string::npos);
}

TEST(RunLogTest, ToleratesAPartialLastLineAndDuplicates) {
  RunRecord a;
  a.index = 0;
  a.key = "p|c|-|trial=0";
  a.problem = "p";
  a.config = "c";
  a.ok = true;
  a.result = {{"values", {{"x", 1.5}}}};
  RunRecord b = a;
  b.index = 1;
  b.key = "p|c|-|trial=1";
  b.ok = false;
  b.error = "bad data";
  const std::string la = RunRecordToJson(a).dump() + "\n", lb = RunRecordToJson(b).dump() + "\n";
  int bad = -1, dup = -1;
  std::vector<RunRecord> r = ParseRunLog(la + lb + la + lb.substr(0, lb.size() / 2), &bad, &dup);
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(bad, 1);
  EXPECT_EQ(dup, 1);
  EXPECT_EQ(r[1].error, "bad data");
  // A complete line that is not JSON, or JSON without the members, counts as bad too.
  r = ParseRunLog(la + "{\"key\":1}\n" + "garbage\n", &bad, &dup);
  EXPECT_EQ(r.size(), 1u);
  EXPECT_EQ(bad, 2);
}

TEST(StudyRunnerTest, JobsDoNotChangeTheSummaries) {
  Fixture f(6);
  const StudySpec spec = f.Spec();
  StudyRunStats s1, s2;
  ASSERT_TRUE(RunMean(spec, f.dir + "/j1", 1, false, 1, 1, &s1).ok());
  ASSERT_TRUE(RunMean(spec, f.dir + "/j2", 2, false, 1, 1, &s2).ok());
  EXPECT_EQ(s1.executed, 48);
  EXPECT_EQ(s2.executed, 48);
  EXPECT_EQ(s2.jobs, 2);
  EXPECT_EQ(Summaries(f.dir + "/j1"), Summaries(f.dir + "/j2"));
  EXPECT_EQ(Keys(f.dir + "/j1"), Keys(f.dir + "/j2"));
  // The compared part is substantial: all 8 groups x their metrics.
  EXPECT_GT(CountLines(f.dir + "/j1/summary.csv"), 8 * 4);
  for (const char* file : {"summary.csv", "summary.md", "timing.csv", "report.html"}) {
    EXPECT_TRUE(FileExists(f.dir + "/j1/" + file)) << file;
  }
}

TEST(StudyRunnerTest, MergedShardsEqualTheWholeStudy) {
  Fixture f(5);
  const StudySpec spec = f.Spec();
  ASSERT_TRUE(RunMean(spec, f.dir + "/whole", 2).ok());
  ASSERT_TRUE(RunMean(spec, f.dir + "/s1", 1, false, 1, 2).ok());
  ASSERT_TRUE(RunMean(spec, f.dir + "/s2", 2, false, 2, 2).ok());
  EXPECT_EQ(CountLines(f.dir + "/s1/runs.jsonl") + CountLines(f.dir + "/s2/runs.jsonl"), 40);
  int merged = 0, missing = -1;
  ASSERT_TRUE(MergeStudyShards(
                  {f.dir + "/s2", f.dir + "/s1"}, f.dir + "/merged", true, false, &merged, &missing)
                  .ok());
  EXPECT_EQ(merged, 40);
  EXPECT_EQ(missing, 0);
  EXPECT_EQ(Summaries(f.dir + "/merged"), Summaries(f.dir + "/whole"));
  EXPECT_EQ(Keys(f.dir + "/merged"), Keys(f.dir + "/whole"));
  // A shard alone is incomplete: refused, or merged when missing runs are allowed.
  Status s = MergeStudyShards({f.dir + "/s1"}, f.dir + "/half", false, false, &merged, &missing);
  EXPECT_NE(s.message().find("20 of the 40 runs"), std::string::npos) << s.message();
  EXPECT_FALSE(FileExists(f.dir + "/half/runs.jsonl"));
  ASSERT_TRUE(
      MergeStudyShards({f.dir + "/s1"}, f.dir + "/half", false, true, &merged, &missing).ok());
  EXPECT_EQ(missing, 20);
  // Shards of different studies are refused.
  Fixture g(4);
  ASSERT_TRUE(RunMean(g.Spec(), g.dir + "/other", 2).ok());
  s = MergeStudyShards({f.dir + "/s1", g.dir + "/other"}, f.dir + "/bad", false, true, &merged,
                       &missing);
  EXPECT_NE(s.message().find("expected shards of one study"), std::string::npos) << s.message();
  EXPECT_FALSE(FileExists(f.dir + "/bad/runs.jsonl"));
  // Merging into a directory that already holds runs is refused.
  s = MergeStudyShards({f.dir + "/s1"}, f.dir + "/whole", false, true, &merged, &missing);
  EXPECT_NE(s.message().find("already holds runs"), std::string::npos) << s.message();
}

TEST(StudyRunnerTest, RefusesToMixStudiesOrOverwrite) {
  Fixture f(2);
  ASSERT_TRUE(RunMean(f.Spec(), f.dir + "/out", 2).ok());
  Status s = RunMean(f.Spec(), f.dir + "/out", 2);
  EXPECT_NE(s.message().find("pass --resume"), std::string::npos) << s.message();
  // Resume of a complete study runs nothing and keeps the summaries.
  StudyRunStats st;
  const std::string before = Summaries(f.dir + "/out");
  ASSERT_TRUE(RunMean(f.Spec(), f.dir + "/out", 2, true, 1, 1, &st).ok());
  EXPECT_EQ(st.executed, 0);
  EXPECT_EQ(st.skipped, 16);
  EXPECT_EQ(Summaries(f.dir + "/out"), before);
  // Another study (3 trials) cannot resume this directory, nor can another shard.
  Fixture g(3);
  s = RunMean(g.Spec(), f.dir + "/out", 2, true);
  EXPECT_NE(s.message().find("the study changed since these runs were recorded: "),
            std::string::npos)
      << s.message();
  EXPECT_NE(s.message().find("expected the same study"), std::string::npos) << s.message();
  s = RunMean(f.Spec(), f.dir + "/out", 2, true, 1, 2);
  EXPECT_NE(s.message().find("holds shard 1/1 of study 'mean_study', not shard 1/2"),
            std::string::npos)
      << s.message();
  // The same study with an edited config: refused, naming the file.
  Write(f.dir + "/c_median.yaml", "estimator: median\nrepeat: 2\n");
  s = RunMean(f.Spec(), f.dir + "/out", 2, true);
  EXPECT_NE(s.message().find(f.dir + "/c_median.yaml (config 'median') has different content"),
            std::string::npos)
      << s.message();
}

// The inputs of a study: the entries' files, files named inside YAML files (recursively, relative
// to the naming file), files named in synthetic mappings; not strings that name nothing.
TEST(StudyInputsTest, FindsEveryFileTheRunsReadAndNamesWhatChanged) {
  Fixture f(2);
  ASSERT_TRUE(MakeDirs(f.dir + "/data/views").ok());
  Write(f.dir + "/data/markers.csv", "id,x,y,z\n1,0,0,0\n");
  Write(f.dir + "/data/nested.yaml", "camera: cam.json\n");
  Write(f.dir + "/data/cam.json", "{}\n");
  Write(f.dir + "/data/views/a.png", "a");
  Write(f.dir + "/data/views/b.png", "b");
  Write(f.dir + "/p_small.yaml", "true_mean: 3.0\nsamples: 20\nmarkers: data/markers.csv\n"
                                 "more: [data/nested.yaml, not_a_file.csv]\nimages: data/views\n");
  Write(f.dir + "/scene.yaml", "x: 1\n");
  std::string study = Read(f.study_path);
  study.replace(study.find("configs:"), 0,
                "  - {name: sim, synthetic: {scene: scene.yaml, markers: thesis}}\n");
  Write(f.study_path, study);
  const StudySpec spec = f.Spec();
  std::map<std::string, std::string> used_by;
  for (const StudyInput& in : StudyInputFiles(spec)) used_by[in.path] = in.used_by;
  const std::string d = f.dir + "/";
  std::map<std::string, std::string> expected = {
      {d + "p_small.yaml", "problem 'small'"},       {d + "data/markers.csv", "problem 'small'"},
      {d + "data/nested.yaml", "problem 'small'"}, {d + "data/cam.json", "problem 'small'"},
      {d + "data/views/a.png", "problem 'small'"}, {d + "data/views/b.png", "problem 'small'"},
      {d + "p_large.yaml", "problem 'large'"},       {d + "scene.yaml", "problem 'sim'"},
      {d + "c_mean.yaml", "config 'mean'"},          {d + "c_median.yaml", "config 'median'"}};
  EXPECT_EQ(used_by, expected);

  const std::vector<RunSpec> runs = EnumerateRuns(spec);
  const nlohmann::json was = StudyIdentityJson(spec, runs, StudyInputFiles(spec));
  EXPECT_EQ(DescribeStudyChange(was, StudyIdentityJson(spec, runs, StudyInputFiles(spec))), "");
  Write(f.dir + "/data/views/b.png", "B");
  nlohmann::json now = StudyIdentityJson(spec, runs, StudyInputFiles(spec));
  EXPECT_NE(now["fingerprint"], was["fingerprint"]);
  EXPECT_EQ(DescribeStudyChange(was, now),
            d + "data/views/b.png (problem 'small') has different content");
  Write(f.dir + "/data/views/b.png", "b");
  Write(f.dir + "/data/views/c.png", "c");
  EXPECT_EQ(DescribeStudyChange(was, StudyIdentityJson(spec, runs, StudyInputFiles(spec))),
            d + "data/views/c.png (problem 'small') is read now but was not before");
  ::unlink((f.dir + "/data/views/c.png").c_str());
  now = StudyIdentityJson(spec, runs, StudyInputFiles(spec));
  EXPECT_EQ(now["fingerprint"], was["fingerprint"]);
  now["carmba_version"] = "9.9.9";
  now["fingerprint"] = "changed";
  EXPECT_EQ(DescribeStudyChange(was, now), "carmba version 0.1.0 differs from 9.9.9");
}

// Kills a study running in a child process halfway, then resumes it.
void KillAndResume(int signal_number) {
  Fixture f(20, /*repeat=*/1500);  // 160 runs of a few ms each
  const StudySpec spec = f.Spec();
  const std::string out = f.dir + "/killed";
  ASSERT_TRUE(MakeDirs(out).ok());
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    const Status s = RunMean(spec, out, 2);
    ::_exit(s.ok() ? 0 : 3);
  }
  // Wait until about a third of the runs are recorded, then kill the child.
  int lines = 0;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while ((lines = CountLines(out + "/runs.jsonl")) < 50 &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, WNOHANG), 0) << "the study finished before it was killed";
  ::kill(pid, signal_number);
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFSIGNALED(status));
  lines = CountLines(out + "/runs.jsonl");
  ASSERT_GE(lines, 50);
  ASSERT_LT(lines, 160);
  EXPECT_FALSE(FileExists(out + "/summary.csv"));  // the killed study wrote no summary
  // Simulate a write cut short by the kill, in case the kill landed between two lines.
  {
    std::ofstream app(out + "/runs.jsonl", std::ios::app);
    app << "{\"index\":3,\"key\":\"small|mean|noise_sd=0.5|tri";
  }
  StudyRunStats st;
  ASSERT_TRUE(RunMean(spec, out, 2, /*resume=*/true, 1, 1, &st).ok());
  EXPECT_EQ(st.dropped_lines, 1);
  EXPECT_EQ(st.skipped + st.executed, 160);
  EXPECT_GE(st.skipped, 50);
  const std::multiset<std::string> keys = Keys(out);
  EXPECT_EQ(keys.size(), 160u);
  EXPECT_EQ(std::set<std::string>(keys.begin(), keys.end()).size(), 160u);  // each exactly once
  ASSERT_TRUE(RunMean(spec, f.dir + "/clean", 1).ok());
  EXPECT_EQ(Summaries(out), Summaries(f.dir + "/clean"));
}

TEST(StudyRunnerTest, SigkillThenResumeLosesNothing) { KillAndResume(SIGKILL); }
TEST(StudyRunnerTest, SigtermThenResumeLosesNothing) { KillAndResume(SIGTERM); }

TEST(StudyRunnerTest, BadProblemsAndConfigsFailTheirRunsOnly) {
  Fixture f(3, 1, "  - {name: lost, file: missing_problem.yaml}\n",
            "  - {name: typo, file: c_typo.yaml}\n  - {name: thrower, file: c_throw.yaml}\n");
  Write(f.dir + "/c_typo.yaml", "estimator: mean\nestimatr: median\n");
  Write(f.dir + "/c_throw.yaml", "estimator: mean\nthrow_on_trial: 1\n");
  const StudySpec spec = f.Spec();
  StudyRunStats st;
  ASSERT_TRUE(RunMean(spec, f.dir + "/out", 2, false, 1, 1, &st).ok());
  // 3 problems x 4 configs x 2 noises x 3 trials.
  EXPECT_EQ(st.executed, 72);
  // lost: 4 configs x 6; typo on the 2 good problems: 2 x 6; thrower trial 1: 2 x 2.
  EXPECT_EQ(st.failed, 24 + 12 + 4);
  const std::string md = Read(f.dir + "/out/summary.md");
  EXPECT_NE(md.find("missing_problem.yaml: cannot open file"), std::string::npos) << md;
  EXPECT_NE(md.find("c_typo.yaml:2: unknown key 'estimatr'"), std::string::npos) << md;
  EXPECT_NE(md.find("exception: trial 1"), std::string::npos) << md;
  // The good runs are all there, with statistics.
  const std::string csv = Read(f.dir + "/out/summary.csv");
  EXPECT_NE(csv.find("small,mean,0.5,3,0,error,abs_error,3,"), std::string::npos) << csv;
  EXPECT_NE(csv.find("lost,mean,0.5,3,3,runs,-,0"), std::string::npos) << csv;
}

// The summaries compute the right statistics: for the mean of n Gaussian samples the reported
// standard error sigma/sqrt(n) matches the spread over trials (consistency ~ 1), and the error
// grows linearly with the noise.
TEST(StudyRunnerTest, SummaryStatisticsMatchTheory) {
  const test::ScratchDir scratch("study");  // removed when it goes
  const std::string& dir = scratch.path();
  Write(dir + "/p.yaml", "true_mean: 10\nsamples: 40\n");
  Write(dir + "/c.yaml", "estimator: mean\n");
  Write(dir + "/s.yaml",
        "trials: 400\nproblems:\n  - {name: p, file: p.yaml}\nconfigs:\n  - {name: m, file: "
        "c.yaml}\nsweeps:\n  noise_sd: [0.5, 2]\n");
  StatusOr<StudySpec> spec = LoadStudySpec(dir + "/s.yaml");
  ASSERT_TRUE(spec.ok()) << spec.status().message();
  ASSERT_TRUE(RunMean(*spec, dir + "/out", 2).ok());
  StatusOr<std::vector<RunRecord>> records =
      ReadRunLog(dir + "/out/runs.jsonl", nullptr, nullptr);
  ASSERT_TRUE(records.ok());
  const std::vector<GroupSummary> groups = Summarize(*records);
  ASSERT_EQ(groups.size(), 2u);
  // With 400 trials the sample standard deviation has a relative standard error of
  // 1/sqrt(2*399) = 3.5%; 4 of those.
  constexpr double kConsistencyTol = 0.14;
  for (size_t i = 0; i < 2; ++i) {
    const double noise = i == 0 ? 0.5 : 2.0;
    const MetricStats* m = groups[i].Find("signed", "mean");
    ASSERT_NE(m, nullptr);
    EXPECT_EQ(m->n, 400);
    EXPECT_NEAR(m->consistency, 1.0, kConsistencyTol);
    EXPECT_NEAR(m->emp_sigma, noise / std::sqrt(40.0), kConsistencyTol * noise / std::sqrt(40.0));
    // Bias: the mean error is within 4 standard errors of zero.
    EXPECT_LT(std::fabs(m->mean), 4 * m->emp_sigma / std::sqrt(400.0));
    ASSERT_EQ(groups[i].budget.size(), 1u);
    EXPECT_NEAR(groups[i].budget[0].second, noise / std::sqrt(40.0), 1e-12);
  }
  // Same data seeds at both noise levels? No: the seed includes the sweep point. The error scales
  // with the noise by 4 up to sampling error.
  const double ratio =
      groups[1].Find("error", "abs_error")->median / groups[0].Find("error", "abs_error")->median;
  EXPECT_NEAR(ratio, 4.0, 0.8);
}

TEST(StudyRunnerTest, ReportHasEveryPlotKind) {
  Fixture f(4);
  ASSERT_TRUE(RunMean(f.Spec(), f.dir + "/out", 2, false, 1, 1, nullptr, /*plots=*/true).ok());
  const std::string html = Read(f.dir + "/out/report.html");
  for (const char* kind :
       {"error-vs-noise", "sigma-consistency", "residual-histogram", "error-budget"}) {
    EXPECT_NE(html.find(std::string("data-plot=\"") + kind), std::string::npos) << kind;
  }
  // Self-contained: no external resources.
  EXPECT_EQ(html.find("src=\"http"), std::string::npos);
  EXPECT_EQ(html.find("href=\"http"), std::string::npos);
}

}  // namespace
}  // namespace carmba
