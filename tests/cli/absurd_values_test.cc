// Absurd values in the calibration, detection, study, CT and simulator inputs, through the built
// command, one corruption at a time: each gives one line on stderr naming the flag or the
// file:line / key, the plausible range (util/plausible.h) and the value printed with %g, a
// non-zero exit and no output. (The pose problem's cases are in solve_cli_test.cc, AbsurdValue.)
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>

#include "synthetic/synthetic_views.h"
#include "cli_test_util.h"
#include "detect/observations.h"

namespace carmba::test {
namespace {

namespace fs = std::filesystem;

// Replaces the one occurrence of `from` in `text` by `to`.
std::string Corrupt(std::string text, const std::string& from, const std::string& to) {
  const auto pos = text.find(from);
  EXPECT_NE(pos, std::string::npos) << from;
  EXPECT_EQ(text.find(from, pos + 1), std::string::npos) << from;
  if (pos != std::string::npos) text.replace(pos, from.size(), to);
  return text;
}

class AbsurdInput : public ::testing::Test {
 protected:
  void SetUp() override {
    // Pre-detected observations of the thesis camera (valid: calibrates).
    SyntheticViewsOptions so;
    GridSpec g;
    const auto obs =
        MakeSyntheticViews({2061, 2255, 204, 205, 0, 0, 0, 0, 0}, 408, 408, g, so);
    ASSERT_TRUE(WriteObservationsCsv(obs, dir_.File("obs.csv")).ok());
    obs_csv_ = ReadTextFile(dir_.File("obs.csv"));
  }
  // Runs `carmba <args> --out <out>`: non-zero exit, one line on stderr containing `expected`,
  // no number printed digit by digit, nothing at <out>.
  void ExpectFails(const std::string& args, const std::string& expected) {
    const std::string out = dir_.File("out");
    fs::remove_all(out);
    const auto r = RunCarmba(args + " --out " + out);
    EXPECT_NE(r.exit_code, 0) << args;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(expected), std::string::npos) << args << "\nstderr: " << r.err;
    EXPECT_FALSE(std::regex_search(r.err, std::regex("[0-9]{12}"))) << r.err;
    EXPECT_FALSE(fs::exists(out)) << args;
  }
  std::string Calibrate(const std::string& obs_csv_text) {
    dir_.Write("bad_obs.csv", obs_csv_text);
    return "calibrate --nomrcal --noopencv --no-plots --observations " + dir_.File("bad_obs.csv");
  }
  ScratchDir dir_;
  std::string obs_csv_;
};

TEST_F(AbsurdInput, ValidObservationsCalibrate) {
  const auto r = RunCarmba(Calibrate(obs_csv_) + " --out " + dir_.File("out"));
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir_.File("out/camera.json")));
}

// Was: "view 0 (...): its plate pose is not determined by its points".
TEST_F(AbsurdInput, SpacingFlag) {
  ExpectFails(Calibrate(obs_csv_) + " --spacing_mm 25000",
              "--spacing-mm: expected 0 (not given) or 0.1 .. 1000 mm, got 25000");
}

// Was: "view 0 (...): no homography (collinear points?)".
TEST_F(AbsurdInput, SpacingFlagHuge) {
  ExpectFails(Calibrate(obs_csv_) + " --spacing_mm 1e300",
              "--spacing-mm: expected 0 (not given) or 0.1 .. 1000 mm, got 1e+300");
}

TEST_F(AbsurdInput, SpacingFlagTiny) {
  ExpectFails(Calibrate(obs_csv_) + " --spacing_mm 1e-9",
              "--spacing-mm: expected 0 (not given) or 0.1 .. 1000 mm, got 1e-09");
}

TEST_F(AbsurdInput, RowsAndColsFlags) {
  ExpectFails("detect --images " + dir_.File("none") + " --rows 0",
              "--rows: expected 2 .. 1000, got 0");
  ExpectFails("detect --images " + dir_.File("none") + " --cols 100000",
              "--cols: expected 2 .. 1000, got 100000");
  ExpectFails("calibrate --images " + dir_.File("none") + " --cols 1000000",
              "--cols: expected 2 .. 1000, got 1000000");
}

TEST_F(AbsurdInput, ObservationsGridSpacing) {
  ExpectFails(Calibrate(Corrupt(obs_csv_, "# grid: circles 5 5 20", "# grid: circles 5 5 25000")),
              "bad_obs.csv: grid: spacing_mm: expected 0.1 .. 1000 mm, got 25000");
}

TEST_F(AbsurdInput, ObservationsImageSize) {
  ExpectFails(Calibrate(Corrupt(obs_csv_, "# image_size: 408 408", "# image_size: 408 1e9")),
              "bad_obs.csv: comment '# image_size:': expected 'width height', each an integer 1 "
              ".. 65535 px, got ' 408 1e9'");
}

TEST_F(AbsurdInput, ObservationsPixel) {
  // The first data row (line 5): view 0, point 0.
  const auto line_start = obs_csv_.find("\n0,") + 1;
  const auto line_end = obs_csv_.find('\n', line_start);
  std::string row = obs_csv_.substr(line_start, line_end - line_start);
  const auto comma = row.find_last_of(',');
  const std::string bad_row = row.substr(0, row.find_last_of(',', comma - 1)) + ",1e200," +
                              row.substr(comma + 1);
  ExpectFails(Calibrate(Corrupt(obs_csv_, row + "\n", bad_row + "\n")),
              "bad_obs.csv:5: column 'u_px': expected -100000 .. 100000 px, got 1e+200");
}

