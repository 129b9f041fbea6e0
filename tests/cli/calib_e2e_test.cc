// End-to-end `carmba calibrate` / `carmba detect`: simulator images of two different scenes
// (thesis plate with barrel distortion; 6x7 plate with pincushion distortion), OpenCV's real
// chessboard photos, and bad inputs (each: clear one-line error, non-zero exit, no output).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <string>

#include "calib/calibrate.h"
#include "camera/camera.h"
#include "cli_test_util.h"
#include "detect/observations.h"
#include "report_browser.h"
#include "scratch.h"
#include "synthetic/synthetic_views.h"
#include "util/image_codecs.h"

namespace {

namespace fs = std::filesystem;

struct CliRun {
  int code;
  std::string out, err;
};

// `name` in this process's scratch directory (shared by the tests of one run of the binary, so
// that a scene is rendered once; removed at exit).
std::string Tmp(const std::string& name) {
  static const carmba::test::ScratchDir dir("calib_e2e");
  return dir.File(name);
}

CliRun Carmba(const std::string& args) {
  const std::string o = Tmp("stdout.txt"), e = Tmp("stderr.txt");
  const int status =
      std::system((std::string(CARMBA_BIN) + " " + args + " >" + o + " 2>" + e).c_str());
  return {WEXITSTATUS(status), carmba::test::ReadTextFile(o), carmba::test::ReadTextFile(e)};
}

void WriteText(const std::string& path, const std::string& text) { std::ofstream(path) << text; }

nlohmann::json Json(const fs::path& p) {
  return nlohmann::json::parse(carmba::test::ReadTextFile(p));
}

// A shipped scene rendered (cli_test_util.h: once per ctest run or test binary run); read only.
std::string Simulated(const std::string& scene) {
  std::string error;
  const std::string dir = carmba::test::SimulatedScene(scene, &error);
  EXPECT_NE(dir, "") << error;
  return dir;
}

// The acceptance checks every simulated scene must pass.
// `flags` are added to the command (" --no-plots" where the plots are not looked at).
void CheckSimulatedCalibration(const std::string& scene,
                               const std::string& glob,
                               const std::string& flags = "") {
  const std::string sim = Simulated(scene);
  const std::string out = Tmp("out_" + scene);
  fs::remove_all(out);
  const nlohmann::json truth = Json(sim + "/truth.json");
  CliRun r = Carmba("calibrate --images '" + sim + "/" + glob + "' --pattern circles --rows " +
                    std::to_string(truth["object"]["rows"].get<int>()) + " --cols " +
                    std::to_string(truth["object"]["cols"].get<int>()) + " --spacing_mm " +
                    std::to_string(truth["object"]["pitch_mm"].get<double>()) + " --truth " + sim +
                    "/truth.json" + flags + " --out " + out);
  ASSERT_EQ(r.code, 0) << r.err;
  for (const char* f : {"camera.json", "camera.cameramodel", "camera_opencv.yml",
                        "observations.csv", "corners.vnl", "report.md", "report.html"}) {
    EXPECT_TRUE(fs::exists(fs::path(out) / f)) << f;
  }
  const nlohmann::json cam = Json(out + "/camera.json");
  // camera.json is the pose problems' camera file; camera.cameramodel reads in mrcal and
  // camera_opencv.yml in cv::FileStorage with the same focal length.
  auto read_back = carmba::ReadCameraJson(out + "/camera.json");
  ASSERT_TRUE(read_back.ok()) << read_back.status().message();
  EXPECT_EQ(read_back->params[0], cam["fx"].get<double>());
  EXPECT_EQ(read_back->covariance.size(), 9u);
  const std::string py =
      "/usr/bin/python3 -c \"import mrcal, cv2; m = mrcal.cameramodel('" + out +
      "/camera.cameramodel'); f = cv2.FileStorage('" + out +
      "/camera_opencv.yml', cv2.FILE_STORAGE_READ); "
      "w = mrcal.cameramodel('" +
      out +
      "/mrcal/camera_with_optimization_inputs.cameramodel'); "
      "assert w.optimization_inputs() is not None; "
      "print(repr(m.intrinsics()[1][0]), repr(f.getNode('camera_matrix').mat()[0][0]))\" > " +
      Tmp("py.txt");
  ASSERT_EQ(std::system(py.c_str()), 0);
  std::istringstream py_out(carmba::test::ReadTextFile(Tmp("py.txt")));
  double fx_mrcal = 0, fx_cv = 0;
  py_out >> fx_mrcal >> fx_cv;
  EXPECT_DOUBLE_EQ(fx_mrcal, cam["fx"].get<double>());
  EXPECT_NEAR(fx_cv, cam["fx"].get<double>(), 1e-9 * fx_cv);  // FileStorage prints 16 digits
  // The grid is found in at least 90 % of the rendered views (OpenCV's grid finder misses a
  // strongly distorted view with a sphere at the field-of-view rim in the pincushion scene).
  EXPECT_GE(cam["views"].size(), 0.9 * truth["views"].size()) << r.err;
  // fx, fy, cx, cy within 3 sigma of the truth (the projection over the field is checked in
  // tests/calib/scene_accuracy_test.cc).
  for (const char* k : {"fx", "fy", "cx", "cy"}) {
    const double d = cam[k].get<double>() - truth["camera"][k].get<double>();
    const double n_sigma = std::abs(d) / cam["sigmas"][k].get<double>();
    std::cout << scene << " " << k << ": estimate - truth = " << d << " px = " << n_sigma
              << " sigma\n";
    EXPECT_LT(n_sigma, 3.0) << scene << " " << k;
  }
  // mrcal on the same observations: RMS within 1 %, projection difference < 0.05 px RMS,
  // sigmas of fx fy cx cy within 10 % (the thresholds).
  const nlohmann::json m = Json(out + "/mrcal/mrcal_out.json");
  // mrcal's RMS counts missing points (dropped at the field-of-view border) as zero residuals.
  const double n_obs = cam["num_points"].get<double>();
  const double n_all = cam["views"].size() * truth["object"]["rows"].get<double>() *
                       truth["object"]["cols"].get<double>();
  EXPECT_NEAR(cam["rms_px"].get<double>() * std::sqrt(n_obs / n_all) / m["rms_px"].get<double>(),
              1.0, 0.01);
  EXPECT_LT(m["projection_diff"]["mrcal"]["rms_px"].get<double>(), 0.05);
  for (int i = 0; i < 4; ++i) {
    const char* k = carmba::kIntrinsicNames[i];
    EXPECT_NEAR(cam["sigmas"][k].get<double>() / m["sigma"][i].get<double>(), 1.0, 0.10) << k;
  }
  const std::string report = carmba::test::ReadTextFile(out + "/report.md");
  EXPECT_EQ(report.find("FAIL"), std::string::npos) << report;
  EXPECT_NE(report.find("## Against the truth"), std::string::npos);
  EXPECT_NE(report.find("| whole image | 441 |"), std::string::npos) << report;
  // Per image: a row of the detection table (images named by their stems, their directory said
  // once) and an overlay picture of the image's size.
  EXPECT_NE(report.find("## Detection per image"), std::string::npos);
  EXPECT_NE(report.find("Images in `" + sim + "/`."), std::string::npos) << report;
  const int rows = truth["object"]["rows"].get<int>(), cols = truth["object"]["cols"].get<int>();
  for (size_t i = 0; i < truth["views"].size(); ++i) {
    const std::string file = truth["views"][i]["file"].get<std::string>();
    EXPECT_NE(report.find("| " + fs::path(file).stem().string() + " | "), std::string::npos)
        << file;
    char name[64];
    std::snprintf(name, sizeof(name), "%03zu_", i);
    const std::string overlay =
        out + "/overlays/" + name + fs::path(file).stem().string() + ".png";
    const cv::Mat o = carmba::ImRead(overlay, cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(o.empty()) << overlay;
    EXPECT_EQ(o.type(), CV_8UC3);
    EXPECT_EQ(o.cols, truth["camera"]["image_size"][0].get<int>());
  }
  EXPECT_NE(report.find(" / " + std::to_string(rows * cols) + " | "), std::string::npos);
}

TEST(CalibE2E, ThesisCalibrationScene) {
  CheckSimulatedCalibration("thesis_calibration", "*.png");
  // report.html: residuals, distortion, mrcal's projection uncertainty over the image and the
  // source positions drawn, and the page renders in a browser.
  const std::string html =
      carmba::test::ReadTextFile(Tmp("out_thesis_calibration") + "/report.html");
  for (const char* id : {"residuals-per-view", "residual-field", "distortion-the-camera",
                         "projection-uncertainty-the-camera", "poses-plate"}) {
    EXPECT_NE(html.find(std::string("data-plot=\"") + id + "\""), std::string::npos) << id;
  }
  carmba::test::ExpectReportRenders(Tmp("out_thesis_calibration") + "/report.html", 5);
}

TEST(CalibE2E, PincushionSevenBySixScene) {
  CheckSimulatedCalibration("calib_7x6_pincushion", "*.png", " --no-plots");
}

// The Monte Carlo on the scenes' geometry is tests/calib/scene_monte_carlo_test.cc.

TEST(CalibE2E, ThesisConfigHoldsTheThesisConstraints) {
  const std::string sim = Simulated("thesis_calibration");
  const std::string out = Tmp("out_thesis_cfg");
  fs::remove_all(out);
  CliRun r =
      Carmba("calibrate --images '" + sim +
             "/*.png' --pattern circles --rows 5 --cols 5 "
             "--spacing_mm 20 --config " +
             std::string(CARMBA_SOURCE_DIR) + "/configs/calib_thesis.yaml --no-plots --out " + out);
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json cam = Json(out + "/camera.json");
  EXPECT_DOUBLE_EQ(cam["cx"].get<double>(), 203.5);
  EXPECT_DOUBLE_EQ(cam["cy"].get<double>(), 203.5);
  EXPECT_EQ(cam["distortion"][2].get<double>(), 0.0);
  EXPECT_EQ(cam["distortion"][3].get<double>(), 0.0);
  EXPECT_NEAR(cam["fy"].get<double>() / cam["fx"].get<double>(), 1.09375, 1e-12);
  // Like with like: mrcal solves with the same held intrinsics too, and every check passes.
  const std::string report = carmba::test::ReadTextFile(out + "/report.md");
  EXPECT_NE(report.find("check (same free intrinsics)"), std::string::npos);
  EXPECT_NE(report.find("carmba's config: cx cy p1 p2 held, fy = r fx"), std::string::npos);
  EXPECT_EQ(report.find("| FAIL |"), std::string::npos) << report;
}

TEST(CalibE2E, DetectThenCalibrateFromObservations) {
  const std::string sim = Simulated("thesis_calibration");
  const std::string csv = Tmp("detected.csv"), out = Tmp("out_from_csv");
  fs::remove_all(out);
  CliRun d = Carmba("detect --images '" + sim +
                    "/*.png' --pattern circles --rows 5 --cols 5 --out " + csv);
  ASSERT_EQ(d.code, 0) << d.err;
  EXPECT_NE(d.out.find("found the grid in 20 of 20"), std::string::npos) << d.out;
  CliRun r = Carmba("calibrate --observations " + csv + " --out " + out +
                    " --nomrcal --noopencv --no-plots");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(carmba::test::ReadTextFile(out + "/report.md").find("Not run: disabled"),
            std::string::npos);
}

TEST(CalibE2E, OpenCvChessboardPhotosAgreeWithOpenCvAndMrcal) {
  const std::string out = Tmp("out_left");
  fs::remove_all(out);
  CliRun r = Carmba("calibrate --problem " + std::string(CARMBA_SOURCE_DIR) +
                    "/problems/calib_opencv_left.yaml --config " + std::string(CARMBA_SOURCE_DIR) +
                    "/configs/calib_free.yaml --no-plots --out " + out);
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json cam = Json(out + "/camera.json");
  const nlohmann::json m = Json(out + "/mrcal/mrcal_out.json");
  // Same optimum as mrcal (1e-3 px on fx..cy) and the same projection.
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(
        cam[carmba::kIntrinsicNames[i]].get<double>(), m["intrinsics"][i].get<double>(), 1e-3);
  }
  EXPECT_LT(m["projection_diff"]["mrcal"]["rms_px"].get<double>(), 0.01);
  EXPECT_LT(m["projection_diff"]["opencv"]["rms_px"].get<double>(), 0.01);
  EXPECT_EQ(cam["views"].size(), 13u);  // left01..left14 without left10 (not shipped)
}

// --images DIR takes the images of a directory and leaves other files (the simulator's
// truth.json) alone; --spacing_mm is recorded in observations.csv.
TEST(CalibE2E, DetectTakesOnlyTheImagesOfADirectory) {
  const std::string sim = Simulated("thesis_calibration");
  ASSERT_TRUE(fs::exists(sim + "/truth.json"));
  const std::string csv = Tmp("detect_dir.csv");
  CliRun r = Carmba("detect --images " + sim + " --spacing_mm 20 --out " + csv);
  ASSERT_EQ(r.code, 0) << r.err;
  auto obs = carmba::ReadObservationsCsv(csv);
  ASSERT_TRUE(obs.ok()) << obs.status().message();
  EXPECT_EQ(obs->views.size(), 20u);
  EXPECT_DOUBLE_EQ(obs->grid.spacing_mm, 20.0);
}

// Bad input: each gives a one-line error and leaves no output directory.
void ExpectFailsCleanly(const std::string& args, const std::string& expected) {
  const std::string out = Tmp("out_bad");
  fs::remove_all(out);
  CliRun r = Carmba(args + " --out " + out);
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find(expected), std::string::npos) << "stderr: " << r.err;
  EXPECT_FALSE(fs::exists(out)) << args;
}

