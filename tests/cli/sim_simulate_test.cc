// End-to-end: `carmba simulate` writes images and truth.json atomically, deterministically, and
// leaves nothing behind on a bad scene.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "cli_test_util.h"
#include "util/image_codecs.h"

namespace {

namespace fs = std::filesystem;

struct SimRun {
  int code;
  std::string err;
};

SimRun Simulate(const std::string& args) {
  const carmba::test::CommandResult r = carmba::test::RunCarmba("simulate " + args);
  return {r.exit_code, r.err};
}

const std::string kScenes = std::string(CARMBA_SOURCE_DIR) + "/configs/scenes/";

TEST(SimulateCli, ThesisPoseWritesImagesAndTruth) {
  const carmba::test::ScratchDir tmp("sim_cli_pose");
  const fs::path out = tmp.File("pose");
  const SimRun r = Simulate("--scene=" + kScenes + "thesis_pose.yaml --out=" + out.string());
  ASSERT_EQ(r.code, 0) << r.err;
  nlohmann::json truth = nlohmann::json::parse(carmba::test::ReadTextFile(out / "truth.json"));
  EXPECT_EQ(truth["kind"], "xray");
  EXPECT_EQ(truth["camera"]["fx"].get<double>(), 2061.389);
  ASSERT_EQ(truth["views"].size(), 7u);
  EXPECT_EQ(truth["object"]["sphere_ids"].size(), 9u);
  for (const auto& v : truth["views"]) {
    const cv::Mat img =
        carmba::ImRead((out / v["file"].get<std::string>()).string(), cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(img.empty()) << v["file"];
    EXPECT_EQ(img.cols, 408);
    EXPECT_EQ(img.type(), CV_8U);
    ASSERT_TRUE(v.contains("cam_from_object"));
    EXPECT_EQ(v["cam_from_object"]["R"].size(), 3u);
    EXPECT_EQ(v["centers_px"].size(), 9u);
    // Metal is dark: the pixel at every projected marker centre is darker than the image median.
    cv::Mat sorted = img.reshape(1, 1).clone();
    cv::sort(sorted, sorted, cv::SORT_ASCENDING);
    const int median = sorted.at<uint8_t>(sorted.cols / 2);
    for (const auto& uv : v["centers_px"]) {
      const int u = static_cast<int>(std::lround(uv[0].get<double>()));
      const int vv = static_cast<int>(std::lround(uv[1].get<double>()));
      EXPECT_LT(img.at<uint8_t>(vv, u), median) << v["file"] << " " << uv;
    }
  }
  EXPECT_EQ(truth["views"][4]["primary_deg"].get<double>(), -90.0);  // RAO 90 (see the scene)
  // No temporary directories left beside the output.
  for (const auto& e : fs::directory_iterator(out.parent_path())) {
    EXPECT_EQ(e.path().filename().string().find("pose.tmp"), std::string::npos);
  }

  // Deterministic: a second run gives byte-identical files.
  const fs::path out2 = tmp.File("pose2");
  ASSERT_EQ(Simulate("--scene=" + kScenes + "thesis_pose.yaml --out=" + out2.string()).code, 0);
  for (const auto& e : fs::directory_iterator(out)) {
    EXPECT_EQ(carmba::test::ReadTextFile(e.path()).size(),
              carmba::test::ReadTextFile(out2 / e.path().filename()).size());
    if (e.path().filename() != "truth.json") {
      EXPECT_TRUE(carmba::test::ReadTextFile(e.path()) ==
                  carmba::test::ReadTextFile(out2 / e.path().filename()))
          << e.path();
    }
  }

  // --seed changes the noise, not the geometry.
  const fs::path out3 = tmp.File("pose3");
  ASSERT_EQ(
      Simulate("--scene=" + kScenes + "thesis_pose.yaml --seed=77 --out=" + out3.string()).code, 0);
  const nlohmann::json truth3 =
      nlohmann::json::parse(carmba::test::ReadTextFile(out3 / "truth.json"));
  EXPECT_EQ(truth3["seed"], 77);
  EXPECT_EQ(truth3["views"][0]["centers_px"], truth["views"][0]["centers_px"]);
  EXPECT_FALSE(carmba::test::ReadTextFile(out3 / "orient_000.png") ==
               carmba::test::ReadTextFile(out / "orient_000.png"));

  // An existing non-empty output is not overwritten without --force ...
  const SimRun again = Simulate("--scene=" + kScenes + "thesis_pose.yaml --out=" + out.string());
  EXPECT_NE(again.code, 0);
  EXPECT_NE(again.err.find("pass --force"), std::string::npos) << again.err;
  // ... and is replaced with it.
  EXPECT_EQ(
      Simulate("--scene=" + kScenes + "thesis_pose.yaml --force --out=" + out.string()).code,
      0);
  EXPECT_TRUE(fs::exists(out / "truth.json"));
}

// `kind: ct` scenes are dispatched to the CT simulator (ct/ct_simulate.h).
TEST(SimulateCli, CtSceneIsDispatched) {
  const carmba::test::ScratchDir tmp("sim_cli_ct");
  const fs::path out = tmp.File("ct");
  const SimRun r = Simulate("--scene=" + kScenes + "thesis_ct.yaml --out=" + out.string());
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json truth =
      nlohmann::json::parse(carmba::test::ReadTextFile(out / "truth.json"));
  EXPECT_EQ(truth["kind"], "ct");
  EXPECT_EQ(truth["markers"].size(), 9u);
  EXPECT_TRUE(fs::is_directory(out / "ct"));
  EXPECT_FALSE(fs::is_empty(out / "ct"));
}

TEST(SimulateCli, BadSceneLeavesNoOutput) {
  const carmba::test::ScratchDir tmp("sim_cli_bad");
  const fs::path dir = tmp.path();
  // The shipped scene plus a last view that puts the plate outside the field of view.
  std::string text = carmba::test::ReadTextFile(kScenes + "thesis_calibration.yaml");
  text +=
      "  - {name: too_far, primary_deg: 0, object_rotation_deg: [90, 0, 0], "
      "object_center_mm: [80, 0, 0]}\n";
  const fs::path scene = dir / "scene.yaml";
  std::ofstream(scene) << text;
  const fs::path out = dir / "out";
  const SimRun r = Simulate("--scene=" + scene.string() + " --out=" + out.string());
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("view 'too_far'"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;  // one line
  EXPECT_FALSE(fs::exists(out));
  int entries = 0;
  for (const auto& e : fs::directory_iterator(dir)) entries += e.path() != scene;
  EXPECT_EQ(entries, 0);  // no temporary directory left

  const SimRun missing = Simulate("--scene=/no/such.yaml --out=" + out.string());
  EXPECT_NE(missing.code, 0);
  EXPECT_NE(missing.err.find("/no/such.yaml"), std::string::npos);
  EXPECT_FALSE(fs::exists(out));
  EXPECT_NE(Simulate("--out=" + out.string()).code, 0);
}

}  // namespace
