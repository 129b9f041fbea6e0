// util/python_worker.h: a pre-started interpreter runs its script as `python SCRIPT ARGS` would
// (argv, __main__, exit code, stdout/stderr files), times out, and never outlives its owner.
#include "util/python_worker.h"

#include <gtest/gtest.h>
#include <stdlib.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "report/plots.h"
#include "scratch.h"

namespace carmba {
namespace {

constexpr const char* kPython = "/usr/bin/python3";

class PythonWorkerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!std::filesystem::exists(kPython)) GTEST_SKIP() << "no " << kPython;
    dir_ = test::MakeScratchDir("pyworker");
  }
  void TearDown() override {
    std::error_code ec;
    if (!dir_.empty()) std::filesystem::remove_all(dir_, ec);
  }
  std::string File(const std::string& name) const { return dir_ + "/" + name; }
  std::string Script(const std::string& text) const {
    const std::string path = File("script.py");
    std::ofstream(path) << text;
    return path;
  }
  static std::string Slurp(const std::string& path) {
    std::ifstream in(path);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }
  std::string dir_;
};

TEST_F(PythonWorkerTest, RunsTheScriptAsMainWithItsArgumentsAndExitCode) {
  PythonWorker w(kPython, "import colorsys\n");
  const std::string script = Script(
      "import sys, os\n"
      "print(__name__, sys.argv[1:], 'colorsys' in sys.modules,\n"
      "      sys.path[0] == os.path.dirname(os.path.abspath(sys.argv[0])))\n"
      "sys.stderr.write('to stderr\\n')\n"
      "sys.exit(7)\n");
  ASSERT_TRUE(w.Start(script, {"a b", "c"}, File("out.txt"), File("err.txt")));
  EXPECT_FALSE(w.Start(script, {}, File("out2.txt"), File("err2.txt")));  // one job only
  EXPECT_EQ(w.Wait(), 7);
  EXPECT_EQ(w.Wait(), 7);  // idempotent
  EXPECT_EQ(Slurp(File("out.txt")), "__main__ ['a b', 'c'] True True\n");
  EXPECT_EQ(Slurp(File("err.txt")), "to stderr\n");
  EXPECT_GT(w.seconds(), 0);
}

// The interpreter is spawned while SIGINT and SIGTERM are blocked in carmba's thread (util/
// temp_paths.h SignalCriticalSection, so that a signal finds it registered); it must not inherit
// that mask, or it would ignore both.
TEST_F(PythonWorkerTest, TheInterpreterStartsWithNoSignalBlocked) {
  PythonWorker w(kPython, "");
  const std::string script = Script(
      "import signal\n"
      "blocked = signal.pthread_sigmask(signal.SIG_BLOCK, [])\n"
      "print(signal.SIGINT in blocked, signal.SIGTERM in blocked)\n");
  ASSERT_TRUE(w.Start(script, {}, File("out.txt"), File("err.txt")));
  EXPECT_EQ(w.Wait(), 0) << Slurp(File("err.txt"));
  EXPECT_EQ(Slurp(File("out.txt")), "False False\n");
}

TEST_F(PythonWorkerTest, AnUncaughtExceptionExitsOneWithItsTraceback) {
  PythonWorker w(kPython, "");
  ASSERT_TRUE(w.Start(Script("raise ValueError('boom')\n"), {}, File("out.txt"), File("err.txt")));
  EXPECT_EQ(w.Wait(), 1);
  const std::string err = Slurp(File("err.txt"));
  EXPECT_NE(err.find("Traceback"), std::string::npos) << err;
  EXPECT_NE(err.find("ValueError: boom"), std::string::npos) << err;
}

TEST_F(PythonWorkerTest, AFailingPreloadLeavesTheErrorToTheScript) {
  PythonWorker w(kPython, "import carmba_no_such_module\n");
  ASSERT_TRUE(w.Start(Script("import sys\nsys.exit(0)\n"), {}, File("out.txt"), File("err.txt")));
  EXPECT_EQ(w.Wait(), 0);
  EXPECT_EQ(Slurp(File("err.txt")), "");
}

TEST_F(PythonWorkerTest, TimesOutAfterTheLimit) {
  PythonWorker w(kPython, "");
  ASSERT_TRUE(
      w.Start(Script("import time\ntime.sleep(60)\n"), {}, File("out.txt"), File("err.txt")));
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(w.Wait(1), PythonWorker::kTimedOut);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_LT(s, 30) << "killed at the 1 s limit, not after the script's 60 s";
}

TEST_F(PythonWorkerTest, AMissingInterpreterCannotRun) {
  PythonWorker w("/nonexistent/python3", "");
  EXPECT_FALSE(w.Start(Script("pass\n"), {}, File("out.txt"), File("err.txt")));
  EXPECT_EQ(w.Wait(), PythonWorker::kCannotRun);
}

TEST_F(PythonWorkerTest, AWorkerWithoutAJobIsKilledNotAwaited) {
  const auto t0 = std::chrono::steady_clock::now();
  {
    PythonWorker w(kPython, "import time\ntime.sleep(60)\n");
  }
  {
    PythonWorker w(kPython, "import time\ntime.sleep(60)\n");
    EXPECT_EQ(w.Wait(), PythonWorker::kCannotRun);
  }
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_LT(s, 30) << "the 60 s preloads were killed";
}

// --no-plots: no interpreter, no warning, and report.html says why it has no plots.
TEST(PlotProcessTest, DisabledPlotsGiveANoteAndNoWarning) {
  PlotOptions o;
  o.enabled = false;
  o.python = "/nonexistent/python3";  // never started
  PlotProcess p(o);
  p.Draw({{"kind", "pose"}});
  const PlotSet s = p.Result();
  EXPECT_TRUE(s.disabled);
  EXPECT_TRUE(s.plots.empty());
  ReportDoc doc;
  doc.Heading(1, "T");
  const ReportFiles f = RenderReport(doc, "T", s);
  EXPECT_EQ(f.warning, "");
  EXPECT_NE(f.html.find("Plots not drawn (--no-plots)"), std::string::npos) << f.html;
}

}  // namespace
}  // namespace carmba