// A calibration problem in the one schema and the same problem in the spelling before it give
// the same calibration as the flags; the problem's truth reaches the report.
TEST(CalibE2E, ProblemInTheOneSchemaAndTheOlderSpellingCalibrateAlike) {
  const std::string sim = Simulated("thesis_calibration");
  const std::string config = std::string(CARMBA_SOURCE_DIR) + "/configs/calib_radial.yaml";
  const std::string grid = "pattern: circles\nrows: 5\ncols: 5\nspacing_mm: 20\n";
  const std::string one = Tmp("calib_one.yaml"), older = Tmp("calib_older.yaml");
  WriteText(one, "name: one\nplate_views:\n  images: " + sim +
                                       "\n  detection: {polarity: dark}\n" +
                                       std::regex_replace(grid, std::regex("(^|\n)(.)"), "$1  $2") +
                                       "truth: " + sim + "/truth.json\n");
  WriteText(older, "name: older\nimages: " + sim + "\n" + grid + "config: " +
                                         config + "\ntruth: " + sim + "/truth.json\n");
  const std::string skip = " --no-plots --no-mrcal --no-opencv --out ";
  CliRun a = Carmba("calibrate --problem " + one + " --config " + config + skip + Tmp("one"));
  ASSERT_EQ(a.code, 0) << a.err;
  CliRun b = Carmba("calibrate --problem " + older + skip + Tmp("older"));
  ASSERT_EQ(b.code, 0) << b.err;
  CliRun c = Carmba("calibrate --images " + sim + " --pattern circles --rows 5 --cols 5 " +
                    "--spacing-mm 20 --config " + config + skip + Tmp("flags"));
  ASSERT_EQ(c.code, 0) << c.err;
  const nlohmann::json ca = Json(Tmp("one") + "/camera.json");
  for (const std::string other : {"older", "flags"}) {
    const nlohmann::json cb = Json(Tmp(other) + "/camera.json");
    for (const char* key : {"fx", "fy", "cx", "cy", "distortion", "sigmas", "sigma_px"}) {
      EXPECT_EQ(ca[key], cb[key]) << other << " " << key;
    }
  }
  // The truth named in the problem is compared in the report, as --truth is.
  EXPECT_NE(carmba::test::ReadTextFile(Tmp("one") + "/report.md").find("truth"), std::string::npos);
}

