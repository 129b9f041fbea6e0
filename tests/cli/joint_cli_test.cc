// End-to-end tests of the joint problem through `carmba`: the simulator's joint scene rendered,
// its CT localised and solved (intrinsics and relative rotations within 3 sigma of the truth,
// result.json's keys), and bad input one corruption at a time.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "synthetic/synthetic_joint.h"
#include "cli_test_util.h"
#include "report_browser.h"

namespace carmba::test {
namespace {

constexpr double kJointSigmas = 3.0;  // the acceptance: within 3 sigma of the truth

TEST(JointCli, SimulatedJointSceneWithinThreeSigma) {
  ScratchDir dir;
  const std::string scene = dir.File("scene");
  ASSERT_EQ(SimulateJointScene("thesis_joint.yaml", scene), "");
  // The shipped problem with its data paths (the demo's out/sim/joint) pointed at this scene.
  std::ifstream in(kSource + "/problems/thesis_joint.yaml");
  std::stringstream ss;
  ss << in.rdbuf();
  std::string problem = ss.str();
  const std::string shipped = "../out/sim/joint";
  for (size_t p = problem.find(shipped); p != std::string::npos; p = problem.find(shipped, p)) {
    problem.replace(p, shipped.size(), scene);
  }
  dir.Write("problem.yaml", problem);
  // The shipped config with the leave-one-marker-out TRE on (it adds to result.json only).
  {
    std::ifstream cin(kSource + "/configs/joint_radial.yaml");
    std::stringstream cs;
    cs << cin.rdbuf() << "tre: true\n";
    dir.Write("config.yaml", cs.str());
  }
  auto r = RunCarmba("solve --problem " + dir.File("problem.yaml") + " --config " +
                dir.File("config.yaml") + " --out " + dir.File("out"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto solve_run = r;  // its stderr is checked below (r is reused)
  const nlohmann::json j = ReadJsonFile(dir.File("out/result.json"));
  const nlohmann::json truth = ReadJsonFile(scene + "/truth.json");
  // Intrinsics within 3 sigma of the truth.
  const auto& intr = j.at("intrinsics");
  for (const char* k : {"fx", "fy", "cx", "cy"}) {
    const double e = intr.at(k).get<double>() - truth.at("camera").at(k).get<double>();
    const double s = intr.at("sigmas").at(k).get<double>();
    std::printf("%s: error %.3f px, sigma %.3f px (%.2f sigma)\n", k, e, s, e / s);
    EXPECT_LT(std::abs(e), kJointSigmas * s) << k;
  }
  EXPECT_EQ(intr.at("covariance").at("names").size(), 9u);
  // Every relative rotation within 3 sigma of the true one.
  ASSERT_EQ(j.at("validation").size(), 3u);
  for (const auto& v : j.at("validation")) {
    const double e = v.at("relative_rotation_deg").get<double>() -
                     v.at("true_relative_rotation_deg").get<double>();
    const double s = v.at("sigma_relative_rotation_deg").get<double>();
    std::printf("%s-%s: error %.4f deg, sigma %.4f deg (%.2f sigma)\n",
                v.at("a").get<std::string>().c_str(), v.at("b").get<std::string>().c_str(), e, s,
                e / s);
    EXPECT_LT(std::abs(e), kJointSigmas * s);
  }
  // Relative poses: all 21 pairs of the 7 object views, each rotation within 3 sigma of the
  // truth (the rotation part's Mahalanobis distance, 3 dof).
  ASSERT_EQ(j.at("relative_poses").size(), 21u);
  double worst = 0, nees = 0;
  for (const auto& p : j.at("relative_poses")) {
    EXPECT_EQ(p.at("covariance_6x6").size(), 6u);
    const double m = p.at("rotation_error_sigma").get<double>();
    worst = std::max(worst, m);
    nees += p.at("nees").get<double>() / 6 / 21;
    EXPECT_LT(m, kJointSigmas) << p.at("a") << "-" << p.at("b");
  }
  std::printf("relative poses: worst rotation error %.2f sigma over 21 pairs, mean NEES / 6 %.2f\n",
              worst, nees);
  // Leave-one-marker-out TRE: every marker evaluated; the measured RMS beside the predicted.
  const auto& tre = j.at("tre");
  EXPECT_EQ(tre.at("evaluated"), 9);
  std::printf(
      "TRE: RMS measured %.3f mm, predicted %.3f mm, Fitzpatrick %.3f mm, mean e^T C^-1 e "
      "/ 3 = %.2f, %.0f ms\n",
      tre.at("rms_error_mm").get<double>(),
      tre.at("rms_predicted_mm").get<double>(),
      tre.at("rms_fitzpatrick_mm").get<double>(),
      tre.at("mean_mahalanobis2_per_dof").get<double>(),
      1e3 * tre.at("time_s").get<double>());
  // Triangulation with the joint covariance (the calibration's share in it): markers 1 and 5
  // from the scene's picks in two and in all seven views, against their true positions. These
  // picks are also in the solve, which the covariance assumes they are not (a new point's are
  // not): a sanity check; the leave-one-out TRE above and the engine's Monte Carlo
  // (tests/ba/triangulation_test.cc) are the strict checks.
  {
    std::ifstream oin(scene + "/object/observations.csv");
    std::string line;
    std::ostringstream pts;
    pts << "point,view,u_px,v_px\n";
    while (std::getline(oin, line)) {
      if (line.empty() || line[0] == '#' || line.rfind("view,", 0) == 0) continue;
      std::stringstream ls(line);
      std::string view, marker, u, v;
      std::getline(ls, view, ',');
      std::getline(ls, marker, ',');
      std::getline(ls, u, ',');
      std::getline(ls, v, ',');
      if (marker == "5") pts << "m5," << view << "," << u << "," << v << "\n";
      if (marker == "1" && (view == "orient_000" || view == "orient_090")) {
        pts << "m1," << view << "," << u << "," << v << "\n";
      }
    }
    dir.Write("points.csv", pts.str());
    r = RunCarmba("triangulate --problem " + dir.File("problem.yaml") + " --config " + kSource +
                  "/configs/joint_radial.yaml --points " + dir.File("points.csv") + " --out " +
                  dir.File("tri"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_EQ(r.err, "");  // no note: the intrinsics are estimated
    const nlohmann::json t = ReadJsonFile(dir.File("tri/triangulation.json"));
    ASSERT_EQ(t.at("points").size(), 2u);
    for (const auto& p : t.at("points")) {
      const int id = p.at("id") == "m5" ? 5 : 1;
      Eigen::Vector3d e;
      Eigen::Matrix3d C;
      for (const auto& m : truth.at("ct_markers")) {
        if (m.at("id") != id) continue;
        e = Eigen::Vector3d(
            m.at("x_mm").get<double>(), m.at("y_mm").get<double>(), m.at("z_mm").get<double>());
      }
      for (int i = 0; i < 3; ++i) {
        e[i] = p.at("p_in_ct_mm")[i].get<double>() - e[i];
        for (int k = 0; k < 3; ++k) C(i, k) = p.at("covariance_mm2")[i][k];
      }
      const double m = std::sqrt(e.dot(C.ldlt().solve(e)));
      std::printf("triangulated marker %d from %zu views: error %.3f mm, %.2f sigma (3 dof); "
                  "plate-pixel variance %.2e mm^2 of %.2e\n",
                  id, p.at("views").size(), e.norm(), m,
                  p.at("variance_by_source_mm2").at("plate pixels").get<double>(), C.trace());
      EXPECT_LT(m, kJointSigmas);
      EXPECT_GT(p.at("variance_by_source_mm2").at("plate pixels").get<double>(), 0.0);
    }
  }
  // The keys the issue names.
  for (const char* k : {"views", "validation", "statistics", "solver", "intrinsics", "outliers",
                        "state_layout", "error_budget", "two_step_comparison", "markers"}) {
    EXPECT_TRUE(j.contains(k)) << k;
  }
  // Per view, the keys a pose problem's views have too: the initial pose and its RMS.
  for (const auto& v : j.at("views")) {
    EXPECT_TRUE(v.contains("initial")) << v.at("id");
    EXPECT_GE(v.at("initial_rms_px").get<double>(), 0.99 * v.at("rms_px").get<double>())
        << v.at("id");
  }
  EXPECT_EQ(j.at("state_layout").at(0), "fx");
  EXPECT_TRUE(j.at("solver").at("converged").get<bool>());
  const auto& row = j.at("error_budget").at(0);
  EXPECT_EQ(row.at("quantity"), "fx");
  double share = 0;
  for (const auto& s : row.at("sources")) share += s.at("share").get<double>();
  EXPECT_NEAR(share, 1.0, 1e-9);
  EXPECT_EQ(j.at("two_step_comparison").size(), 3u);
  // mrcal reaches the same optimum (markers held, same initial values) with the same free
  // intrinsics: joint_radial holds p1 p2 k3, which mrcal's optimizer cannot, so the script solves
  // mrcal's residuals with carmba's free set (like with like).
  const auto& mc = j.at("mrcal_crosscheck");
  ASSERT_FALSE(mc.contains("error")) << mc.dump();
  EXPECT_NE(mc.at("what").get<std::string>().find("p1 p2 k3 held"), std::string::npos);
  EXPECT_TRUE(mc.at("mrcal").at("held_gauss_newton_iterations").is_number());
  std::printf("mrcal: max relative difference fx..cy %.2e, max %.2e sigma; RMS %.9g vs %.9g\n",
              mc.at("max_relative_difference_fx_fy_cx_cy").get<double>(),
              mc.at("max_difference_in_sigmas").get<double>(), mc.at("rms_px_mrcal").get<double>(),
              mc.at("rms_px_carmba_in_mrcal").get<double>());
  EXPECT_LT(mc.at("max_relative_difference_fx_fy_cx_cy").get<double>(), 1e-6);
  EXPECT_LT(mc.at("max_difference_in_sigmas").get<double>(), 1e-4);
  // mrcal seeded at carmba's optimum stays there: every intrinsic within 1e-3 of its sigma (in
  // relative terms k3, in the flat k2-k3 valley, can move 1e-4 at no cost).
  std::printf("mrcal seeded at carmba's optimum moves %.2e sigma (%.2e relative)\n",
              mc.at("max_move_in_sigmas_of_mrcal_seeded_at_carmba").get<double>(),
              mc.at("max_relative_move_of_mrcal_seeded_at_carmba").get<double>());
  EXPECT_LT(mc.at("max_move_in_sigmas_of_mrcal_seeded_at_carmba").get<double>(), 1e-3);
  EXPECT_NEAR(mc.at("rms_px_mrcal").get<double>(), mc.at("rms_px_carmba_in_mrcal").get<double>(),
              1e-9 * mc.at("rms_px_mrcal").get<double>());
  std::ifstream rep(dir.File("out/report.md"));
  std::stringstream rs;
  rs << rep.rdbuf();
  EXPECT_NE(rs.str().find("## Error budget"), std::string::npos);
  EXPECT_NE(rs.str().find("## Joint against two-step"), std::string::npos);
  // report.html: the joint solve's plots, rendered in a browser.
  const std::string html = ReadTextFile(dir.File("out/report.html"));
  for (const char* id : {"residuals-per-view", "residual-field", "distortion-the-camera",
                         "projection-uncertainty-the-camera", "error-budget", "poses-plate",
                         "poses-object", "markers"}) {
    EXPECT_NE(html.find(std::string("data-plot=\"") + id + "\""), std::string::npos) << id;
  }
  ExpectReportRenders(dir.File("out/report.html"), 8);
  // The pixel sigma behind the uncertainties is named; correlated intrinsics are warnings in
  // result.json, the report and on stderr, or the report says there are none.
  EXPECT_NE(rs.str().find("Sigmas: the stated sigmas"), std::string::npos);
  ASSERT_TRUE(j.at("warnings").is_array());
  for (const auto& w : j.at("warnings")) {
    EXPECT_NE(rs.str().find("**Warning:** " + w.get<std::string>()), std::string::npos) << w;
    EXPECT_NE(solve_run.err.find("carmba solve: warning: " + w.get<std::string>()),
              std::string::npos);
  }
  EXPECT_EQ(j.at("warnings").empty(),
            rs.str().find("No two intrinsics correlate beyond 0.99") != std::string::npos);
}

// A small valid joint problem written from the synthetic generator; each test corrupts one thing.
class JointBadInput : public ::testing::Test {
 protected:
  void SetUp() override {
    ba::SyntheticJointSpec spec;
    spec.num_plate_views = 6;
    spec.object_angles_deg = {0, 30, 90};
    const ba::SyntheticJoint sj = ba::MakeSyntheticJoint(spec, ba::NoiseSwitches(), 3);
    std::ostringstream plate, object, fid;
    plate << "# carmba observations\n# grid: circles 5 5 20\n# image_size: 408 408\n"
          << "view,image,point,u_px,v_px\n";
    object << "view,marker,u_px,v_px\n";
    int pv = 0;
    for (const auto& v : sj.problem.views) {
      for (size_t i = 0; i < v.point_ids.size(); ++i) {
        char line[128];
        if (v.kind == ba::ViewKind::kPlate) {
          std::snprintf(line, sizeof line, "%d,plate%02d.png,%d,%.6f,%.6f\n", pv, pv,
                        v.point_ids[i], v.uv_px[i].x(), v.uv_px[i].y());
          plate << line;
        } else {
          std::snprintf(line, sizeof line, "%s,%d,%.6f,%.6f\n", v.id.c_str(), v.point_ids[i],
                        v.uv_px[i].x(), v.uv_px[i].y());
          object << line;
        }
      }
      if (v.kind == ba::ViewKind::kPlate) ++pv;
    }
    fid << "id,x_mm,y_mm,z_mm,cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz\n";
    for (const auto& m : sj.problem.markers) {
      fid << m.id << "," << m.p_ct.x() << "," << m.p_ct.y() << "," << m.p_ct.z() << ","
          << m.covariance(0, 0) << ",0,0," << m.covariance(1, 1) << ",0," << m.covariance(2, 2)
          << "\n";
    }
    plate_ = plate.str();
    object_ = object.str();
    fiducials_ = fid.str();
    problem_ =
        "name: joint_bad_input\n"
        "plate_views: {observations: plate.csv, sigma_px: 0.05}\n"
        "object_views: {observations: object.csv, sigma_px: 0.2}\n"
        "fiducials: fiducials.csv\n"
        "validation: [{a: '+000', b: '+030', expected_deg: 30}]\n";
    config_ = "name: c\ninitializer: posit\nfix: [p1, p2, k3]\n";
  }
  void WriteAll() {
    dir_.Write("plate.csv", plate_);
    dir_.Write("object.csv", object_);
    dir_.Write("fiducials.csv", fiducials_);
    dir_.Write("problem.yaml", problem_);
    dir_.Write("config.yaml", config_);
    dir_.Write("groups.csv", groups_);
  }
  CommandResult Solve() {
    WriteAll();
    return RunCarmba("solve --problem=" + dir_.File("problem.yaml") + " --config=" +
                     dir_.File("config.yaml") + " --no-plots --no-mrcal --out=" + dir_.File("out"));
  }
  void ExpectError(const std::string& expected) {
    const auto r = Solve();
    EXPECT_NE(r.exit_code, 0);
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(expected), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir_.File("out/result.json")));
    EXPECT_FALSE(std::filesystem::exists(dir_.File("out/report.md")));
  }
  ScratchDir dir_;
  std::string plate_, object_, fiducials_, problem_, config_, groups_ = "view,group\n";
};

TEST_F(JointBadInput, ValidProblemSolves) {
  const auto r = Solve();
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = ReadJsonFile(dir_.File("out/result.json"));
  EXPECT_EQ(j.at("views").size(), 9u);
  EXPECT_EQ(j.at("validation").size(), 1u);
}

// `handedness: mirrored` means the same for every problem kind (problem/ba_assembly.h): a joint
// problem whose fiducials file has y negated solves as the as-given one does. (Before the one
// assembly the joint front end ignored the key.)
TEST_F(JointBadInput, MirroredFiducialsSolveAsTheAsGivenOnes) {
  ASSERT_EQ(Solve().exit_code, 0);
  const nlohmann::json as_given = ReadJsonFile(dir_.File("out/result.json"));
  std::istringstream in(fiducials_);
  std::string line, mirrored;
  std::getline(in, line);
  mirrored = line + "\n";
  while (std::getline(in, line)) {
    std::vector<std::string> f;
    std::stringstream cells(line);
    for (std::string c; std::getline(cells, c, ',');) f.push_back(c);
    ASSERT_EQ(f.size(), 10u) << line;
    f[2] = std::to_string(-std::stod(f[2]));
    for (size_t k = 0; k < f.size(); ++k) mirrored += (k ? "," : "") + f[k];
    mirrored += "\n";
  }
  fiducials_ = mirrored;
  problem_ += "handedness: mirrored\n";
  std::filesystem::remove_all(dir_.File("out"));
  ASSERT_EQ(Solve().exit_code, 0);
  const nlohmann::json m = ReadJsonFile(dir_.File("out/result.json"));
  for (const char* k : {"fx", "fy", "cx", "cy"}) {
    EXPECT_NEAR(m["intrinsics"][k].get<double>(), as_given["intrinsics"][k].get<double>(), 1e-6)
        << k;
  }
  for (size_t v = 0; v < as_given["views"].size(); ++v) {
    if (as_given["views"][v]["kind"] != "object") continue;
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(m["views"][v]["cam_from_object"]["t_mm"][i].get<double>(),
                  as_given["views"][v]["cam_from_object"]["t_mm"][i].get<double>(),
                  1e-4);
    }
  }
}

TEST_F(JointBadInput, PerGroupIntrinsics) {
  problem_ += "intrinsics: {model: per_group, groups: groups.csv}\n";
  groups_ = "view,group\nplate00,a\nplate01,a\nplate02,a\n3,b\n4,b\nplate05,b\n"
            "+000,a\n+030,b\n+090,b\n";
  config_ = "name: c\nfix: [k1, k2, p1, p2, k3]\n";  // 3 plate views per group: pinhole
  const auto r = Solve();
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = ReadJsonFile(dir_.File("out/result.json"));
  ASSERT_TRUE(j.at("intrinsics").is_array());
  ASSERT_EQ(j.at("intrinsics").size(), 2u);
  EXPECT_EQ(j.at("intrinsics")[0].at("group"), "a");
  EXPECT_EQ(j.at("intrinsics")[1].at("group"), "b");
  for (const auto& g : j.at("intrinsics")) {
    EXPECT_NEAR(g.at("fx").get<double>(), 2000.0, 5 * g.at("sigmas").at("fx").get<double>() + 1);
  }
  // The state layout names each group's parameters.
  EXPECT_EQ(j.at("state_layout")[0], "a fx");
  // geometry.json: the object views, each with the intrinsics of its own group.
  const nlohmann::json g = ReadJsonFile(dir_.File("out/geometry.json"));
  ASSERT_EQ(g.at("views").size(), 3u);
  for (const auto& gv : g.at("views")) {
    const int group = gv.at("id") == "+000" ? 0 : 1;
    EXPECT_EQ(gv.at("camera").at("fx").get<double>(),
              j.at("intrinsics")[group].at("fx").get<double>())
        << gv.at("id");
  }
  for (const auto& v : j.at("views")) {
    if (v.at("id") == "+030") {
      EXPECT_EQ(v.at("group"), "b");
    }
  }
}

TEST_F(JointBadInput, MarkerNotInFiducials) {
  object_ += "+090,42,200.0,200.0\n";
  ExpectError("observes marker 42, which is not among the fiducials");
}

TEST_F(JointBadInput, FiducialsWithoutCovarianceAndNoSigma) {
  fiducials_ =
      "id,x_mm,y_mm,z_mm\n1,0,0,0\n2,-58.85,1,14\n3,13.35,1,14\n4,-8.25,-20.5,24\n"
      "5,-56.05,19,31\n6,-27.07,-20,31\n7,-15.01,-21.5,40\n8,-42.2,18.75,44\n9,-1.4,5,49\n";
  ExpectError("fiducials.sigma_mm: missing: give the CT sigma or covariance columns");
}

// A value out of range in the fiducials' mapping is named before the CSV is read (it used to
// give "fiducials.sigma_mm: missing", as if the key were not there).
TEST_F(JointBadInput, FiducialsSigmaOutOfRange) {
  const std::string from = "fiducials: fiducials.csv\n";
  problem_.replace(problem_.find(from), from.size(),
                   "fiducials: {file: fiducials.csv, sigma_mm: 2e-9}\n");
  ExpectError("problem.yaml:4: key 'fiducials.sigma_mm': expected 1e-06 .. 1000 mm, got 2e-09");
}

// plate_views.sigma_px is optional in the schema (`carmba calibrate` estimates it) but `carmba
// solve` needs it, and says so before it solves.
TEST_F(JointBadInput, PlateSigmaMissing) {
  const std::string from = "plate_views: {observations: plate.csv, sigma_px: 0.05}\n";
  problem_.replace(problem_.find(from), from.size(), "plate_views: {observations: plate.csv}\n");
  ExpectError("key 'plate_views.sigma_px': missing");
}

TEST_F(JointBadInput, ObjectViewWithFewerThanFourMarkers) {
  object_ += "+045,1,200.0,200.0\n+045,2,210.0,200.0\n+045,3,200.0,210.0\n";
  ExpectError("object view '+045' has 3 observed markers; a pose needs at least 4");
}

TEST_F(JointBadInput, ViewInTwoGroups) {
  problem_ += "intrinsics: {model: per_group, groups: groups.csv}\n";
  groups_ = "view,group\nplate00,a\nplate00,b\n";
  ExpectError("groups.csv:3: view 'plate00' is in two groups ('a' and 'b')");
}

TEST_F(JointBadInput, GroupWithoutPlateViews) {
  problem_ += "intrinsics: {model: per_group, groups: groups.csv}\n";
  groups_ = "view,group\n";
  for (int v = 0; v < 6; ++v) groups_ += "plate0" + std::to_string(v) + ",lao0\n";
  groups_ += "+000,lao0\n+030,lao0\n+090,lao90\n";
  ExpectError("intrinsics group 'lao90' has no plate views and no camera file");
}

TEST_F(JointBadInput, PlateObservationsOfAnotherGridSize) {
  problem_ =
      "name: joint_bad_input\n"
      "plate_views: {observations: plate.csv, sigma_px: 0.05, pattern: circles, rows: 6, cols: 8,"
      " spacing_mm: 15}\n"
      "object_views: {observations: object.csv, sigma_px: 0.2}\n"
      "fiducials: fiducials.csv\n";
  ExpectError(
      "plate.csv: grid circles 5x5 spacing 20.000000 mm, "
      "but plate_views.rows/cols/spacing_mm say circles 6x8");
}

TEST_F(JointBadInput, CalibrationConfigGivenToSolve) {
  config_ = "fix: []\nrobust_loss: none\npixel_sigma_px: 0\n";
  ExpectError("this is a calibration config (key 'robust_loss'), for `carmba calibrate`");
}

TEST_F(JointBadInput, ProblemNamesItsConfig) {
  problem_ += "config: ../configs/joint_radial.yaml\n";
  ExpectError("a problem does not name its config");
}

TEST_F(JointBadInput, UnknownFixName) {
  config_ = "name: c\nfix: [p1, q2]\n";
  ExpectError("'q2' is not an intrinsic");
}

// The object views' covariance columns count in a joint problem as in a pose problem (one reader,
// problem/pixel_csv.h): with them, the object observations are the "detected blobs" noise group
// (whitened by their 2x2), without them the "object pixels" group.
std::string WithCovarianceColumns(const std::string& csv, const std::string& cov) {
  std::istringstream in(csv);
  std::string line, out;
  bool header = true;
  while (std::getline(in, line)) {
    out += line + (header ? ",cov_uu,cov_uv,cov_vv" : "," + cov) + "\n";
    header = false;
  }
  return out;
}

std::vector<std::string> NoiseGroupKeys(const nlohmann::json& result) {
  std::vector<std::string> keys;
  for (const auto& g : result.at("variance_components").at("groups")) keys.push_back(g.at("group"));
  return keys;
}

TEST_F(JointBadInput, ObjectCovarianceColumnsMakeDetectedBlobs) {
  auto without = Solve();
  ASSERT_EQ(without.exit_code, 0) << without.err;
  const auto plain = NoiseGroupKeys(ReadJsonFile(dir_.File("out/result.json")));
  EXPECT_NE(std::find(plain.begin(), plain.end(), "object_pixels"), plain.end());
  EXPECT_EQ(std::find(plain.begin(), plain.end(), "detected_blobs"), plain.end());
  std::filesystem::remove_all(dir_.File("out"));
  object_ = WithCovarianceColumns(object_, "0.04,0.01,0.05");
  const auto with = Solve();
  ASSERT_EQ(with.exit_code, 0) << with.err;
  const auto blobs = NoiseGroupKeys(ReadJsonFile(dir_.File("out/result.json")));
  EXPECT_NE(std::find(blobs.begin(), blobs.end(), "detected_blobs"), blobs.end());
  EXPECT_EQ(std::find(blobs.begin(), blobs.end(), "object_pixels"), blobs.end());
}

TEST_F(JointBadInput, ObjectCovarianceNotPositiveDefinite) {
  object_ = WithCovarianceColumns(object_, "0.04,0.05,0.05");
  ExpectError("object.csv:2: columns cov_uu, cov_uv, cov_vv: expected a positive definite pixel "
              "covariance (px^2), got 0.04, 0.05, 0.05");
}

}  // namespace
}  // namespace carmba::test
