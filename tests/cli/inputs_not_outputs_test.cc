// Inputs are never outputs: every command refuses an --out that is, or contains, one of its inputs
// (cli/common_flags.h CheckOutIsNoInput), --force or not, with one line naming --out and the
// input's flag, exit code 2 (a usage error), and the input left as it was. The check runs before
// the command reads anything, so the inputs here are stand-ins (empty files of the right names).
//
// And temporary paths: SIGTERM during a command leaves nothing `*.tmp*` behind
// (util/temp_paths.h).
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "cli_test_util.h"

namespace carmba::test {
namespace {

namespace fs = std::filesystem;

// Stand-in inputs: one directory of "images" and one file per other input.
struct Inputs {
  ScratchDir dir;
  Inputs() {
    fs::create_directories(dir.File("images"));
    dir.Write("images/view_001.png", "original pixels");
    dir.Write("images/view_002.png", "original pixels");
    fs::create_directories(dir.File("dicom"));
    dir.Write("dicom/slice_001.dcm", "original slice");
    fs::create_directories(dir.File("result"));
    dir.Write("result/result.json", "{}");
    fs::create_directories(dir.File("shard1"));
    dir.Write("shard1/runs.jsonl", "");
    for (const char* f : {"camera.json", "config.yaml", "problem.yaml", "observations.csv",
                          "truth.json", "model.csv", "fiducials.csv", "detection.yaml",
                          "scene.yaml", "study.yaml", "points.csv"}) {
      dir.Write(f, std::string("original ") + f);
    }
  }
  // The path given to --FLAG.
  std::string Of(const std::string& flag) const {
    static const std::map<std::string, std::string> kPath = {
        {"images", "images"},       {"dicom", "dicom"},         {"result", "result"},
        {"shards", "shard1"},       {"camera", "camera.json"},  {"config", "config.yaml"},
        {"problem", "problem.yaml"}, {"observations", "observations.csv"},
        {"truth", "truth.json"},    {"model", "model.csv"},     {"fiducials", "fiducials.csv"},
        {"detection", "detection.yaml"}, {"scene", "scene.yaml"}, {"study", "study.yaml"},
        {"points", "points.csv"}};
    return dir.File(kPath.at(flag));
  }
};

// Every command that writes, with the input flags it has (all of them given at once: the check
// names the first input --out collides with).
const std::map<std::string, std::vector<std::string>>& InputFlagsByCommand() {
  static const std::map<std::string, std::vector<std::string>> k = {
      {"calibrate", {"images", "observations", "config", "problem", "truth", "detection"}},
      {"ct-fiducials", {"dicom", "model"}},
      {"detect", {"images", "detection"}},
      {"export-geometry", {"result"}},
      {"pose", {"images", "camera", "fiducials", "config", "detection"}},
      {"simulate", {"scene"}},
      {"solve", {"problem", "config"}},
      {"study", {"study"}},
      {"study-merge", {"shards"}},
      {"triangulate", {"problem", "config", "points"}},
      {"undistort", {"images", "camera"}},
  };
  return k;
}

std::string Snapshot(const std::string& root) {
  std::ostringstream s;
  std::set<std::string> lines;
  for (const auto& e : fs::recursive_directory_iterator(root)) {
    lines.insert(e.path().string() + "=" + (e.is_regular_file() ? ReadTextFile(e.path()) : "dir"));
  }
  for (const auto& l : lines) s << l << "\n";
  return s.str();
}

// Each command's every input, as --out itself and as the directory holding it, with --force.
TEST(InputsNotOutputs, EveryCommandRefusesAnOutThatIsOrContainsAnInput) {
  Inputs in;
  const std::string before = Snapshot(in.dir.path());
  for (const auto& [cmd, flags] : InputFlagsByCommand()) {
    for (const std::string& flag : flags) {
      std::string args = cmd;
      for (const std::string& f : flags) args += " --" + f + " " + in.Of(f);
      // As --out itself ("is"); a file input's directory, or a directory input's parent
      // ("contains").
      const std::string input = in.Of(flag);
      for (const std::string& out : {input, fs::path(input).parent_path().string()}) {
        SCOPED_TRACE(cmd + " --" + flag + " --out " + out);
        // Other inputs may collide first (they share the parent): only the message's form and the
        // exit code are checked for the parent; for the input itself, the flag is named.
        const auto r = RunCarmba(args + " --out " + out + " --force");
        EXPECT_EQ(r.exit_code, 2) << r.err;
        EXPECT_EQ(CountLines(r.err), 1) << r.err;
        EXPECT_EQ(r.err.rfind("carmba " + cmd + ": error: --out " + out + ": ", 0), 0u) << r.err;
        EXPECT_NE(r.err.find("an output never replaces an input, with --force or not"),
                  std::string::npos)
            << r.err;
        if (out == input) {
          const std::string named = "--" + flag;
          EXPECT_NE(r.err.find(": is the input --"), std::string::npos) << r.err;
          // The first colliding input is this one, or one listed before it sharing the path.
          EXPECT_NE(r.err.find("the input " + named + " " + input), std::string::npos) << r.err;
        } else {
          EXPECT_NE(r.err.find(": contains the input --"), std::string::npos) << r.err;
        }
      }
    }
  }
  EXPECT_EQ(Snapshot(in.dir.path()), before) << "an input was changed";
}

// The table above covers every command that has --out: a new command must be added to it.
TEST(InputsNotOutputs, TableCoversEveryCommandWithOut) {
  const auto usage = RunCarmba("help");
  ASSERT_EQ(usage.exit_code, 0);
  std::istringstream lines(usage.out);
  std::string line;
  bool in_commands = false;
  int commands = 0;
  while (std::getline(lines, line)) {
    if (line == "Commands:") {
      in_commands = true;
      continue;
    }
    if (!in_commands || line.size() < 3 || line[0] != ' ') {
      if (in_commands && line.empty()) break;
      continue;
    }
    const std::string name = line.substr(2, line.find(' ', 2) - 2);
    if (name == "help") continue;
    ++commands;
    const auto help = RunCarmba("help " + name);
    if (help.out.find("\n  --out=") == std::string::npos) continue;
    // track's inputs are NAME=PATH lists (--cameras, --images), not one path per flag: its own
    // test covers them (TrackCli.BadCommandLinesAreOneLineAndWriteNothing).
    if (name == "track") continue;
    EXPECT_TRUE(InputFlagsByCommand().count(name)) << name << " has --out but is not in the table";
  }
  EXPECT_GE(commands, 11);
}

// The reported case: undistort --force --out INPUT_DIR overwrote the original images.
TEST(InputsNotOutputs, UndistortForceIntoItsImagesIsRefused) {
  Inputs in;
  const auto r = RunCarmba("undistort --images " + in.Of("images") + " --camera " +
                           in.Of("camera") + " --out " + in.Of("images") + "/ --force");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("is the input --images"), std::string::npos) << r.err;
  EXPECT_EQ(ReadTextFile(in.Of("images") + "/view_001.png"), "original pixels");
}

// Globs and symbolic links: the directory a glob reads, and a link to an input, are inputs too;
// an --out inside an input directory (a new subdirectory) is not one.
TEST(InputsNotOutputs, GlobsLinksAndSubdirectories) {
  Inputs in;
  const std::string glob = "'" + in.Of("images") + "/view_*.png'";
  auto r = RunCarmba("detect --images " + glob + " --out " + in.Of("images") + " --force");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("contains the input --images"), std::string::npos) << r.err;
  fs::create_directory_symlink(in.Of("images"), in.dir.File("link"));
  r = RunCarmba("undistort --images " + in.Of("images") + " --camera " + in.Of("camera") +
                " --out " + in.dir.File("link") + " --force");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("is the input --images"), std::string::npos) << r.err;
  // A subdirectory of the images is a new output: the command runs (and fails on the stand-in
  // camera, a data error).
  r = RunCarmba("undistort --images " + in.Of("images") + " --camera " + in.Of("camera") +
                " --out " + in.Of("images") + "/undistorted");
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_EQ(r.err.find("never replaces an input"), std::string::npos) << r.err;
}