// What `carmba calibrate` does not solve is refused naming the key, and a --problem excludes the
// plate flags.
TEST(CalibE2E, ProblemKeysCalibrateDoesNotSolveAreRefused) {
  const std::string sim = Simulated("thesis_calibration");
  const std::string plate = "plate_views: {images: " + sim +
                            ", pattern: circles, rows: 5, cols: 5, spacing_mm: 20";
  const std::string free = Tmp("calib_free_plate.yaml"), roi = Tmp("calib_roi.yaml");
  WriteText(free, "name: f\n" + plate + ", plate: {free: true}}\n");
  WriteText(roi,
                              "name: r\n" + plate + ", detection: {roi_px: [0, 0, 20, 20]}}\n");
  ExpectFailsCleanly("calibrate --problem " + free, "plate_views.plate.free");
  // The problem's detection options are used: a 20 px region of interest holds no grid.
  ExpectFailsCleanly("calibrate --problem " + roi, "key 'plate_views.images': the grid");
  ExpectFailsCleanly("calibrate --problem " + free + " --rows 6",
                     "--rows: the --problem names the plate views");
  const std::string pose = std::string(CARMBA_SOURCE_DIR) + "/problems/thesis_pose.yaml";
  ExpectFailsCleanly("calibrate --problem " + pose, "no plate_views");
}