TEST_F(AbsurdInput, CalibrationProblemSpacing) {
  dir_.Write("problem.yaml", "name: p\nobservations: obs.csv\npattern: circles\nrows: 5\ncols: 5\n"
                             "spacing_mm: 25000\n");
  ExpectFails("calibrate --nomrcal --noopencv --problem " + dir_.File("problem.yaml"),
              "problem.yaml:6: key 'spacing_mm': expected 0.1 .. 1000 mm, got 25000");
}

TEST_F(AbsurdInput, CalibrationConfig) {
  dir_.Write("c1.yaml", "pixel_sigma_px: 1e9\n");
  ExpectFails(Calibrate(obs_csv_) + " --config " + dir_.File("c1.yaml"),
              "c1.yaml: pixel_sigma_px: expected 0 (estimate) or 1e-06 .. 1000 px, got 1e+09");
  dir_.Write("c2.yaml", "robust_loss: huber\nrobust_loss_scale_px: 1e300\n");
  ExpectFails(Calibrate(obs_csv_) + " --config " + dir_.File("c2.yaml"),
              "c2.yaml:2: key 'robust_loss_scale_px': expected 1e-06 .. 10000 px, got 1e+300");
  dir_.Write("c3.yaml", "num_threads: 0\n");
  ExpectFails(Calibrate(obs_csv_) + " --config " + dir_.File("c3.yaml"),
              "c3.yaml:1: key 'num_threads': expected an integer 1 .. 1024, got 0");
  dir_.Write("c5.yaml", "fov_margin_px: 1e300\n");
  ExpectFails("detect --images " + dir_.File("none") + " --pattern circles --rows 5 --cols 5 " +
                  "--detection " + dir_.File("c5.yaml") + " --out " + dir_.File("c5.csv"),
              "c5.yaml: fov_margin_px: expected 0 .. 65535 px, got 1e+300");
  dir_.Write("c4.yaml", "initial_intrinsics: [1e308, 2255, 204, 205, 0, 0, 0, 0, 0]\n");
  ExpectFails(Calibrate(obs_csv_) + " --config " + dir_.File("c4.yaml"),
              "c4.yaml: initial_intrinsics: fx: expected 1 .. 1e+06 px, got 1e+308");
}

TEST_F(AbsurdInput, StudyJobs) {
  ExpectFails("study --study " + dir_.File("none.yaml") + " --jobs 100000",
              "--jobs: expected 0 .. 1024 (0 = all cores), got 100000");
  ExpectFails("study --study " + dir_.File("none.yaml") + " --jobs -1",
              "--jobs: expected 0 .. 1024 (0 = all cores), got -1");
}

TEST_F(AbsurdInput, CtFiducialsFlags) {
  ExpectFails("ct-fiducials --dicom " + dir_.File("none") + " --diameter_mm 1e300",
              "diameter_mm: expected 0.1 .. 100 mm, got 1e+300");
  ExpectFails("ct-fiducials --dicom " + dir_.File("none") + " --threshold_hu 1e9",
              "threshold_hu: expected -1024 .. 32767 HU, got 1e+09");
  ExpectFails("ct-fiducials --dicom " + dir_.File("none") + " --label_tolerance_mm 0",
              "label_tolerance_mm: expected 1e-06 .. 1000 mm, got 0");
}

TEST_F(AbsurdInput, SceneFile) {
  const std::string scene = ReadTextFile(kSource + "/configs/scenes/thesis_calibration.yaml");
  ASSERT_FALSE(scene.empty());
  dir_.Write("sid.yaml", Corrupt(scene, "sid_mm: 1000 ", "sid_mm: 1e300 "));
  ExpectFails("simulate --scene " + dir_.File("sid.yaml"),
              "sid.yaml:20: key 'carm.sid_mm': expected 1 .. 10000 mm, got 1e+300");
  dir_.Write("fx.yaml", Corrupt(scene, "fx: 2061.389", "fx: 1e308"));
  ExpectFails("simulate --scene " + dir_.File("fx.yaml"),
              "fx.yaml:14: key 'camera.fx': expected 1 .. 1e+06 px, got 1e+308");
  // Was: the simulator never returned (Poisson sampling with a mean of 1e300).
  dir_.Write("photons.yaml", Corrupt(scene, "photons_per_pixel: 250", "photons_per_pixel: 1e300"));
  ExpectFails("simulate --scene " + dir_.File("photons.yaml"),
              "photons.yaml:34: key 'imaging.photons_per_pixel': expected 0 .. 1e+09 photons, got "
              "1e+300");
  dir_.Write("thick.yaml", Corrupt(scene, "thickness_mm: 5", "thickness_mm: 1e300"));
  ExpectFails("simulate --scene " + dir_.File("thick.yaml"),
              "thick.yaml:45: key 'plate.thickness_mm': expected 0 .. 10000 mm, got 1e+300");
}

TEST_F(AbsurdInput, CtSceneFile) {
  const std::string scene = ReadTextFile(kSource + "/configs/scenes/thesis_ct.yaml");
  ASSERT_FALSE(scene.empty());
  dir_.Write("pixel.yaml",
             Corrupt(scene, "pixel_spacing_mm: 0.3515625", "pixel_spacing_mm: 1e300"));
  ExpectFails("simulate --scene " + dir_.File("pixel.yaml"),
              "pixel.yaml:21: key 'ct.pixel_spacing_mm': expected 0.001 .. 10 mm, got 1e+300");
  dir_.Write("hu.yaml", Corrupt(scene, "air_hu: -1000", "air_hu: -1e200"));
  ExpectFails("simulate --scene " + dir_.File("hu.yaml"),
              "hu.yaml:17: key 'air_hu': expected -1024 .. 32767 HU, got -1e+200");
}

}  // namespace
}  // namespace carmba::test
