// Temporary paths removed on SIGINT / SIGTERM (util/temp_paths.h): a child process registers a
// tree and a file, installs the handler and signals itself; it must die by that signal and leave
// nothing registered behind, while a path it did not register stays.
#include "scratch.h"
#include "util/temp_paths.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace carmba {
namespace {

namespace fs = std::filesystem;

std::string MakeScratch() { return test::MakeScratchDir("temp_paths"); }

TEST(TempPaths, SignalRemovesRegisteredPathsAndReRaises) {
  for (int sig : {SIGTERM, SIGINT}) {
    SCOPED_TRACE(sig);
    const std::string dir = MakeScratch();
    ASSERT_FALSE(dir.empty());
    const std::string tree = dir + "/out.tmp.1", file = dir + "/result.json.tmp.1",
                      kept = dir + "/input.png";
    const pid_t pid = ::fork();
    if (pid == 0) {
      fs::create_directories(tree + "/mrcal/deeper");
      for (int i = 0; i < 300; ++i) std::ofstream(tree + "/f" + std::to_string(i)) << i;
      std::ofstream(tree + "/mrcal/deeper/x") << "x";
      std::ofstream(file) << "partial";
      std::ofstream(kept) << "input";
      RegisterTempPath(tree);
      RegisterTempPath(file);
      InstallTempPathCleanup();
      ::raise(sig);
      ::_exit(0);  // not reached: the handler re-raises with the default action
    }
    int status = 0;
    ASSERT_EQ(::waitpid(pid, &status, 0), pid);
    ASSERT_TRUE(WIFSIGNALED(status)) << status;
    EXPECT_EQ(WTERMSIG(status), sig);
    EXPECT_FALSE(fs::exists(tree));
    EXPECT_FALSE(fs::exists(file));
    EXPECT_TRUE(fs::exists(kept));
    fs::remove_all(dir);
  }
}

TEST(TempPaths, ScopedPathIsRemovedOrReleasedAndUnregistered) {
  const std::string dir = MakeScratch();
  ASSERT_FALSE(dir.empty());
  const int before = NumRegisteredTempPaths();
  {
    ScopedTempPath t(dir + "/work.tmp");
    fs::create_directories(t.path() + "/a");
    EXPECT_EQ(NumRegisteredTempPaths(), before + 1);
  }
  EXPECT_FALSE(fs::exists(dir + "/work.tmp"));
  {
    ScopedTempPath t(dir + "/kept");
    fs::create_directories(t.path());
    t.Release();
    EXPECT_EQ(NumRegisteredTempPaths(), before);
  }
  EXPECT_TRUE(fs::exists(dir + "/kept"));
  EXPECT_EQ(NumRegisteredTempPaths(), before);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace carmba
