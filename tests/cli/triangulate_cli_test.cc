// `carmba triangulate` end to end on the thesis's pose problem (markers of the CT triangulated
// from their picks, in the CT frame despite the problem's mirrored handedness), the thesis's
// 4-marker problem's leave-one-out TRE (skipped, with the reason), and bad input one corruption
// at a time: each a one-line error with no output, or a warning where the result is valid.
// The joint scene's relative poses, TRE and a triangulation with the calibration's uncertainty
// are checked in joint_cli_test.cc (it renders that scene once).
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "cli_test_util.h"
#include "figures.h"
#include "synthetic/synthetic_pose.h"

namespace carmba::test {
namespace {


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
  ScratchDir dir_;
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
  std::map<std::string, std::string> figure;  // id -> its error, for results.md
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
    char text[64];
    std::snprintf(text, sizeof text, "%.2f mm (%.2f sigma)", e.norm(), std::sqrt(m2));
    figure[id] = text;
    EXPECT_LT(std::sqrt(m2), 3.0) << id;  // within 3 sigma (3 dof: P = 0.97)
    EXPECT_TRUE(p.at("warnings").empty()) << p.at("warnings");
    EXPECT_EQ(p.at("views").size(), id == "m4" ? 5u : 2u);
  }
  if (figure.size() == 3) {
    testing::RecordFigureText(
        "triangulate.thesis_picks",
        "marker 3 " + figure["m3"] + ", marker 4 " + figure["m4"] + ", marker 8 " + figure["m8"]);
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
  EXPECT_EQ(j.at("points")[0].at("warnings").size(), 1u);
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
  ExpectError("--points " + dir_.File("p.csv"), "p.csv:2: columns cov_uu, cov_uv, cov_vv: "
                                                "expected a positive definite pixel covariance");
}

TEST(SolveTre, FourMarkerViewsAreSkippedWithTheReason) {
  // The thesis's views see 4 markers: without one, 3 remain and no view can be solved.
  ScratchDir dir;
  std::ifstream in(kSource + "/configs/posit_ba_analytic.yaml");
  std::stringstream ss;
  ss << in.rdbuf() << "tre: true\n";
  dir.Write("config.yaml", ss.str());
  const auto r = RunCarmba("solve --problem " + kSource + "/problems/thesis_pose.yaml --config " +
                           dir.File("config.yaml") + " --no-plots --out " + dir.File("out"));
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
  EXPECT_NE(rs.str().find("## Target registration error (leave one marker out)"),
            std::string::npos);
}

// The thesis's pose problem with a covariance in camera.json: the intrinsics stay held (the same
// poses) and the covariances grow by the calibration's part; `consider_calibration: false` gives
// back the held-intrinsics covariances; triangulate says which, without the "left out" note.
TEST(ConsiderCalibrationCli, CameraCovarianceEntersPosesRelativePosesAndTriangulation) {
  ScratchDir dir;
  std::ifstream cam_in(kSource + "/data/thesis/camera.json");
  nlohmann::json cam = nlohmann::json::parse(cam_in);
  // sigmas fx, fy 20 px, cx, cy 5 px; fx-fy correlation 0.9.
  cam["covariance"] = {
      {"names", {"fx", "fy", "cx", "cy"}},
      {"matrix", {{400, 360, 0, 0}, {360, 400, 0, 0}, {0, 0, 25, 0}, {0, 0, 0, 25}}}};
  dir.Write("camera.json", cam.dump(2));
  std::ifstream pin(kSource + "/problems/thesis_pose.yaml");
  std::stringstream ps;
  ps << pin.rdbuf();
  std::string problem = ps.str();
  const std::string data = kSource + "/data/thesis/";
  for (size_t at; (at = problem.find("../data/thesis/")) != std::string::npos;) {
    problem.replace(at, std::string("../data/thesis/").size(), data);
  }
  problem.replace(
      problem.find(data + "camera.json"), (data + "camera.json").size(), dir.File("camera.json"));
  dir.Write("problem.yaml", problem);
  std::ifstream cin_(kSource + "/configs/posit_ba_analytic.yaml");
  std::stringstream cs;
  cs << cin_.rdbuf();
  dir.Write("off.yaml", cs.str() + "consider_calibration: false\n");
  const std::string config = kSource + "/configs/posit_ba_analytic.yaml";
  auto solve =
      [&](const std::string& problem_file, const std::string& cfg, const std::string& out) {
        const auto r = RunCarmba("solve --problem " + problem_file + " --config " + cfg +
                                 " --no-plots --out " + dir.File(out));
        EXPECT_EQ(r.exit_code, 0) << r.err;
        return ReadJsonFile(dir.File(out + "/result.json"));
      };
  const nlohmann::json on = solve(dir.File("problem.yaml"), config, "on");
  const nlohmann::json off = solve(dir.File("problem.yaml"), dir.File("off.yaml"), "off");
  const nlohmann::json held = solve(kSource + "/problems/thesis_pose.yaml", config, "held");
  ASSERT_EQ(on.at("views").size(), 5u);
  for (size_t v = 0; v < 5; ++v) {
    for (int a = 0; a < 3; ++a) {
      const double t_on = on["views"][v]["cam_from_object"]["t_mm"][a].get<double>();
      EXPECT_NEAR(t_on,
                  held["views"][v]["cam_from_object"]["t_mm"][a].get<double>(),
                  1e-9 * std::abs(t_on) + 1e-9);
      const double s_on = on["views"][v]["sigma_translation_mm"][a].get<double>();
      const double s_off = off["views"][v]["sigma_translation_mm"][a].get<double>();
      EXPECT_NEAR(s_off, held["views"][v]["sigma_translation_mm"][a].get<double>(), 1e-9 * s_off);
      EXPECT_GT(s_on, s_off) << "view " << v << " axis " << a;
    }
  }
  // tz is the calibration-dominated axis (fx, fy scale the distance).
  std::printf("view 0 sigma tz: %.3f mm with the calibration considered, %.3f mm without\n",
              on["views"][0]["sigma_translation_mm"][2].get<double>(),
              off["views"][0]["sigma_translation_mm"][2].get<double>());
  ASSERT_EQ(on.at("relative_poses").size(), 10u);
  EXPECT_GT(on["relative_poses"][0]["sigma_angle_calibration_deg"].get<double>(), 0.0);
  EXPECT_EQ(off["relative_poses"][0]["sigma_angle_calibration_deg"].get<double>(), 0.0);
  std::ifstream rep(dir.File("on/report.md"));
  std::stringstream rs;
  rs << rep.rdbuf();
  EXPECT_NE(rs.str().find("its covariance is considered"), std::string::npos);
  EXPECT_EQ(rs.str().find("leave the calibration's uncertainty out"), std::string::npos);
  // Triangulation: marker 4 from all five views.
  const auto r = RunCarmba(
      "triangulate --problem " + dir.File("problem.yaml") + " --config " + config +
      " --pixels '0=134,270;10=160,271;30=201,271;50=221,275;90=182,286' --out " + dir.File("tri"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find("not in the covariance"), std::string::npos) << r.err;
  const nlohmann::json t = ReadJsonFile(dir.File("tri/triangulation.json"));
  EXPECT_NE(t.at("covariance").get<std::string>().find("considered"), std::string::npos);
  const auto& cc = t.at("points")[0].at("covariance_calibration_mm2");
  EXPECT_GT(cc[0][0].get<double>() + cc[1][1].get<double>() + cc[2][2].get<double>(), 0.0);
  EXPECT_GT(
      t.at("points")[0].at("variance_by_source_mm2").at("calibration (intrinsics)").get<double>(),
      0.0);
}

}  // namespace
}  // namespace carmba::test
