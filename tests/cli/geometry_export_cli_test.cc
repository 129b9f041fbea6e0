// End-to-end tests of geometry.json (written by `carmba solve`), `carmba export-geometry` and
// `carmba undistort`, and their bad input one corruption at a time.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "camera/camera_model.h"
#include "cli_test_util.h"
#include "export/rtk_geometry.h"
#include "export/view_geometry.h"
#include "geometry/rotation.h"
#include "io/dicom_xray.h"
#include "util/image_codecs.h"

namespace carmba::test {
namespace {


TEST(GeometryCli, PoseSolveWritesTheProjectionMatricesOfItsPoses) {
  ScratchDir out;
  const auto r =
      RunCarmba("solve --problem=" + kSource + "/problems/thesis_pose.yaml --config=" + kSource +
                "/configs/posit_ba_analytic.yaml --no-plots --out=" + out.path());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto g = ReadGeometryJson(out.File("geometry.json"));
  ASSERT_TRUE(g.ok()) << g.status().message();
  const nlohmann::json j = ReadJsonFile(out.File("result.json"));
  ASSERT_EQ(g->views.size(), j.at("views").size());
  ASSERT_TRUE(g->reference_point_ct_mm.has_value());
  // The thesis problem's object frame is the CT frame mirrored (handedness: mirrored): P maps the
  // CT point (x, y, z) to the pixel the pose maps the object point (x, -y, z) to.
  for (size_t k = 0; k < g->views.size(); ++k) {
    const auto& vj = j.at("views")[k];
    EXPECT_EQ(g->views[k].id, vj.at("id").get<std::string>());
    EXPECT_TRUE(g->views[k].ct_mirrored);
    double pose[6];
    for (int i = 0; i < 3; ++i) pose[i] = vj.at("cam_from_object").at("rvec")[i].get<double>();
    for (int i = 0; i < 3; ++i) pose[3 + i] = vj.at("cam_from_object").at("t_mm")[i].get<double>();
    const Matrix34 P = ProjectionMatrix(g->views[k]);
    for (const auto& m : j.at("markers")) {
      const double p_obj[3] = {m.at("p_in_object_mm")[0].get<double>(),
                               m.at("p_in_object_mm")[1].get<double>(),
                               m.at("p_in_object_mm")[2].get<double>()};
      double uv[2];
      std::array<double, kNumIntrinsics> pinhole = g->views[k].camera.params;
      std::fill(pinhole.begin() + 4, pinhole.end(), 0.0);
      ASSERT_TRUE(ProjectPoint(pinhole.data(), pose, p_obj, uv));
      Eigen::Vector2d q;
      ASSERT_TRUE(ProjectWithMatrix(P, Eigen::Vector3d(p_obj[0], -p_obj[1], p_obj[2]), &q));
      EXPECT_LT((q - Eigen::Vector2d(uv[0], uv[1])).norm(), 1e-8);
    }
  }
  // json export is a copy; RTK and plastimatch refuse the mirrored frame, naming it, with no
  // output.
  auto e = RunCarmba("export-geometry --result " + out.path() + " --format json --out " +
                     out.File("exp"));
  ASSERT_EQ(e.exit_code, 0) << e.err;
  EXPECT_TRUE(ReadGeometryJson(out.File("exp/geometry.json")).ok());
  for (const char* f : {"rtk", "plastimatch", "all"}) {
    e = RunCarmba("export-geometry --result " + out.path() + " --format " + f + " --out " +
                  out.File(std::string("bad_") + f));
    EXPECT_NE(e.exit_code, 0) << f;
    EXPECT_EQ(CountLines(e.err), 1) << e.err;
    EXPECT_NE(e.err.find("mirrored"), std::string::npos) << e.err;
    EXPECT_FALSE(std::filesystem::exists(out.File(std::string("bad_") + f)));
  }
}

// A right-handed geometry (two views) written as geometry.json.
std::string WriteGeometry(const ScratchDir& dir) {
  GeometrySet set;
  for (int k = 0; k < 2; ++k) {
    ViewGeometry v;
    v.id = "view " + std::to_string(k);
    v.camera.width = 408;
    v.camera.height = 408;
    v.camera.params = {2061.389, 2254.646, 203.655, 205.117, -2.5, 0, 0, 0, 0};
    v.cam_from_ct << 0.1 + 0.8 * k, -0.4, 0.2, 10, -20 + k, 700;
    v.sid_mm = 1000;
    set.views.push_back(v);
  }
  set.reference_point_ct_mm = Eigen::Vector3d(0, 0, 0);
  dir.Write("geometry.json", GeometryToJson(set).dump(2));
  return dir.File("geometry.json");
}

TEST(ExportGeometryCli, AllFormatsAndTheirRoundTrip) {
  ScratchDir dir;
  const std::string geometry = WriteGeometry(dir);
  const auto r = RunCarmba("export-geometry --result " + geometry + " --out " + dir.File("out"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* f : {"geometry.json", "rtk_geometry.xml", "rtk_detector.json",
                        "plastimatch/0000_view_0.txt", "plastimatch/0001_view_1.txt",
                        "plastimatch/drr.sh"}) {
    EXPECT_TRUE(std::filesystem::exists(dir.File(std::string("out/") + f))) << f;
  }
  auto set = ReadGeometryJson(geometry);
  ASSERT_TRUE(set.ok());
  auto rtk = ReadRtkGeometryXml(dir.File("out/rtk_geometry.xml"));
  ASSERT_TRUE(rtk.ok()) << rtk.status().message();
  const nlohmann::json det = ReadJsonFile(dir.File("out/rtk_detector.json"));
  RtkDetector d;
  d.width = det.at("size_px")[0].get<int>();
  d.height = det.at("size_px")[1].get<int>();
  d.spacing_u_mm = det.at("spacing_mm")[0].get<double>();
  d.spacing_v_mm = det.at("spacing_mm")[1].get<double>();
  for (size_t k = 0; k < 2; ++k) {
    EXPECT_LT(RelativeMatrixDifference(PixelMatrixFromRtk((*rtk)[k].matrix, d),
                                       ProjectionMatrix(set->views[k])),
              1e-9);
    // SDD is the views' nominal sid_mm.
    EXPECT_DOUBLE_EQ((*rtk)[k].sdd_mm, 1000);
  }
  EXPECT_NEAR(det.at("anisotropy_fx_over_fy").get<double>(), 2061.389 / 2254.646, 1e-12);
}

TEST(ExportGeometryCli, BadInputIsOneLineAndNoOutput) {
  ScratchDir dir;
  const std::string geometry = WriteGeometry(dir);
  auto expect_error = [&](const std::string& args, const std::string& expected) {
    const auto r = RunCarmba("export-geometry " + args + " --out " + dir.File("out"));
    EXPECT_NE(r.exit_code, 0) << args;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(expected), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir.File("out"))) << args;
  };
  expect_error("", "--result");
  expect_error("--result " + geometry + " --format vtk", "--format: expected rtk, plastimatch");
  expect_error("--result " + geometry + " --sdd_mm -5", "--sdd-mm: expected");
  expect_error("--result " + dir.File("missing"), "missing");
  dir.Write("other.json", "{\"views\": []}");
  expect_error("--result " + dir.File("other.json"), "key 'format'");
  nlohmann::json j = ReadJsonFile(geometry);
  j["views"][1]["P"][2][0] = 0.5;
  dir.Write("edited.json", j.dump());
  expect_error("--result " + dir.File("edited.json"), "views[1].P: differs");
  j = ReadJsonFile(geometry);
  j["views"][1]["camera"]["image_size"] = {400, 408};
  j["views"][1].erase("P");
  dir.Write("sizes.json", j.dump());
  expect_error("--result " + dir.File("sizes.json") + " --format rtk",
               "view 'view 1': image size 400x408 differs");
}

TEST(UndistortCli, SixteenBitImagesAndDicomFramesKeepTheirDepth) {
  ScratchDir dir;
  dir.Write("camera.json",
            "{\"image_size\": [64, 48], \"fx\": 300, \"fy\": 320, \"cx\": 31.5, \"cy\": 23.5, "
            "\"distortion\": [-0.5, 0, 0, 0, 0]}");
  std::filesystem::create_directories(dir.File("in"));
  cv::Mat img(48, 64, CV_16UC1);
  for (int v = 0; v < 48; ++v) {
    for (int u = 0; u < 64; ++u) img.at<uint16_t>(v, u) = static_cast<uint16_t>(300 * u + 17 * v);
  }
  ASSERT_TRUE(carmba::ImWrite(dir.File("in/a.png"), img));
  DicomXrayWriteOptions o;
  ASSERT_TRUE(WriteDicomXray(dir.File("in/run.dcm"), {img, img}, o).ok());
  const auto r = RunCarmba("undistort --images " + dir.File("in") + " --camera " +
                           dir.File("camera.json") + " --out " + dir.File("out"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* f : {"a.png", "run_frame1.png", "run_frame2.png"}) {
    const cv::Mat m = carmba::ImRead(dir.File(std::string("out/") + f), cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(m.empty()) << f;
    EXPECT_EQ(m.type(), CV_16UC1) << f;
    EXPECT_EQ(m.size(), img.size()) << f;
    // At the principal point the distortion is nil: the value is the original's (bilinear at
    // (31.5, 23.5) of a linear ramp).
    EXPECT_NEAR(m.at<uint16_t>(23, 31), 300 * 31 + 17 * 23, 20) << f;
    EXPECT_GT(m.at<uint16_t>(23, 63), m.at<uint16_t>(23, 62)) << f;
  }
}

TEST(UndistortCli, BadInputIsOneLineAndNoOutput) {
  ScratchDir dir;
  dir.Write("camera.json",
            "{\"image_size\": [64, 48], \"fx\": 300, \"fy\": 320, \"cx\": 31.5, \"cy\": 23.5}");
  std::filesystem::create_directories(dir.File("in"));
  ASSERT_TRUE(carmba::ImWrite(dir.File("in/a.png"), cv::Mat(48, 64, CV_16UC1, cv::Scalar(5))));
  ASSERT_TRUE(carmba::ImWrite(dir.File("in/b.png"), cv::Mat(40, 64, CV_16UC1, cv::Scalar(5))));
  auto expect_error = [&](const std::string& args, const std::string& expected) {
    const auto r = RunCarmba("undistort " + args + " --out " + dir.File("out"));
    EXPECT_NE(r.exit_code, 0) << args;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(expected), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir.File("out"))) << args;
  };
  expect_error("--images " + dir.File("in"), "--camera is required");
  expect_error("--images " + dir.File("in") + " --camera " + dir.File("nope.json"), "nope.json");
  // b.png is 64x40: an error naming it, and a.png is not left behind either.
  expect_error("--images " + dir.File("in") + " --camera " + dir.File("camera.json"),
               "b.png: image is 64x40 px, the camera's image_size 64x48");
  dir.Write("bad_camera.json",
            "{\"image_size\": [64, 48], \"fx\": -3, \"fy\": 320, \"cx\": 1, \"cy\": 1}");
  expect_error("--images " + dir.File("in/a.png") + " --camera " + dir.File("bad_camera.json"),
               "fx");
}

}  // namespace
}  // namespace carmba::test
