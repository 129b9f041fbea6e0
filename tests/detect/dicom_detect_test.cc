// Detection from DICOM: the simulator's calibration plate rendered as 16-bit images, written as
// PNG and as DICOM XA (single-frame files, and one multi-frame JPEG-lossless file), detected from
// each: the same points. Plus the view naming of multi-frame files and the directory listing.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "detect/grid_detector.h"
#include "io/dicom_xray.h"
#include "io/image_files.h"
#include "scratch.h"
#include "sim/xray_scene.h"
#include "util/file_util.h"
#include "util/image_codecs.h"

namespace carmba {
namespace {

namespace fs = std::filesystem;
using test::ScratchDir;

constexpr int kViews = 3;

// The first kViews views of the thesis calibration scene as 16-bit images (with the scene's
// noise), and their true sphere centres.
struct Rendered {
  std::vector<cv::Mat> images;
  std::vector<std::vector<Eigen::Vector2d>> centers_px;
  GridSpec grid;
};

const Rendered& Render() {
  static const Rendered r = [] {
    Rendered out;
    auto scene = sim::LoadXrayScene(std::string(CARMBA_SOURCE_DIR) +
                                    "/configs/scenes/thesis_calibration.yaml");
    EXPECT_TRUE(scene.ok()) << scene.status().message();
    scene->bit_depth = 16;
    auto grid = sim::RayGrid::Build(scene->camera, scene->render);
    EXPECT_TRUE(grid.ok());
    for (int i = 0; i < kViews; ++i) {
      auto v = sim::RenderXrayView(*scene, i, grid->get());
      EXPECT_TRUE(v.ok()) << v.status().message();
      EXPECT_EQ(v->image.type(), CV_16UC1);
      out.images.push_back(v->image);
      out.centers_px.push_back(v->centers_px);
    }
    out.grid.rows = scene->plate.rows;
    out.grid.cols = scene->plate.cols;
    out.grid.spacing_mm = scene->plate.pitch_mm;
    return out;
  }();
  return r;
}

// Same views, same ids, bit-identical centres (the pixels are identical, so is the detection).
void ExpectSameObservations(const ObservationSet& a, const ObservationSet& b) {
  ASSERT_EQ(a.views.size(), b.views.size());
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  for (size_t v = 0; v < a.views.size(); ++v) {
    ASSERT_EQ(a.views[v].point_ids, b.views[v].point_ids) << "view " << v;
    for (size_t i = 0; i < a.views[v].uv_px.size(); ++i) {
      EXPECT_EQ(a.views[v].uv_px[i], b.views[v].uv_px[i]) << "view " << v << " point " << i;
    }
  }
}

TEST(DicomDetect, SimulatedPlateSamePointsFromDicomAsFromPng) {
  const Rendered& r = Render();
  ScratchDir dir;
  std::vector<std::string> png, dcm;
  for (int i = 0; i < kViews; ++i) {
    png.push_back(dir.File("view_" + std::to_string(i) + ".png"));
    dcm.push_back(dir.File("view_" + std::to_string(i) + ".dcm"));
    ASSERT_TRUE(carmba::ImWrite(png.back(), r.images[i]));
    DicomXrayWriteOptions o;
    o.geometry.sid_mm = 1000;
    ASSERT_TRUE(WriteDicomXray(dcm.back(), {r.images[i]}, o).ok());
  }
  DicomXrayWriteOptions jpeg;
  jpeg.transfer_syntax = "jpeg_lossless";
  const std::string multi = dir.File("run.dcm");
  ASSERT_TRUE(WriteDicomXray(multi, r.images, jpeg).ok());

  std::vector<std::string> skipped;
  auto from_png = DetectGridInFiles(png, r.grid, DetectionOptions(), &skipped);
  ASSERT_TRUE(from_png.ok()) << from_png.status().message();
  ASSERT_TRUE(skipped.empty()) << skipped[0];
  ASSERT_EQ(from_png->views.size(), static_cast<size_t>(kViews));
  auto from_dcm = DetectGridInFiles(dcm, r.grid, DetectionOptions(), &skipped);
  ASSERT_TRUE(from_dcm.ok()) << from_dcm.status().message();
  ExpectSameObservations(*from_png, *from_dcm);
  EXPECT_EQ(from_dcm->views[1].image, dcm[1]);
  double per_view_s = 0;
  auto from_multi = DetectGridInFiles({multi}, r.grid, DetectionOptions(), &skipped, &per_view_s);
  ASSERT_TRUE(from_multi.ok()) << from_multi.status().message();
  ExpectSameObservations(*from_png, *from_multi);
  for (int i = 0; i < kViews; ++i) {
    EXPECT_EQ(from_multi->views[i].image, multi + "#frame" + std::to_string(i + 1));
  }
  EXPECT_GT(per_view_s, 0);  // averaged over the 3 frames of the one file

  // The detections are the plate's: every centre within 0.2 px of a true one (the scene's
  // detection noise is ~0.03 px).
  for (int v = 0; v < kViews; ++v) {
    EXPECT_GE(from_multi->views[v].uv_px.size(), 24u);
    for (const auto& uv : from_multi->views[v].uv_px) {
      double best = 1e9;
      for (const auto& t : r.centers_px[v]) best = std::min(best, (uv - t).norm());
      EXPECT_LT(best, 0.2) << "view " << v;
    }
  }
}

TEST(DicomDetect, FramesOfAMultiFrameFileAreViews) {
  ScratchDir dir;
  std::vector<cv::Mat> frames;
  for (int k = 0; k < 3; ++k) frames.push_back(cv::Mat(10, 12, CV_8UC1, cv::Scalar(10 * k + 1)));
  const std::string multi = dir.File("m.dcm");
  DicomXrayWriteOptions o;
  o.geometry.primary_angle_deg = 30;
  o.primary_increment_deg = {5};
  ASSERT_TRUE(WriteDicomXray(multi, frames, o).ok());

  auto all = ReadImageViews(multi);
  ASSERT_TRUE(all.ok()) << all.status().message();
  ASSERT_EQ(all->size(), 3u);
  EXPECT_EQ((*all)[2].name, multi + "#frame3");
  EXPECT_EQ((*all)[2].image.at<uint8_t>(0, 0), 21);
  ASSERT_TRUE((*all)[2].geometry.has_value());
  EXPECT_EQ((*all)[2].geometry->primary_angle_deg, 40.0);  // 30 + 2 x 5

  auto one = ReadImageViews(multi + "#frame2");
  ASSERT_TRUE(one.ok()) << one.status().message();
  ASSERT_EQ(one->size(), 1u);
  EXPECT_EQ((*one)[0].name, multi + "#frame2");
  EXPECT_EQ((*one)[0].image.at<uint8_t>(0, 0), 11);
  EXPECT_EQ((*one)[0].geometry->primary_angle_deg, 35.0);

  auto beyond = ReadImageViews(multi + "#frame4");
  ASSERT_FALSE(beyond.ok());
  EXPECT_NE(
      beyond.status().message().find("m.dcm#frame4: no such frame, " + multi + " has 3 frames"),
      std::string::npos)
      << beyond.status().message();

  auto whole = ReadImageFile(multi);
  ASSERT_FALSE(whole.ok());
  EXPECT_NE(whole.status().message().find("3 frames, name one as " + multi + "#frameN"),
            std::string::npos)
      << whole.status().message();
  auto frame = ReadImageFile(multi + "#frame3");
  ASSERT_TRUE(frame.ok()) << frame.status().message();
  EXPECT_EQ(frame->at<uint8_t>(9, 11), 21);

  // A single-frame DICOM file reads like a PNG; a broken one is an error naming it.
  const std::string single = dir.File("s.dcm");
  ASSERT_TRUE(WriteDicomXray(single, {frames[1]}, DicomXrayWriteOptions()).ok());
  auto s = ReadImageFile(single);
  ASSERT_TRUE(s.ok()) << s.status().message();
  EXPECT_EQ(s->at<uint8_t>(5, 5), 11);
  fs::resize_file(single, 200);
  auto bad = ReadImageFile(single);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().message().rfind(single + ": corrupt DICOM file", 0), 0u)
      << bad.status().message();
}

TEST(DicomDetect, DirectoryListingTakesDicomFilesWithAndWithoutExtension) {
  ScratchDir dir;
  const cv::Mat img(10, 12, CV_8UC1, cv::Scalar(5));
  ASSERT_TRUE(carmba::ImWrite(dir.File("a.png"), img));
  ASSERT_TRUE(WriteDicomXray(dir.File("b.DCM"), {img}, DicomXrayWriteOptions()).ok());
  ASSERT_TRUE(WriteDicomXray(dir.File("c"), {img}, DicomXrayWriteOptions()).ok());  // no extension
  ASSERT_TRUE(WriteDicomXray(dir.File("c.IMA"), {img}, DicomXrayWriteOptions()).ok());  // Siemens
  ASSERT_TRUE(WriteDicomXray(dir.File("1.2.826.0.1.7"), {img}, DicomXrayWriteOptions()).ok());
  // A DICOMDIR has the preamble but no pixels: left out (here any DICOM file stands for one).
  ASSERT_TRUE(WriteDicomXray(dir.File("DICOMDIR"), {img}, DicomXrayWriteOptions()).ok());
  std::ofstream(dir.File("d")) << "not an image, no extension";
  std::ofstream(dir.File("truth.json")) << "{}";
  auto files = ListImageFiles(dir.path());
  ASSERT_TRUE(files.ok()) << files.status().message();
  EXPECT_EQ(*files,
            (std::vector<std::string>{dir.File("1.2.826.0.1.7"),
                                      dir.File("a.png"),
                                      dir.File("b.DCM"),
                                      dir.File("c"),
                                      dir.File("c.IMA")}));
  auto png_views = ReadImageViews(dir.File("a.png"));
  ASSERT_TRUE(png_views.ok()) << png_views.status().message();
  ASSERT_EQ(png_views->size(), 1u);
  EXPECT_FALSE((*png_views)[0].geometry.has_value());
  auto uid_named = ReadImageFile(dir.File("1.2.826.0.1.7"));
  ASSERT_TRUE(uid_named.ok()) << uid_named.status().message();
  // The extension-less DICOM file reads as an image.
  auto c = ReadImageFile(dir.File("c"));
  ASSERT_TRUE(c.ok()) << c.status().message();
  EXPECT_EQ(c->at<uint8_t>(0, 0), 5);
  // One frame named on the command line.
  auto frame = ListImageFiles(dir.File("b.DCM") + "#frame1");
  ASSERT_TRUE(frame.ok()) << frame.status().message();
  EXPECT_EQ(frame->size(), 1u);
}

}  // namespace
}  // namespace carmba
