// The command line every subcommand shares (cli/main.cc, cli/command.h): --version, help in two
// spellings, required flags marked and checked first, flags shown with dashes and accepted with
// dashes or underscores, --no-x for booleans, one-line errors for misspelt flags and commands with
// the closest name suggested.
#include <gtest/gtest.h>

#include <filesystem>
#include <regex>
#include <set>
#include <string>

#include "synthetic/synthetic_views.h"
#include "cli_test_util.h"
#include "detect/observations.h"
#include "util/file_util.h"

namespace carmba::test {
namespace {

namespace fs = std::filesystem;

// The command names listed by `carmba help`.
std::vector<std::string> CommandNames() {
  const auto r = RunCarmba("help");
  std::vector<std::string> names;
  const std::regex line("^  ([a-z-]+)  ");
  std::istringstream in(r.out);
  std::string l;
  bool in_list = false;
  while (std::getline(in, l)) {
    if (l == "Commands:") in_list = true;
    std::smatch m;
    if (in_list && std::regex_search(l, m, line) && m[1] != "help") names.push_back(m[1]);
  }
  return names;
}

TEST(CommandLine, Version) {
  for (const char* args : {"--version", "version", "-V"}) {
    const auto r = RunCarmba(args);
    EXPECT_EQ(r.exit_code, 0) << args;
    EXPECT_EQ(r.out.rfind("carmba 0.", 0), 0u) << args << ": " << r.out;
    EXPECT_NE(r.out.find("Ceres"), std::string::npos) << r.out;
  }
}

TEST(CommandLine, HelpInBothSpellingsForEveryCommand) {
  const auto names = CommandNames();
  ASSERT_GE(names.size(), 8u);  // calibrate ct-fiducials detect simulate solve study ...
  for (const auto& name : names) {
    const auto a = RunCarmba("help " + name);
    const auto b = RunCarmba(name + " --help");
    const auto c = RunCarmba(name + " -h");
    EXPECT_EQ(a.exit_code, 0) << name;
    EXPECT_EQ(b.exit_code, 0) << name;
    EXPECT_EQ(a.out, b.out) << name;
    EXPECT_EQ(a.out, c.out) << name;
    EXPECT_EQ(a.out.rfind("carmba " + name + ": ", 0), 0u) << a.out;
    // Flag names are shown with dashes, never with underscores (except where the help says
    // that both work).
    const std::string note = "Flag names take dashes or underscores (--spacing-mm = --spacing_mm).";
    ASSERT_NE(a.out.find(note), std::string::npos) << a.out;
    std::string text = a.out;
    text.erase(text.find(note), note.size());
    std::smatch m;
    const std::regex underscored("--[a-z0-9]+_[a-z0-9_]*");
    EXPECT_FALSE(std::regex_search(text, m, underscored)) << name << ": " << m.str();
    EXPECT_NE(a.out.find("--verbose"), std::string::npos) << name;
  }
}

TEST(CommandLine, RequiredFlagsAreMarkedAndCheckedFirst) {
  const auto solve = RunCarmba("help solve").out;
  for (const char* f : {"--problem", "--config", "--out"}) {
    EXPECT_NE(solve.find(std::string(f) + "=STRING  (required)"), std::string::npos) << solve;
  }
  EXPECT_NE(solve.find("Usage: carmba solve --problem=... --config=... --out=..."),
            std::string::npos)
      << solve;
  // calibrate's --config is optional (the problem file may name one), its --out is not.
  const auto calibrate = RunCarmba("calibrate --help").out;
  EXPECT_NE(calibrate.find("--config=STRING  (default: none)"), std::string::npos) << calibrate;
  EXPECT_NE(calibrate.find("--out=STRING  (required)"), std::string::npos) << calibrate;
  // A missing required flag: one line naming it, before any work (the problem is never read).
  ScratchDir dir;
  auto r = RunCarmba("solve --problem=" + dir.File("no.yaml") + " --out=" + dir.File("o"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.err, "carmba solve: error: --config is required (see 'carmba solve --help')\n");
  EXPECT_FALSE(fs::exists(dir.File("o")));
  // Given but empty counts as missing.
  r = RunCarmba("detect --images= --out=" + dir.File("o.csv"));
  EXPECT_EQ(r.err, "carmba detect: error: --images is required (see 'carmba detect --help')\n");
}

TEST(CommandLine, RowsAndColsSayWhatTheyCount) {
  for (const char* cmd : {"calibrate", "detect"}) {
    const auto help = RunCarmba(std::string("help ") + cmd).out;
    for (const char* flag : {"--rows=INT32", "--cols=INT32"}) {
      const size_t at = help.find(flag);
      ASSERT_NE(at, std::string::npos) << help;
      const std::string text = help.substr(at, help.find("\n\n", at) - at);
      EXPECT_NE(text.find("chessboard the inner corners"), std::string::npos) << text;
      EXPECT_NE(text.find("circles and acircles the circles"), std::string::npos) << text;
    }
  }
}

class CommandLineCalibrate : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(WriteSyntheticGridObservations(dir_.File("obs.csv")));
  }
  std::string Calibrate(const std::string& flags, const std::string& out) const {
    return "calibrate --no-plots --observations " + dir_.File("obs.csv") + " " + flags + " --out " +
           dir_.File(out);
  }
  ScratchDir dir_;
};

// --spacing-mm and --spacing_mm, --no-mrcal / --no_mrcal / --nomrcal, `--flag value` and
// `--flag=value` all read the same flag.
TEST_F(CommandLineCalibrate, DashesAndUnderscoresBothWork) {
  const std::vector<std::string> spellings = {
      "--no-mrcal --no-opencv --spacing-mm 25", "--no_mrcal --noopencv --spacing_mm=25",
      "--nomrcal --opencv=false -spacing-mm=25"};
  for (size_t i = 0; i < spellings.size(); ++i) {
    const std::string out = "o" + std::to_string(i);
    const auto r = RunCarmba(Calibrate(spellings[i], out));
    ASSERT_EQ(r.exit_code, 0) << spellings[i] << ": " << r.err;
    const auto obs = ReadObservationsCsv(dir_.File(out + "/observations.csv"));
    ASSERT_TRUE(obs.ok()) << obs.status().message();
    EXPECT_DOUBLE_EQ(obs->grid.spacing_mm, 25) << spellings[i];
    // Neither cross-check ran.
    EXPECT_FALSE(fs::exists(dir_.File(out + "/mrcal"))) << spellings[i];
    const auto report = ReadFile(dir_.File(out + "/report.md"));
    ASSERT_TRUE(report.ok());
    // The report's command line is written with dashes too.
    EXPECT_NE(report->find("--spacing-mm 25"), std::string::npos);
    EXPECT_NE(report->find("--no-mrcal --no-opencv"), std::string::npos);
  }
}

TEST_F(CommandLineCalibrate, MisspeltFlagSuggestsTheClosest) {
  struct Case {
    std::string args, expected;
  };
  const std::vector<Case> cases = {
      {"--spacing-nm 20", "unknown flag --spacing-nm; did you mean --spacing-mm?"},
      {"--spacing_nm=20", "unknown flag --spacing-nm; did you mean --spacing-mm?"},
      {"--obsevations x", "unknown flag --obsevations; did you mean --observations?"},
      {"--no-mrcl", "unknown flag --no-mrcl; did you mean --no-mrcal?"},
      {"--config-file c.yaml", "unknown flag --config-file; did you mean --config?"},
      {"--frobnicate", "unknown flag --frobnicate (see 'carmba calibrate --help')"},
      // A flag of another command is named as such.
      {"--scene x.yaml", "flag --scene is not a flag of 'calibrate'"},
      {"--no-mrcal=1", "flag --no-mrcal takes no value, got '1'"},
  };
  for (const auto& c : cases) {
    const auto r = RunCarmba(Calibrate(c.args, "bad"));
    EXPECT_EQ(r.exit_code, 2) << c.args;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_EQ(r.err.rfind("carmba calibrate: error: ", 0), 0u) << r.err;
    EXPECT_NE(r.err.find(c.expected), std::string::npos) << c.args << ": " << r.err;
    EXPECT_FALSE(fs::exists(dir_.File("bad"))) << c.args;
  }
}

TEST(CommandLine, MisspeltCommandSuggestsTheClosest) {
  auto r = RunCarmba("slove --problem x");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.err, "carmba: error: unknown command 'slove'; did you mean 'solve'? (see 'carmba "
                   "help')\n");
  r = RunCarmba("help calibrat");
  EXPECT_NE(r.err.find("did you mean 'calibrate'?"), std::string::npos) << r.err;
  r = RunCarmba("xyzzy");
  EXPECT_EQ(r.err, "carmba: error: unknown command 'xyzzy' (see 'carmba help')\n");
}

}  // namespace
}  // namespace carmba::test

