// `carmba triangulate` end to end on the thesis's pose problem (markers of the CT triangulated
// from their picks, in the CT frame despite the problem's mirrored handedness), the thesis's
// 4-marker problem's leave-one-out TRE (skipped, with the reason), and bad input one corruption
// at a time: each a one-line error with no output, or a warning where the result is valid.
// The joint scene's relative poses, TRE and a triangulation with the calibration's uncertainty
// are checked in joint_cli_test.cc (it renders that scene once).
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <filesystem>
#include <map>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "cli_test_util.h"

namespace carmba::test {
namespace {

const std::string kSource = CARMBA_SOURCE_DIR;

class TriangulateCli : public ::testing::Test {
 protected:
  std::string Args(const std::string& extra) const {
    return "triangulate --problem " + kSource + "/problems/thesis_pose.yaml --config " + kSource +
           "/configs/posit_ba_analytic.yaml --out " + dir_.File("out") + " " + extra;
  }
  // Non-zero exit, one line on stderr containing `expected`, nothing written.
  void ExpectError(const std::string& extra, const std::string& expected) {
    const auto r = RunCarmba(Args(extra));
    EXPECT_NE(r.exit_code, 0);
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(expected), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir_.File("out")));
  }
  TempDir dir_;
};

TEST_F(TriangulateCli, ThesisMarkersInTheCtFrame) {
  // Markers 3 (the origin) and 8 from the thesis's picks (Table 5.2) in views 0 and 90, and
  // marker 4 in all five views.
  dir_.Write("points.csv",
             "point,view,u_px,v_px\n"
             "m3,0,133,180\nm3,90,153,182\n"
             "m8,0,240,317\nm8,90,63,347\n"
             "m4,0,134,270\nm4,10,160,271\nm4,30,201,271\nm4,50,221,275\nm4,90,182,286\n");
  const auto r = RunCarmba(Args("--points " + dir_.File("points.csv")));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // The pose problem holds the intrinsics: said once, as a note.
  EXPECT_NE(r.err.find("calibration's uncertainty is not in the covariance"), std::string::npos);
  const nlohmann::json j = ReadJsonFile(dir_.File("out/triangulation.json"));
  ASSERT_EQ(j.at("points").size(), 3u);
  const std::map<std::string, Eigen::Vector3d> ct = {
      {"m3", {0, 0, 0}}, {"m8", {-55.4, 17.8, 30}}, {"m4", {-21.6, -21.5, 10}}};
  for (const auto& p : j.at("points")) {
    const std::string id = p.at("id");
    Eigen::Vector3d x;
    Eigen::Matrix3d C;
    for (int i = 0; i < 3; ++i) {
      x[i] = p.at("p_in_ct_mm")[i];
      for (int k = 0; k < 3; ++k) C(i, k) = p.at("covariance_mm2")[i][k];
    }
    // Against the CT positions (sigma 0.3 mm each axis in the problem): e^T (C + C_ct)^-1 e.
    const Eigen::Vector3d e = x - ct.at(id);
    const Eigen::Matrix3d Ct = C + 0.09 * Eigen::Matrix3d::Identity();
    const double m2 = e.dot(Ct.ldlt().solve(e));
    std::printf("%s: error %.3f mm, sqrt(e^T C^-1 e) %.2f, rays %.1f deg\n", id.c_str(), e.norm(),
                std::sqrt(m2), p.at("max_ray_angle_deg").get<double>());
    EXPECT_LT(std::sqrt(m2), 3.0) << id;  // within 3 sigma (3 dof: P = 0.97)
    EXPECT_TRUE(p.at("warning").is_null());
    EXPECT_EQ(p.at("views").size(), id == "m4" ? 5u : 2u);
  }
  // points.csv in the fiducials' format.
  std::ifstream in(dir_.File("out/points.csv"));
  std::stringstream ss;
  ss << in.rdbuf();
  EXPECT_NE(ss.str().find("id,x_mm,y_mm,z_mm,cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz\nm3,"),
            std::string::npos);
}