TEST(CalibE2E, BadInputs) {
  const std::string empty = Tmp("empty_dir");
  fs::create_directories(empty);
  ExpectFailsCleanly("calibrate --images " + empty + " --pattern circles", "--images");

  const std::string junk = Tmp("junk_dir");
  fs::create_directories(junk);
  std::ofstream(junk + "/a.png") << "not an image";
  ExpectFailsCleanly("calibrate --images " + junk + " --pattern circles", "unreadable image");

  const std::string sim = Simulated("thesis_calibration");
  ExpectFailsCleanly("calibrate --images '" + sim + "/*.png' --pattern circles --rows 4 --cols 9",
                     "found in 0 of 20 images");
  ExpectFailsCleanly(
      "calibrate --images '" + sim + "/*.png' --pattern chessboard --rows 5 --cols 5",
      "found in 0 of 20 images");

  ExpectFailsCleanly("calibrate --images '" + sim + "/*.png' --spacing_mm -20",
                     "--spacing-mm: expected 0 (not given) or 0.1 .. 1000 mm, got -20");
  ExpectFailsCleanly("calibrate --images '" + sim + "/*.png' --config " + empty,
                     "is a directory");
  // A sphere diameter in centimetres or metres, or spheres wider than the pitch.
  ExpectFailsCleanly("calibrate --images '" + sim + "/*.png' --sphere-diameter-mm 3060",
                     "--sphere-diameter-mm: expected 0 (not known) or 0.1 .. 100 mm, got 3060");
  ExpectFailsCleanly("calibrate --images '" + sim + "/*.png' --sphere-diameter-mm 30",
                     "grid: sphere_diameter_mm 30 is not below the spacing 20 mm");
  const std::string wide = Tmp("calib_wide_spheres.yaml");
  WriteText(wide,
            "name: w\nplate_views: {images: " + sim +
                ", pattern: circles, rows: 5, cols: 5, spacing_mm: 20, "
                "sphere_diameter_mm: 25}\n");
  ExpectFailsCleanly("calibrate --problem " + wide, "plate_views.sphere_diameter_mm");

  // A config says how to solve: what older configs also held is refused, naming where it went.
  const std::string old_detection = Tmp("calib_old_detection.yaml");
  WriteText(old_detection, "fix: []\ndetection: {polarity: dark}\n");
  ExpectFailsCleanly("calibrate --images '" + sim + "/*.png' --config " + old_detection,
                     "key 'detection': the plate's detection options belong to the data: the "
                     "problem's plate_views.detection, or calibrate --detection FILE");
  const std::string old_cross = Tmp("calib_old_crosscheck.yaml");
  WriteText(old_cross, "crosscheck: {opencv: false}\n");
  ExpectFailsCleanly("calibrate --images '" + sim + "/*.png' --config " + old_cross,
                     "key 'crosscheck': the cross-checks are calibrate's flags: --no-mrcal, "
                     "--no-opencv");
  // --detection is used (a 20 px region holds no grid), is checked, and is for images only.
  const std::string roi = Tmp("calib_detection_roi.yaml"), bad = Tmp("calib_detection_bad.yaml");
  WriteText(roi, "roi_px: [0, 0, 20, 20]\n");
  WriteText(bad, "polarity: darker\n");
  ExpectFailsCleanly("calibrate --images '" + sim + "/*.png' --detection " + roi,
                     "found in 0 of 20 images");
  ExpectFailsCleanly("calibrate --images '" + sim + "/*.png' --detection " + bad,
                     "calib_detection_bad.yaml:1: key 'polarity'");
  ExpectFailsCleanly("calibrate --observations " + roi + " --detection " + roi,
                     "--detection: the --observations are already detected");
  EXPECT_EQ(Carmba("calibrate --observations " + roi + " --detection " + roi + " --out " +
                   Tmp("out_usage"))
                .code,
            2);  // a usage error

  // All fronto-parallel views (pre-detected observations): degenerate.
  carmba::SyntheticViewsOptions so;
  so.min_tilt_deg = so.max_tilt_deg = 0;
  carmba::GridSpec g;
  const auto obs =
      carmba::MakeSyntheticViews({2061, 2255, 204, 205, 0, 0, 0, 0, 0}, 408, 408, g, so);
  const std::string csv = Tmp("fronto.csv");
  ASSERT_TRUE(carmba::WriteObservationsCsv(obs, csv).ok());
  ExpectFailsCleanly("calibrate --observations " + csv, "fronto-parallel");

  std::ofstream(Tmp("bad.csv")) << "# grid: circles 5 5 20\n# image_size: 408 408\n"
                                   "view,image,point,u_px,v_px\n0,a,0,1.0,nan\n";
  ExpectFailsCleanly("calibrate --observations " + Tmp("bad.csv"), "bad.csv:4");
}

