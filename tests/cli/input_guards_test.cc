// Guards with reasons (issue 23 §3): wrong inputs named as such, once, with the flag or key and
// the plausible range (util/plausible.h), instead of per-view failures or a silent result.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "cli_test_util.h"

namespace carmba::test {
namespace {

namespace fs = std::filesystem;

class InputGuards : public ::testing::Test {
 protected:
  // Simulated plate images and a simulated CT series, made once.
  static void SetUpTestSuite() {
    data_ = new ScratchDir("input_guards");
    const std::string err = SimulatePlateAndCt(*data_);
    ASSERT_EQ(err, "");
  }
  static void TearDownTestSuite() {
    delete data_;
    data_ = nullptr;
  }
  static ScratchDir* data_;
};

ScratchDir* InputGuards::data_ = nullptr;

// A CT series given as X-ray images is named once (reported: 120 "too few blobs" lines).
TEST_F(InputGuards, CtSeriesGivenAsXrayImagesIsNamedOnce) {
  ScratchDir out;
  for (const std::string cmd : {"calibrate --no-mrcal --no-opencv", "detect"}) {
    SCOPED_TRACE(cmd);
    const auto r = RunCarmba(cmd + " --images " + data_->File("ct/ct") + " --out " +
                             out.File(cmd.substr(0, 6) + ".out"));
    EXPECT_EQ(r.exit_code, 1);
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(" is a CT slice (Modality CT), not an X-ray projection: a CT series is "
                         "read by 'carmba ct-fiducials --dicom DIR'"),
              std::string::npos)
        << r.err;
    EXPECT_EQ(r.err.find("blobs"), std::string::npos) << r.err;
  }
}

// --spacing-mm 2 (cm meant) put the plate at 78 mm without a word; now an error naming the flag.
TEST_F(InputGuards, PlateImplausiblyNearTheSourceNamesTheSpacing) {
  ScratchDir out;
  const std::string calibrate = "calibrate --no-mrcal --no-opencv --no-plots --images " +
                                data_->File("plate") + " --rows 5 --cols 5 --out ";
  auto r = RunCarmba(calibrate + out.File("bad") + " --spacing-mm 2");
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("mm from the source (median of 20 views), expected 100 .. 5000 mm: check "
                       "the grid pitch, --spacing-mm 2 (a unit slip? cm for mm)"),
            std::string::npos)
      << r.err;
  EXPECT_FALSE(fs::exists(out.File("bad")));
  // 200 for 20: 7.8 m.
  r = RunCarmba(calibrate + out.File("far") + " --spacing-mm 200");
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("--spacing-mm 200 (a unit slip?)"), std::string::npos) << r.err;
  // The true pitch passes.
  r = RunCarmba(calibrate + out.File("ok") + " --spacing-mm 20");
  EXPECT_EQ(r.exit_code, 0) << r.err;
}

// A joint problem whose rows / cols do not match the plate names the grid, not "no plate views".
TEST_F(InputGuards, JointProblemWithWrongRowsSaysTheGridWasNotFound) {
  ScratchDir dir;
  dir.Write("problem.yaml", "name: wrong_rows\n"
                            "plate_views: {images: " + data_->File("plate") +
                                ", pattern: circles, rows: 7, cols: 5, spacing_mm: 20, "
                                "sigma_px: 0.05}\n"
                                "object_views: {observations: object.csv, sigma_px: 0.2}\n"
                                "fiducials: fiducials.csv\n");
  dir.Write("config.yaml", "name: c\n");
  const auto r = RunCarmba("solve --problem " + dir.File("problem.yaml") + " --config " +
                           dir.File("config.yaml") + " --out " + dir.File("out"));
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("key 'plate_views.images': the grid (circles 7 x 5: plate_views.pattern, "
                       "plate_views.rows, plate_views.cols) was found in 0 of 20 images: check "
                       "rows and cols; first skipped: "),
            std::string::npos)
      << r.err;
}

// A marker diameter or source-to-object distance in metres names the flag or key and its range,
// once (reported: seven per-view lines about px_per_mm or "0 marker blobs").
TEST_F(InputGuards, UnitSlipsNameTheFlagOrKeyOnce) {
  ScratchDir dir;
  dir.Write("camera.json", R"({"image_size": [408, 408], "fx": 2061.4, "fy": 2254.6, "cx": 203.7,)"
                           R"( "cy": 205.1, "distortion": [0, 0, 0, 0, 0]})");
  dir.Write("markers.csv", "id,x_mm,y_mm,z_mm\n1,0,0,0\n2,-58.85,1,14\n3,13.35,1,14\n");
  const std::string pose = "pose --images " + data_->File("plate") + " --camera " +
                           dir.File("camera.json") + " --fiducials " + dir.File("markers.csv") +
                           " --out " + dir.File("out");
  struct Case {
    std::string flags, expected;
    int exit_code;
  };
  dir.Write("detection.yaml", "diameter_mm: 0.003\nsource_to_object_mm: 780\n");
  dir.Write("detection_m.yaml", "diameter_mm: 3\nsource_to_object_mm: 0.78\n");
  const Case cases[] = {
      {"--marker-diameter-mm 0.003 --source-to-object-mm 780",
       "--marker-diameter-mm: expected 0.1 .. 100 mm, got 0.003 (a diameter in metres?)", 2},
      {"--marker-diameter-mm 3 --source-to-object-mm 0.78",
       "--source-to-object-mm: expected 50 .. 10000 mm, got 0.78 (a distance in metres?)", 2},
      {"--detection " + dir.File("detection.yaml"),
       "diameter_mm: expected 0.1 .. 100 mm, got 0.003 (a diameter in metres?)", 1},
      {"--detection " + dir.File("detection_m.yaml"),
       "source_to_object_mm: expected 0 (unknown) or 50 .. 10000 mm, got 0.78 (a distance in "
       "metres?)", 1},
  };
  for (const Case& c : cases) {
    const auto r = RunCarmba(pose + " " + c.flags);
    EXPECT_EQ(r.exit_code, c.exit_code) << c.flags << ": " << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(c.expected), std::string::npos) << c.flags << ": " << r.err;
    EXPECT_EQ(r.err.find("calib_0"), std::string::npos) << "a per-view message: " << r.err;
  }
}

}  // namespace
}  // namespace carmba::test
