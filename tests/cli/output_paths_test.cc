// Output paths, checked before any work (util/file_util.h CheckOutputDir / CheckOutputFile): a
// directory that cannot take files, a directory where a file is meant, a file where a directory
// is meant. Each gives one line on stderr naming --out and the reason, a non-zero exit and no
// output. And an output directory that is a mount point of its own: the results are staged inside
// it, so no rename crosses file systems (it used to fail with EXDEV / EBUSY).
//
// Read-only directories: the tests run as root, for whom a chmod 0555 directory is writable. A
// read-only bind mount is used where mount(8) is allowed (the test is skipped otherwise); /sys
// and /proc, which refuse new entries even to root, are used always.
#include <gtest/gtest.h>
#include <sys/statvfs.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "synthetic/synthetic_views.h"
#include "cli_test_util.h"
#include "detect/observations.h"

namespace carmba::test {
namespace {

namespace fs = std::filesystem;

// `mount --bind src dst` (read-only if asked) for the lifetime of the object; ok() is false when
// mounting is not allowed here.
class BindMount {
 public:
  BindMount(const std::string& src, const std::string& dst, bool read_only) : dst_(dst) {
    ok_ = std::system(("mount --bind '" + src + "' '" + dst + "' 2>/dev/null").c_str()) == 0;
    if (ok_ && read_only &&
        std::system(("mount -o remount,ro,bind '" + dst + "' 2>/dev/null").c_str()) != 0) {
      Unmount();
    }
  }
  ~BindMount() { Unmount(); }
  bool ok() const { return ok_; }

 private:
  void Unmount() {
    if (ok_) std::system(("umount '" + dst_ + "'").c_str());
    ok_ = false;
  }
  std::string dst_;
  bool ok_ = false;
};

class OutputPaths : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_.Write("camera.json",
               R"({"image_size": [408, 408], "fx": 2061.4, "fy": 2254.6, "cx": 203.7,)"
               R"( "cy": 205.1, "distortion": [0, 0, 0, 0, 0]})");
    dir_.Write("markers.csv",
               "id,x_mm,y_mm,z_mm\n1,0,0,0\n2,-58.85,1,14\n3,13.35,1,14\n4,-8.25,-20.5,24\n"
               "5,-56.05,19,31\n");
    dir_.Write(
        "obs.csv",
        "view,marker,u_px,v_px\n"
        "a,1,230.0,210.0\na,2,54.1,214.5\na,3,269.0,214.7\na,4,183.1,145.2\na,5,63.0,267.2\n");
    dir_.Write("problem.yaml",
               "name: out_test\ncamera: camera.json\nsigma_px: 0.5\n"
               "markers: {file: markers.csv, sigma_mm: 0.2}\n"
               "observations: {file: obs.csv, format: long}\n");
    dir_.Write("config.yaml", "name: c\ninitializer: posit\n");
    dir_.Write("a_file", "x\n");
    fs::create_directories(dir_.File("a_dir"));
    SyntheticViewsOptions so;
    GridSpec g;
    const auto obs = MakeSyntheticViews({2061, 2255, 204, 205, 0, 0, 0, 0, 0}, 408, 408, g, so);
    ASSERT_TRUE(WriteObservationsCsv(obs, dir_.File("grid_obs.csv")).ok());
  }
  std::string Solve(const std::string& out) const {
    return "solve --problem=" + dir_.File("problem.yaml") +
           " --config=" + dir_.File("config.yaml") + " --no-plots --out=" + out;
  }
  std::string Detect(const std::string& out) const {
    return "detect --images " + dir_.File("no_images") + " --out " + out;
  }
  std::string Calibrate(const std::string& out) const {
    return "calibrate --nomrcal --noopencv --no-plots --observations " + dir_.File("grid_obs.csv") +
           " --out " + out;
  }
  // Non-zero exit, one line on stderr containing `expected`; `absent` was not created.
  static void ExpectFails(const std::string& args,
                          const std::string& expected,
                          const std::string& absent) {
    const auto r = RunCarmba(args);
    EXPECT_NE(r.exit_code, 0) << args;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(expected), std::string::npos) << args << "\nstderr: " << r.err;
    if (!absent.empty()) {
      EXPECT_FALSE(fs::exists(absent)) << absent;
    }
  }
  ScratchDir dir_;
};

TEST_F(OutputPaths, ValidOutputsAreWritten) {
  const auto r = RunCarmba(Solve(dir_.File("new/sub")));
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir_.File("new/sub/result.json")));
  // No probe or staging directory is left behind.
  for (const auto& e : fs::directory_iterator(dir_.path())) {
    EXPECT_EQ(e.path().filename().string().find(".carmba-"), std::string::npos) << e.path();
  }
}

// /sys refuses new entries with EPERM, /proc with ENOENT (here both are mounted read-write, so
// access(2) alone would let them through).
TEST_F(OutputPaths, DirectoryThatTakesNoFiles) {
  const std::string sys = "/sys/carmba_output_paths_test";
  // Containers often mount /sys read-only: then that is the reason given.
  struct statvfs vfs;
  const bool sys_read_only = ::statvfs("/sys", &vfs) == 0 && (vfs.f_flag & ST_RDONLY);
  ExpectFails(Solve(sys),
              "--out " + sys + (sys_read_only ? ": /sys is on a read-only file system"
                                              : ": cannot create files in /sys ("),
              sys);
  const std::string proc = "/proc/carmba_output_paths_test";
  ExpectFails(Solve(proc),
              "--out " + proc + ": cannot create files in /proc (the file system accepts no new "
              "entries), expected a writable directory",
              proc);
  ExpectFails(Detect(proc + ".csv"), "--out " + proc + ".csv: cannot create files in /proc",
              proc + ".csv");
}