// calibrate --problem: the problem's images / observations / config / truth are inputs too.
TEST(InputsNotOutputs, CalibrateProblemInputs) {
  Inputs in;
  in.dir.Write("calib_problem.yaml", "name: p\nobservations: observations.csv\n");
  const auto r = RunCarmba("calibrate --problem " + in.dir.File("calib_problem.yaml") +
                           " --out " + in.Of("observations") + " --force");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("is the input named in --problem " + in.dir.File("calib_problem.yaml") +
                       ": " + in.Of("observations")),
            std::string::npos)
      << r.err;
  EXPECT_EQ(ReadTextFile(in.Of("observations")), "original observations.csv");
}

// Files named inside a problem, config or study file are inputs too, at any depth: a study names
// a problem file, which names its data directory; solve and triangulate read a problem's files.
TEST(InputsNotOutputs, FilesNamedInsideProblemConfigAndStudyFiles) {
  Inputs in;
  fs::create_directories(in.dir.File("data"));
  in.dir.Write("data/markers.csv", "original markers");
  in.dir.Write("nested_problem.yaml", "name: p\nviews:\n  - observations: data/markers.csv\n");
  in.dir.Write("nested_study.yaml",
               "name: s\nproblems:\n  - {name: p, file: nested_problem.yaml}\n");
  struct Case {
    std::string args, named_in;
  };
  const std::vector<Case> cases = {
      {"solve --problem " + in.dir.File("nested_problem.yaml") + " --config " + in.Of("config"),
       "--problem " + in.dir.File("nested_problem.yaml")},
      {"triangulate --problem " + in.dir.File("nested_problem.yaml") + " --points " +
           in.Of("points"),
       "--problem " + in.dir.File("nested_problem.yaml")},
      {"study --study " + in.dir.File("nested_study.yaml"),
       "--study " + in.dir.File("nested_study.yaml")},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.args);
    const auto r = RunCarmba(c.args + " --out " + in.dir.File("data") + " --force");
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(": contains the input named in " + c.named_in + ": "), std::string::npos)
        << r.err;
    EXPECT_NE(r.err.find("data/markers.csv"), std::string::npos) << r.err;
  }
  EXPECT_EQ(ReadTextFile(in.dir.File("data/markers.csv")), "original markers");
}

