// `carmba pose` end to end on the simulated clutter scene (configs/scenes/markers_clutter.yaml):
// images -> marker blobs -> labels -> bundle adjustment with per-blob sigmas; and its bad input.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "cli/cli_test_util.h"
#include "cli/report_browser.h"
#include "figures.h"

namespace carmba::test {
namespace {

namespace fs = std::filesystem;

class PoseCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new ScratchDir();
    ASSERT_EQ(LinkSimulatedScene("markers_clutter", dir_->File("sim")), "");  // read only
    truth_ = nlohmann::json::parse(ReadTextFile(dir_->File("sim/truth.json")));
    // camera.json: the simulator's camera; fiducials.csv: the object's true centres with a
    // 0.1 mm CT sigma (as `carmba ct-fiducials` writes them).
    std::ofstream(dir_->File("camera.json")) << truth_["camera"].dump(2);
    std::ofstream f(dir_->File("fiducials.csv"));
    f << "# test fiducials\nid,x_mm,y_mm,z_mm,cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz\n";
    const auto& obj = truth_["object"];
    for (size_t k = 0; k < obj["sphere_ids"].size(); ++k) {
      const auto& c = obj["centers_mm"][k];
      f << obj["sphere_ids"][k].get<int>() << "," << c[0].get<double>() << "," << c[1].get<double>()
        << "," << c[2].get<double>() << ",0.01,0,0,0.01,0,0.01\n";
    }
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static std::string Args(const std::string& images) {
    return "pose --images '" + images + "' --fiducials " + dir_->File("fiducials.csv") +
           " --camera " + dir_->File("camera.json") +
           " --marker_diameter_mm 2 --source_to_object_mm 700";
  }
  static ScratchDir* dir_;
  static nlohmann::json truth_;
};
ScratchDir* PoseCli::dir_ = nullptr;
nlohmann::json PoseCli::truth_;

TEST_F(PoseCli, WritesObservationsOverlaysAndTheBundleAdjustment) {
  const std::string out = dir_->File("out");
  const auto r = RunCarmba(Args(dir_->File("sim/*.png")) + " --out " + out);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string csv = ReadTextFile(out + "/observations.csv");
  EXPECT_NE(csv.find("\nview,marker,u_px,v_px,cov_uu,cov_uv,cov_vv\n"), std::string::npos);
  // 9 markers in 5 views, 8 in the partial view, 7 in the overlap view.
  EXPECT_EQ(CountLines(csv) - 3, 5 * 9 + 8 + 7);
  int overlays = 0;
  for (const auto& e : fs::directory_iterator(out))
    overlays += e.path().filename().string().rfind("overlay_", 0) == 0;
  EXPECT_EQ(overlays, 7);
  const auto j = nlohmann::json::parse(ReadTextFile(out + "/result.json"));
  ASSERT_EQ(j["views"].size(), 7u);
  // The per-blob covariances are honest: the a-posteriori factor near 1 (true camera, exact CT
  // centres, so the pixel noise is all there is; each observation whitened by its blob's full 2x2
  // covariance, which is conservative over anatomy: sigma0 below 1).
  const double sigma0 = j["statistics"]["sigma0"].get<double>();
  testing::RecordFigure("posecli.sigma0", "%.2f", sigma0);
  std::cout << "pose on the clutter scene: sigma0 " << sigma0 << ", RMS "
            << j["statistics"]["rms_px"] << " px\n";
  EXPECT_GT(sigma0, 0.5);
  EXPECT_LT(sigma0, 1.5);
  // Each view's translation within 4 sigma of the truth.
  for (size_t v = 0; v < j["views"].size(); ++v) {
    const auto& jv = j["views"][v];
    const std::string id = jv["id"];
    nlohmann::json tv;
    // Views are named by their file's stem (the file is kept in marker_detection[].image).
    for (const auto& t : truth_["views"]) {
      if (fs::path(t["file"].get<std::string>()).stem().string() == id)
        tv = t["cam_from_object"]["t_mm"];
    }
    ASSERT_FALSE(tv.is_null()) << id;
    for (int a = 0; a < 3; ++a) {
      const double err = jv["cam_from_object"]["t_mm"][a].get<double>() - tv[a].get<double>();
      EXPECT_LT(std::fabs(err), 4 * jv["sigma_translation_mm"][a].get<double>() + 1e-3)
          << jv["id"] << " axis " << a;
    }
  }
  EXPECT_NE(ReadTextFile(out + "/report.md").find("Marker detection and labelling"),
            std::string::npos);
  // The blur's pull (the scene's 0.6 px blur on the PMMA block's sloping background) is measured
  // and removed per view, and stated: thousandths of a pixel here.
  for (const auto& det : j["marker_detection"]) {
    EXPECT_GT(det["blur_variance_px2"].get<double>(), 0.1) << det["image"];
    EXPECT_GT(det["blur_correction_max_px"].get<double>(), 0.0) << det["image"];
    EXPECT_LT(det["blur_correction_max_px"].get<double>(), 0.05) << det["image"];
  }
  EXPECT_NE(ReadTextFile(out + "/report.md").find("| blur pull px |"), std::string::npos);
  // report.html: the same report with its plots, rendered in a browser.
  EXPECT_NE(ReadTextFile(out + "/report.html").find("Marker detection and labelling"),
            std::string::npos);
  ExpectReportRenders(out + "/report.html", 2);
}

// A problem naming object_views: {images, detection} instead of observations: object views only,
// so a pose problem (the intrinsics held at camera.json), solved by the pose front end.
TEST_F(PoseCli, JointProblemWithObjectViewImages) {
  dir_->Write(
      "problem.yaml",
      "name: pose_from_images\ncamera: camera.json\nfiducials: fiducials.csv\n"
      "object_views:\n  images: sim/*.png\n"
      "  detection: {diameter_mm: 2, source_to_object_mm: 700}\n");
  dir_->Write("fixed.yaml", "name: fixed_intrinsics\nfix: [fx, fy, cx, cy, k1, k2, p1, p2, k3]\n");
  const std::string out = dir_->File("joint_out");
  const auto r = RunCarmba("solve --problem " + dir_->File("problem.yaml") + " --config " +
                           dir_->File("fixed.yaml") + " --no-plots --out " + out);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("solved pose_from_images with fixed_intrinsics: 7 views"), std::string::npos)
      << r.out;
  // Images and observations together are an error naming the key.
  dir_->Write(
      "both.yaml",
      "name: both\ncamera: camera.json\nfiducials: fiducials.csv\n"
      "object_views:\n  images: sim/*.png\n  observations: obs.csv\n"
      "  detection: {diameter_mm: 2}\n");
  const auto b = RunCarmba("solve --problem " + dir_->File("both.yaml") + " --config " +
                           dir_->File("fixed.yaml") + " --out " + dir_->File("both_out"));
  EXPECT_NE(b.exit_code, 0);
  EXPECT_NE(b.err.find("object_views.observations"), std::string::npos) << b.err;
  EXPECT_FALSE(fs::exists(dir_->File("both_out")));
}