// Was: "ro/report.md: cannot open for writing (Read-only file system)" after solving, "cannot
// write into ro: Invalid cross-device link" (calibrate into the mount point), "ro/obs.csv: cannot
// open for writing" after detecting.
TEST_F(OutputPaths, ReadOnlyMount) {
  fs::create_directories(dir_.File("ro_src"));
  fs::create_directories(dir_.File("ro"));
  BindMount mount(dir_.File("ro_src"), dir_.File("ro"), /*read_only=*/true);
  if (!mount.ok())
    GTEST_SKIP() << "mount --bind is not allowed here (see DirectoryThatTakesNoFiles)";
  const std::string ro = dir_.File("ro");
  ExpectFails(Solve(ro + "/out"),
              "--out " + ro + "/out: " + ro +
                  " is on a read-only file system, expected a writable directory",
              ro + "/out");
  ExpectFails(Solve(ro), "--out " + ro + ": " + ro + " is on a read-only file system", "");
  ExpectFails(Calibrate(ro), "--out " + ro + ": " + ro + " is on a read-only file system", "");
  ExpectFails(Detect(ro + "/obs.csv"), "--out " + ro + "/obs.csv: " + ro + " is on a read-only",
              ro + "/obs.csv");
  EXPECT_TRUE(fs::is_empty(ro));
}

// Was: "isdir: cannot rename temporary file (Is a directory)" after detecting.
TEST_F(OutputPaths, DirectoryWhereAFileIsMeant) {
  const std::string d = dir_.File("a_dir");
  ExpectFails(Detect(d), "--out " + d + ": is a directory, expected a file name", "");
  ExpectFails("ct-fiducials --dicom " + dir_.File("none") + " --out " + d,
              "--out " + d + ": is a directory, expected a file name", "");
  EXPECT_TRUE(fs::is_empty(d));
}

TEST_F(OutputPaths, FileWhereADirectoryIsMeant) {
  const std::string f = dir_.File("a_file");
  ExpectFails(Solve(f), "--out " + f + ": exists and is not a directory, expected a directory", "");
  ExpectFails(Solve(f + "/sub"), "--out " + f + "/sub: " + f + " is a file, expected a directory",
              "");
  ExpectFails(Calibrate(f + "/sub/deeper"),
              "--out " + f + "/sub/deeper: " + f + " is a file, expected a directory", "");
  ExpectFails(Detect(f + "/obs.csv"),
              "--out " + f + "/obs.csv: " + f + " is a file, expected a directory", "");
  ExpectFails("simulate --scene " + kSource + "/configs/scenes/thesis_calibration.yaml --out " + f,
              "--out " + f + ": exists and is not a directory", "");
  EXPECT_EQ(fs::file_size(f), 2u);
}

// An existing --out with a directory where an output file goes: both files or neither. Was:
// report.md written, then "result.json: cannot rename temporary file (Is a directory)".
TEST_F(OutputPaths, DirectoryInTheWayOfAnOutputFile) {
  const std::string out = dir_.File("a_dir");
  fs::create_directories(out + "/result.json");
  ExpectFails(Solve(out) + " --force",
              out + "/result.json: is a directory, expected a file (or nothing)",
              out + "/report.md");
  EXPECT_TRUE(fs::is_empty(out + "/result.json"));
  for (const auto& e : fs::directory_iterator(out)) {
    EXPECT_EQ(e.path().filename().string().find(".carmba-"), std::string::npos) << e.path();
  }
}

// An existing output directory that is a mount point: the staging directory is inside it, so the
// final renames stay on its file system. Was: "cannot write into DIR: Invalid cross-device link"
// (calibrate, staging beside DIR) and "DIR: cannot move the result into place: Device or resource
// busy" (simulate, renaming DIR itself).
TEST_F(OutputPaths, OutputDirectoryIsAMountPoint) {
  fs::create_directories(dir_.File("mnt_src"));
  fs::create_directories(dir_.File("mnt"));
  BindMount mount(dir_.File("mnt_src"), dir_.File("mnt"), /*read_only=*/false);
  if (!mount.ok()) GTEST_SKIP() << "mount --bind is not allowed here";
  const std::string mnt = dir_.File("mnt");
  std::ofstream(mnt + "/keep.txt") << "kept\n";
  auto r = RunCarmba(Calibrate(mnt) + " --force");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(mnt + "/camera.json"));
  EXPECT_TRUE(fs::exists(mnt + "/keep.txt"));  // calibrate writes file by file
  r = RunCarmba("simulate --force --scene " + kSource +
                "/configs/scenes/thesis_calibration.yaml --out " + mnt);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(mnt + "/truth.json"));
  EXPECT_FALSE(fs::exists(mnt + "/keep.txt"));  // simulate --force replaces the contents
  for (const auto& e : fs::directory_iterator(mnt)) {
    EXPECT_EQ(e.path().filename().string().find(".carmba-"), std::string::npos) << e.path();
  }
}

}  // namespace
}  // namespace carmba::test
