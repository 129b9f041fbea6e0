// End-to-end `carmba detect` / `carmba calibrate --images` on DICOM: the simulator's thesis
// calibration plate (20 views) as PNGs and as ONE multi-frame JPEG-lossless 16-bit XA file; both
// commands give the same result from either, the DICOM views named file.dcm#frameN. And a broken
// DICOM file: a one-line error naming it, no output.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "cli/cli_test_util.h"
#include "detect/observations.h"
#include "io/dicom_xray.h"
#include "sim/xray_scene.h"
#include "util/image_codecs.h"

namespace carmba {
namespace {

namespace fs = std::filesystem;
using test::RunCarmba;
using test::ScratchDir;

// Renders the scene's views (3 x 3 supersampling instead of the scene's 5 x 5: twice as fast, and
// PNG and DICOM get the same pixels either way) into dir/png/*.png and dir/dcm/run.dcm.
void RenderBoth(const ScratchDir& dir) {
  auto scene = sim::LoadXrayScene(std::string(CARMBA_SOURCE_DIR) +
                                  "/configs/scenes/thesis_calibration.yaml");
  ASSERT_TRUE(scene.ok()) << scene.status().message();
  scene->bit_depth = 16;
  scene->render.supersampling = 3;
  auto grid = sim::RayGrid::Build(scene->camera, scene->render);
  ASSERT_TRUE(grid.ok());
  fs::create_directories(dir.File("png"));
  fs::create_directories(dir.File("dcm"));
  std::vector<cv::Mat> frames;
  for (int i = 0; i < static_cast<int>(scene->views.size()); ++i) {
    auto v = sim::RenderXrayView(*scene, i, grid->get());
    ASSERT_TRUE(v.ok()) << v.status().message();
    char name[32];
    std::snprintf(name, sizeof(name), "png/view_%02d.png", i + 1);
    ASSERT_TRUE(carmba::ImWrite(dir.File(name), v->image));
    frames.push_back(v->image);
  }
  DicomXrayWriteOptions o;
  o.transfer_syntax = "jpeg_lossless";
  const Status s = WriteDicomXray(dir.File("dcm/run.dcm"), frames, o);
  ASSERT_TRUE(s.ok()) << s.message();
}

TEST(DicomCli, DetectAndCalibrateFromAMultiFrameXaFileAsFromPngs) {
  ScratchDir dir;
  RenderBoth(dir);
  if (HasFatalFailure()) return;
  const std::string grid = " --pattern circles --rows 5 --cols 5 --spacing_mm 20";
  auto d_png =
      RunCarmba("detect --images " + dir.File("png") + grid + " --out " + dir.File("png.csv"));
  ASSERT_EQ(d_png.exit_code, 0) << d_png.err;
  auto d_dcm =
      RunCarmba("detect --images " + dir.File("dcm") + grid + " --out " + dir.File("dcm.csv"));
  ASSERT_EQ(d_dcm.exit_code, 0) << d_dcm.err;
  EXPECT_NE(d_dcm.out.find("found the grid in 20 of 20 images"), std::string::npos) << d_dcm.out;
  auto png = ReadObservationsCsv(dir.File("png.csv"));
  auto dcm = ReadObservationsCsv(dir.File("dcm.csv"));
  ASSERT_TRUE(png.ok() && dcm.ok());
  ASSERT_EQ(png->views.size(), 20u);
  ASSERT_EQ(dcm->views.size(), 20u);
  for (size_t v = 0; v < 20; ++v) {
    EXPECT_EQ(dcm->views[v].image, dir.File("dcm/run.dcm") + "#frame" + std::to_string(v + 1));
    EXPECT_EQ(dcm->views[v].point_ids, png->views[v].point_ids);
    for (size_t i = 0; i < png->views[v].uv_px.size(); ++i) {
      // The CSV rounds both the same way: equal text, equal numbers.
      EXPECT_EQ(dcm->views[v].uv_px[i], png->views[v].uv_px[i]) << "view " << v;
    }
  }
  // One frame named on the command line.
  auto d_one = RunCarmba("detect --images '" + dir.File("dcm/run.dcm") + "#frame7'" + grid +
                         " --out " + dir.File("one.csv"));
  ASSERT_EQ(d_one.exit_code, 0) << d_one.err;
  EXPECT_NE(d_one.out.find("found the grid in 1 of 1 images"), std::string::npos) << d_one.out;

  auto c_png = RunCarmba("calibrate --images " + dir.File("png") + grid +
                         " --nomrcal --noopencv --no-plots" + " --out " + dir.File("cal_png"));
  ASSERT_EQ(c_png.exit_code, 0) << c_png.err;
  auto c_dcm = RunCarmba("calibrate --images " + dir.File("dcm") + grid +
                         " --nomrcal --noopencv --no-plots" + " --out " + dir.File("cal_dcm"));
  ASSERT_EQ(c_dcm.exit_code, 0) << c_dcm.err;
  const auto a = nlohmann::json::parse(test::ReadTextFile(dir.File("cal_png/camera.json")));
  const auto b = nlohmann::json::parse(test::ReadTextFile(dir.File("cal_dcm/camera.json")));
  for (const char* k : {"fx", "fy", "cx", "cy"}) {
    ASSERT_TRUE(a.contains(k)) << k;
    EXPECT_EQ(a[k].get<double>(), b[k].get<double>()) << k;
  }
  // Sanity: the thesis intrinsics (fx 2061.389) within a few px.
  EXPECT_NEAR(b["fx"].get<double>(), 2061.389, 20);
}

TEST(DicomCli, TruncatedDicomFileIsAOneLineErrorNamingIt) {
  ScratchDir dir;
  DicomXrayWriteOptions o;
  const std::string path = dir.File("broken.dcm");
  ASSERT_TRUE(WriteDicomXray(path, {cv::Mat(64, 64, CV_16UC1, cv::Scalar(1000))}, o).ok());
  fs::resize_file(path, 1000);
  auto r = RunCarmba("detect --images " + path + " --out " + dir.File("o.csv"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find(path + ": corrupt DICOM file: truncated"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_FALSE(fs::exists(dir.File("o.csv")));
}

}  // namespace
}  // namespace carmba