TEST_F(TriangulateCli, PixelsFlag) {
  const auto r = RunCarmba(Args("--pixels '0=240,317;90=63,347'"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("point 1: (-55."), std::string::npos) << r.out;
}

TEST_F(TriangulateCli, NearlyParallelRaysAreAWarning) {
  // Views 0 and 10 see marker 8 along rays about 10 deg apart: a warning above that threshold,
  // naming the angle; the result is written.
  const auto r = RunCarmba(Args("--pixels '0=240,317;10=251,318' --min_angle_deg 20"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("warning: point '1': the rays are nearly parallel: the widest pair (views "
                       "'0' and '10') is "),
            std::string::npos)
      << r.err;
  const nlohmann::json j = ReadJsonFile(dir_.File("out/triangulation.json"));
  EXPECT_FALSE(j.at("points")[0].at("warning").is_null());
  EXPECT_EQ(j.at("warnings").size(), 1u);
}

TEST_F(TriangulateCli, SeenInOneViewOnly) {
  dir_.Write("p.csv", "point,view,u_px,v_px\ntip,0,133,180\n");
  ExpectError("--points " + dir_.File("p.csv"),
              "p.csv: point 'tip': seen in one view only ('0'): at least two views are needed");
}

TEST_F(TriangulateCli, UnknownView) {
  dir_.Write("p.csv", "view,u_px,v_px\n0,133,180\n45,150,180\n");
  ExpectError("--points " + dir_.File("p.csv"),
              "p.csv:3: view '45' is not an object view of the problem (object views: 0, 10, 30, "
              "50, 90)");
}

TEST_F(TriangulateCli, NanPixel) {
  dir_.Write("p.csv", "view,u_px,v_px\n0,133,180\n90,nan,182\n");
  ExpectError("--points " + dir_.File("p.csv"), "p.csv:3: column 'u_px'");
}

TEST_F(TriangulateCli, NanInPixelsFlag) {
  ExpectError("--pixels '0=133,180;90=nan,182'",
              "--pixels: '90=nan,182': expected VIEW=U,V with finite numbers (px)");
}

TEST_F(TriangulateCli, MissingColumn) {
  dir_.Write("p.csv", "view,u_px\n0,133\n90,153\n");
  ExpectError("--points " + dir_.File("p.csv"), "p.csv: missing column 'v_px'");
}

TEST_F(TriangulateCli, SameViewTwice) {
  ExpectError("--pixels '0=133,180;0=134,181'", "point '1': view '0' is given twice");
}

TEST_F(TriangulateCli, PointsAndPixelsTogether) {
  dir_.Write("p.csv", "view,u_px,v_px\n0,133,180\n90,153,182\n");
  ExpectError("--points " + dir_.File("p.csv") + " --pixels '0=1,2;90=3,4'",
              "give either --points CSV or --pixels");
}

TEST_F(TriangulateCli, BadPixelCovariance) {
  dir_.Write("p.csv", "view,u_px,v_px,cov_uu,cov_uv,cov_vv\n0,133,180,1,2,1\n90,153,182,1,0,1\n");
  ExpectError("--points " + dir_.File("p.csv"), "p.csv:2: cov_uu, cov_uv, cov_vv: expected a "
                                                "positive definite pixel covariance");
}

TEST(SolveTre, FourMarkerViewsAreSkippedWithTheReason) {
  // The thesis's views see 4 markers: without one, 3 remain and no view can be solved.
  TempDir dir;
  std::ifstream in(kSource + "/configs/posit_ba_analytic.yaml");
  std::stringstream ss;
  ss << in.rdbuf() << "tre: true\n";
  dir.Write("config.yaml", ss.str());
  const auto r = RunCarmba("solve --problem " + kSource + "/problems/thesis_pose.yaml --config " +
                           dir.File("config.yaml") + " --out " + dir.File("out"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = ReadJsonFile(dir.File("out/result.json"));
  ASSERT_EQ(j.at("tre").at("markers").size(), 4u);
  EXPECT_EQ(j.at("tre").at("evaluated"), 0);
  EXPECT_EQ(j.at("tre").at("markers")[0].at("skipped"),
            "seen in 0 view(s) of the solve without it (5 view(s) left out: fewer than 4 other "
            "markers): at least two are needed");
  // Relative poses: all 10 pairs of the 5 views.
  EXPECT_EQ(j.at("relative_poses").size(), 10u);
  std::ifstream rep(dir.File("out/report.md"));
  std::stringstream rs;
  rs << rep.rdbuf();
  EXPECT_NE(rs.str().find("## Relative C-arm poses"), std::string::npos);
  EXPECT_NE(rs.str().find("## Target registration error (leave one marker out)"), std::string::npos);
}

}  // namespace
}  // namespace carmba::test