namespace carmba::test {
namespace {

// One exit code scheme (cli/command.h): 2 for the command line itself, 1 for the data; each a
// one-line error; `carmba help` lists them.
TEST(CommandLine, ExitCodesTwoForUsageOneForData) {
  ScratchDir dir;
  ASSERT_TRUE(WriteSyntheticGridObservations(dir.File("obs.csv")));
  const std::string calibrate =
      "calibrate --no-mrcal --no-opencv --observations " + dir.File("obs.csv");
  struct Case {
    std::string args;
    int exit_code;
    std::string expected;  // in the one line of stderr
  };
  const std::vector<Case> cases = {
      {"slove", 2, "unknown command 'slove'"},
      {calibrate + " --out " + dir.File("o") + " --spacing-nm 20", 2, "unknown flag --spacing-nm"},
      {calibrate + " --out " + dir.File("o") + " --scene x.yaml", 2, "not a flag of 'calibrate'"},
      {calibrate + " --out " + dir.File("o") + " --rows abc",
       2,
       "--rows: expected an integer, got 'abc'"},
      {calibrate + " --out " + dir.File("o") + " --rows=4.5",
       2,
       "--rows: expected an integer, got '4.5'"},
      {calibrate + " --out " + dir.File("o") + " --spacing-mm 2cm",
       2,
       "--spacing-mm: expected a number, got '2cm'"},
      {calibrate + " --out " + dir.File("o") + " --mrcal=maybe",
       2,
       "--mrcal: expected true or false, got 'maybe'"},
      {"study --study x.yaml --out " + dir.File("o") + " --jobs -3",
       2,
       "--jobs: expected 0 .. 1024"},
      {calibrate + " --out " + dir.File("o") + " --rows 1", 2, "--rows: expected 2 .. 1000"},
      {calibrate + " --out", 2, "flag --out needs a value"},
      {calibrate + " --out " + dir.File("o") + " stray", 2, "unexpected argument 'stray'"},
      {"solve --problem x.yaml --out " + dir.File("o"), 2, "--config is required"},
      {"pose --images " + dir.path() + " --fiducials f.csv --camera c.json --out " + dir.File("o") +
           " --marker-diameter-mm 0.002",
       2,
       "--marker-diameter-mm: expected 0.1 .. 100 mm, got 0.002"},
      // Data: a file that does not exist, a file that is wrong.
      {"solve --problem " + dir.File("none.yaml") + " --config " + dir.File("none.yaml") +
           " --out " + dir.File("o"),
       1,
       "none.yaml"},
      {"calibrate --no-mrcal --no-opencv --observations " + dir.File("none.csv") + " --out " +
           dir.File("o"),
       1,
       "none.csv"},
  };
  for (const auto& c : cases) {
    const auto r = RunCarmba(c.args);
    EXPECT_EQ(r.exit_code, c.exit_code) << c.args << ": " << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << c.args << ": " << r.err;
    EXPECT_NE(r.err.find(c.expected), std::string::npos) << c.args << ": " << r.err;
    EXPECT_FALSE(fs::exists(dir.File("o"))) << c.args;
  }
  const auto help = RunCarmba("help").out;
  EXPECT_NE(help.find("Exit codes (every command):\n  0  success\n  1  the data"),
            std::string::npos)
      << help;
  EXPECT_NE(help.find("  2  usage: an unknown command or flag"), std::string::npos) << help;
}

}  // namespace
}  // namespace carmba::test