// Any entry of `dir` whose name holds "tmp" (WriteFileAtomic's FILE.tmp.PID, StagedOutputDir's
// DIR.tmp.PID and .carmba-tmp.PID, the mrcal cross-check's OUT.mrcal.tmp.PID).
std::vector<std::string> TmpEntries(const std::string& dir) {
  std::vector<std::string> found;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, ec); !ec && it != fs::end(it);
       it.increment(ec)) {
    if (it->path().filename().string().find("tmp") != std::string::npos) {
      found.push_back(it->path().string());
    }
  }
  return found;
}

// Starts `carmba args` (stdout, stderr to /dev/null; `env`: NAME=VALUE words put before it),
// waits until a temporary path shows in `watch` (at most 120 s), sends `sig`. Returns the wait
// status; *seen = whether a temporary path was seen before the signal.
int RunAndSignalOnTmp(const std::string& args,
                      const std::string& watch,
                      int sig,
                      bool* seen,
                      const std::string& env = "") {
  const pid_t pid = ::fork();
  if (pid == 0) {
    const std::string cmd = "exec env " + env + " " + std::string(CARMBA_BIN) + " " + args +
                            " >/dev/null 2>/dev/null";
    ::execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  *seen = false;
  int status = 0;
  const auto t0 = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() - t0 < std::chrono::seconds(120)) {
    if (::waitpid(pid, &status, WNOHANG) == pid) return status;  // finished before a tmp showed
    if (!TmpEntries(watch).empty()) {
      *seen = true;
      ::kill(pid, sig);
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  if (!*seen) ::kill(pid, SIGKILL);
  ::waitpid(pid, &status, 0);
  return status;
}

// SIGTERM and SIGINT while `carmba simulate` writes its images through DIR.tmp.PID: the command
// dies by the signal and leaves no *tmp* path (reported: SIGTERM during the mrcal step left
// OUT.mrcal.tmp.PID/ beside the output).
TEST(TempPaths, SignalLeavesNoTemporaryPath) {
  for (int sig : {SIGTERM, SIGINT}) {
    SCOPED_TRACE(sig);
    ScratchDir root;
    bool seen = false;
    const int status = RunAndSignalOnTmp("simulate --scene " + kSource +
                                             "/configs/scenes/thesis_calibration.yaml --out " +
                                             root.File("sim"),
                                         root.path(), sig, &seen);
    ASSERT_TRUE(seen) << "no temporary path appeared";
    EXPECT_TRUE(WIFSIGNALED(status)) << status;
    if (WIFSIGNALED(status)) {
      EXPECT_EQ(WTERMSIG(status), sig);
    }
    EXPECT_TRUE(TmpEntries(root.path()).empty()) << TmpEntries(root.path()).front();
  }
}

// The processes whose environment holds `marker` (NAME=VALUE), from /proc.
std::vector<int> ProcessesWithEnvironment(const std::string& marker) {
  std::vector<int> pids;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator("/proc", ec)) {
    const std::string name = entry.path().filename().string();
    if (name.find_first_not_of("0123456789") != std::string::npos) continue;
    std::ifstream in(entry.path() / "environ", std::ios::binary);
    for (std::string var; std::getline(in, var, '\0');) {
      if (var == marker) {
        pids.push_back(std::stoi(name));
        break;
      }
    }
  }
  return pids;
}

// The same during calibrate's mrcal cross-check (OUT.mrcal.tmp.PID/, the reported case), when
// python3-mrcal is there to make it: no temporary path is left, neither beside the output nor
// under $TMPDIR (the plot script's directory), and no Python interpreter (the plots', mrcal's)
// outlives carmba (reported: the mrcal child survived SIGTERM).
TEST(TempPaths, SigtermDuringTheMrcalStepLeavesNoTemporaryDirectory) {
  if (std::system("/usr/bin/python3 -c 'import mrcal' >/dev/null 2>&1") != 0) {
    GTEST_SKIP() << "python3-mrcal not installed";
  }
  ScratchDir root;
  ASSERT_TRUE(WriteSyntheticGridObservations(root.File("obs.csv")));
  fs::create_directories(root.File("T"));  // $TMPDIR (a name without "tmp": TmpEntries)
  const std::string marker = "CARMBA_SIGNAL_TEST=" + root.path();
  bool seen = false;
  const int status = RunAndSignalOnTmp(
      "calibrate --no-opencv --observations " + root.File("obs.csv") + " --out " +
          root.File("calib"),
      root.path(), SIGTERM, &seen, marker + " TMPDIR=" + root.File("T"));
  ASSERT_TRUE(seen) << "no temporary path appeared";
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGTERM) << status;
  EXPECT_TRUE(TmpEntries(root.path()).empty()) << TmpEntries(root.path()).front();
  EXPECT_TRUE(fs::is_empty(root.File("T"))) << fs::directory_iterator(root.File("T"))->path();
  // The handler reaps its children before it re-raises; allow the kernel a moment all the same.
  std::vector<int> left;
  for (int i = 0; i < 50 && !(left = ProcessesWithEnvironment(marker)).empty(); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_TRUE(left.empty()) << "process " << left.front() << " outlived carmba";
  for (int pid : left) ::kill(pid, SIGKILL);
}

}  // namespace
}  // namespace carmba::test
