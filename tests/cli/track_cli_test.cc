// `carmba track` on the real Autoscoper wrist radiographs (data/real/autoscoper-wrist: two
// calibrated cameras, three frames of 1760 x 1760): every output written and consistent, and the
// checks that hold without ground truth measured and printed. Bad command lines: one line, exit 2
// or 1, nothing written.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>

#include "cli_test_util.h"

namespace carmba::test {
namespace {

const std::string kWrist = std::string(CARMBA_SOURCE_DIR) + "/data/real/autoscoper-wrist";

std::string WristArgs(const std::string& out) {
  return "track --cameras '" + std::string("cam01=") + kWrist +
         "/calibration/xr_calib_wrist_cam01.txt;cam02=" + kWrist +
         "/calibration/xr_calib_wrist_cam02.txt' --images 'cam01=" + kWrist +
         "/images/cam01;cam02=" + kWrist + "/images/cam02' --marker-diameter-mm 1 --out " + out;
}

TEST(TrackCli, RealWristRadiographsTrackedWithEveryOutput) {
  ScratchDir dir("track_cli");
  const std::string out = dir.File("out");
  const auto r = RunCarmba(WristArgs(out));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::printf("%s", r.out.c_str());
  for (const char* f : {"points.csv",
                        "observations.csv",
                        "rigid_bodies.json",
                        "report.md",
                        "report.html",
                        "overlays/frame2_cam01.png",
                        "overlays/frame158_cam02.png"}) {
    EXPECT_TRUE(std::filesystem::exists(out + "/" + f)) << f;
  }
  const std::string points = ReadTextFile(out + "/points.csv");
  EXPECT_NE(
      points.find(
          "frame,point,x_mm,y_mm,z_mm,"
          "cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz,num_views,rms_px\n"),
      std::string::npos);
  const nlohmann::json j = ReadJsonFile(out + "/rigid_bodies.json");
  ASSERT_TRUE(j.is_object());
  ASSERT_GE(j["bodies"].size(), 1u);
  // Every body has a pose in the first frame held at the identity, and a 6x6 covariance per pose.
  for (const auto& body : j["bodies"]) {
    ASSERT_GE(body["points"].size(), 3u);
    EXPECT_EQ(body["poses"][0]["frame"], 2);
    EXPECT_EQ(body["poses"][0]["lab_from_body_translation_mm"][0], 0.0);
    for (const auto& pose : body["poses"]) EXPECT_EQ(pose["covariance_6x6"].size(), 6u);
  }
  // The measured checks, against what was measured when this test was written (the issue's
  // targets are in the report; tests/track/track_test.cc and the closing note say which hold).
  const auto& c = j["checks"];
  std::printf(
      "wrist: >= %d beads per frame, RMS %.3f px, spread <= %.3f mm, change <= %.2f sigma\n",
      c["min_beads_per_frame"].get<int>(),
      c["rms_px"].get<double>(),
      c["max_spread_mm"].get<double>(),
      c["max_change_sigmas"].get<double>());
  // Issue 22's targets that hold on this data (measured 2026-12-06 with the third body: 10 beads in
  // the least frame, RMS 0.229 px, largest change 1.51 sigma at the noise the bundle adjustment
  // estimates). The spread target (<= 0.1 mm) does not hold: 0.189 mm (the third body's 6.8 mm
  // distance, sigma 0.21 mm; 0.127 mm with two bodies), reported, not asserted beyond 0.2 mm.
  EXPECT_GE(c["min_beads_per_frame"].get<int>(), 10);
  EXPECT_LE(c["rms_px"].get<double>(), 0.4);
  EXPECT_LE(c["max_change_sigmas"].get<double>(), 3.0);
  EXPECT_LE(c["max_spread_mm"].get<double>(), 0.2);
  // Why: the pixel noise at the noise the bundle adjustment estimates predicts a larger spread
  // (0.288 mm; 0.107 mm at the detector's stated covariances, which the residuals say are
  // sigma0 = 2.7 too small here; with two bodies 0.225 / 0.085 mm, and 0.414 / 0.195 mm before
  // the noise correlation was measured from second differences), and the report says which
  // verdict that is: not "a wrong match or a body that is not rigid".
  const double predicted = c["predicted_max_spread_mm"].get<double>();
  EXPECT_GE(predicted, c["max_spread_mm"].get<double>());
  const std::string report = ReadTextFile(out + "/report.md");
  EXPECT_TRUE(report.find("is out of reach on these data") != std::string::npos ||
              report.find("but not what the noise predicts") != std::string::npos);
  EXPECT_EQ(report.find("look for a wrong match"), std::string::npos);
  // The radius, the ulna and a third bone: three beads 80-110 mm from the others, seen in frames
  // 2 and 158, whose distances to both other bodies change by 4-17 mm between those frames. In
  // cam02 they sit on the darker side of bone edges, where the marker detector rejected them as
  // "merged" until it judged a round blob on a plateau by its own surroundings (2026-12-06; the
  // images show three round dark beads there in both cameras). Moving every centre by at most
  // 0.009 px
  // (the blur-pull correction) once gave a false body: two 6-bead cliques tied and the first one
  // found was taken; the tie now goes to the one whose distances agree best (track.cc
  // LargestClique).
  ASSERT_EQ(j["bodies"].size(), 3u);
  std::vector<size_t> sizes;
  for (const auto& body : j["bodies"]) sizes.push_back(body["points"].size());
  std::sort(sizes.begin(), sizes.end());
  EXPECT_EQ(sizes, (std::vector<size_t>{3, 5, 6}));
  // Every observation row names a bead of points.csv in the same frame.
  std::istringstream obs(ReadTextFile(out + "/observations.csv"));
  int rows = 0;
  for (std::string line; std::getline(obs, line);) {
    if (line.empty() || line[0] == '#' || line.rfind("frame,", 0) == 0) continue;
    std::istringstream fields(line);
    std::string frame, camera, point;
    std::getline(fields, frame, ',');
    std::getline(fields, camera, ',');
    std::getline(fields, point, ',');
    EXPECT_NE(points.find("\n" + frame + "," + point + ","), std::string::npos) << line;
    ++rows;
  }
  EXPECT_GE(rows, 18);
  EXPECT_NE(report.find("## Checks"), std::string::npos);
}

TEST(TrackCli, BadCommandLinesAreOneLineAndWriteNothing) {
  ScratchDir dir("track_cli_bad");
  const std::string out = dir.File("out");
  struct Case {
    std::string args, expected;
    int code;
  };
  const std::string cams = "--cameras 'cam01=" + kWrist +
                           "/calibration/xr_calib_wrist_cam01.txt;cam02=" + kWrist +
                           "/calibration/xr_calib_wrist_cam02.txt'";
  const std::vector<Case> cases = {
      {"track " + cams + " --images 'cam01=" + kWrist +
           "/images/cam01' --marker-diameter-mm 1 --out " + out,
       "--images: expected at least two cameras",
       2},
      {"track " + cams + " --images 'cam01=" + kWrist + "/images/cam01;cam03=" + kWrist +
           "/images/cam02' --marker-diameter-mm 1 --out " + out,
       "no images for camera 'cam02'",
       2},
      {"track " + cams + " --images 'cam01=" + kWrist + "/images/cam01;cam02=" + kWrist +
           "/images/cam02' --marker-diameter-mm 0.001 --out " + out,
       "--marker-diameter-mm: expected 0.1 .. 100 mm, got 0.001 (a diameter in metres?)",
       2},
      {"track --cameras 'cam01=" + kWrist + "/LICENSE;cam02=" + kWrist +
           "/calibration/xr_calib_wrist_cam02.txt' --images 'cam01=" + kWrist +
           "/images/cam01;cam02=" + kWrist + "/images/cam02' --marker-diameter-mm 1 --out " + out,
       "LICENSE:1: unknown section",
       1},
      {"track " + cams + " --images 'cam01=" + kWrist + "/images/cam01;cam02=" + kWrist +
           "/images/cam02' --marker-diameter-mm 1 --out " + kWrist + "/images",
       "contains the input --images cam01",
       2},
      {"track " + cams + " --images 'cam01=" + kWrist + "/images/cam01;cam02=" + kWrist +
           "/images/cam02' --marker-diameter-mm 1 --force --out " + kWrist +
           "/calibration/xr_calib_wrist_cam02.txt",
       "is the input --cameras cam02",
       2},
  };
  for (const Case& c : cases) {
    const auto r = RunCarmba(c.args);
    EXPECT_EQ(r.exit_code, c.code) << c.args << "\n" << r.err;
    EXPECT_NE(r.err.find(c.expected), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(std::filesystem::exists(out)) << c.args;
  }
}

}  // namespace
}  // namespace carmba::test