// A truncated PNG among good images: carmba's one-line error only (no "libpng error: ..." from
// the decoder). A pattern smaller than the plate (4 x 5 or 5 x 4 on the 5 x 5 plate): every view
// would pick its own sub-window of the plate, so no view is accepted.
TEST(CalibE2E, TruncatedImageAndPatternSmallerThanPlate) {
  const std::string sim = Simulated("thesis_calibration");
  const std::string dir = Tmp("truncated_dir");
  fs::remove_all(dir);
  fs::create_directories(dir);
  for (int i = 1; i <= 3; ++i) {
    const std::string name = "calib_00" + std::to_string(i) + ".png";
    fs::copy_file(sim + "/" + name, dir + "/" + name);
  }
  const std::string whole = carmba::test::ReadTextFile(sim + "/calib_004.png");
  std::ofstream(dir + "/calib_004.png", std::ios::binary) << whole.substr(0, whole.size() / 2);
  const std::string out = Tmp("out_truncated");
  fs::remove_all(out);
  CliRun r = Carmba("calibrate --images '" + dir + "/*.png' --out " + out);
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("calib_004.png: unreadable image"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("libpng"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));

  ExpectFailsCleanly("calibrate --images '" + sim + "/*.png' --pattern circles --rows 4 --cols 5",
                     "found in 0 of 20 images");
  ExpectFailsCleanly("calibrate --images '" + sim + "/*.png' --pattern circles --rows 5 --cols 4",
                     "found in 0 of 20 images");
}

}  // namespace