TEST_F(PoseCli, BadInputIsAOneLineErrorAndNoOutput) {
  struct Case {
    std::string args, expected;
  };
  ScratchDir bad;
  std::ofstream(bad.File("corrupt.png")) << "not an image";
  // Another object's 9 fiducials (a different layout of the same size).
  std::string other = "id,x_mm,y_mm,z_mm,cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz\n";
  const double xyz[9][3] = {{0, 0, 0},
                            {35, 5, 2},
                            {-20, 30, 10},
                            {10, -25, 18},
                            {-40, -10, 25},
                            {25, 28, 33},
                            {-5, 12, 41},
                            {30, -15, 47},
                            {-30, 22, 52}};
  for (int k = 0; k < 9; ++k) {
    other += std::to_string(k + 1) + "," + std::to_string(xyz[k][0]) + "," +
             std::to_string(xyz[k][1]) + "," + std::to_string(xyz[k][2]) +
             ",0.01,0,0,0.01,0,0.01\n";
  }
  bad.Write("other.csv", other);
  const std::string base = Args(dir_->File("sim/*.png"));
  const std::vector<Case> cases = {
      {Args(bad.File("corrupt.png")), bad.File("corrupt.png") + ": unreadable image"},
      {Args(bad.File("missing.png")), "missing.png"},
      {"pose --images '" + dir_->File("sim/*.png") + "' --fiducials " + bad.File("other.csv") +
           " --camera " + dir_->File("camera.json") +
           " --marker_diameter_mm 2 --source_to_object_mm 700",
       "no view could be labelled"},
      {"pose --images '" + dir_->File("sim/*.png") + "' --fiducials " +
           dir_->File("fiducials.csv") + " --camera " + dir_->File("camera.json"),
       "marker diameter"},
  };
  for (const Case& c : cases) {
    const std::string out = bad.File("out");
    const auto r = RunCarmba(c.args + " --out " + out);
    EXPECT_NE(r.exit_code, 0) << c.args;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(c.expected), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(out)) << c.args;
  }
}

}  // namespace
}  // namespace carmba::test
