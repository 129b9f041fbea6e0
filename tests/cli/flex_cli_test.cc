// C-arm flex through `carmba` (issue 14): the flexing joint scene simulated (per-view true
// intrinsics, views.csv), solved with the smooth model (per-view intrinsics and object poses at
// and between the calibrated angles within 3 sigma of the truth, the held-out selection picking
// smooth, result.json's keys, the plot), and bad input: a view without angles, too few
// orientation groups for the smooth model, an angles row naming no view.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "cli_test_util.h"
#include "markdown_doc.h"

namespace carmba::test {
namespace {

constexpr double kFlexSigmas = 3.0;  // the acceptance: within 3 sigma of the truth

std::string Replace(std::string s, const std::string& from, const std::string& to) {
  for (size_t p = s.find(from); p != std::string::npos; p = s.find(from, p + to.size())) {
    s.replace(p, from.size(), to);
  }
  return s;
}

TEST(FlexCli, FlexingSceneSmoothModelWithinThreeSigmaAndBadInput) {
  ScratchDir dir;
  const std::string scene = dir.File("scene");
  ASSERT_EQ(SimulateJointScene("flex_joint.yaml", scene), "");
  const nlohmann::json truth = ReadJsonFile(scene + "/truth.json");
  // The simulator's per-view truth follows the flex (camera/carm_flex.h).
  for (const auto& v : truth.at("view_intrinsics")) {
    if (v.at("id") != "plate_pp40_sp00_1") continue;
    EXPECT_NEAR(
        v.at("camera").at("cx").get<double>(), 203.655 + 6.0 * std::sin(40 * M_PI / 180), 1e-9);
    EXPECT_NEAR(v.at("camera").at("fx").get<double>(),
                2061.389 * (1 + 0.004 * (1 - std::cos(40 * M_PI / 180))), 1e-9);
  }
  const std::string problem =
      Replace(ReadTextFile(kSource + "/problems/flex_joint_smooth.yaml"), "../out/sim/flex", scene);
  dir.Write("problem.yaml", problem);
  const std::string config = " --config " + kSource + "/configs/joint_radial.yaml";
  auto r = RunCarmba("solve --problem " + dir.File("problem.yaml") + config + " --out " +
                     dir.File("out"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = ReadJsonFile(dir.File("out/result.json"));
  std::map<std::string, nlohmann::json> true_intr;
  for (const auto& v : truth.at("view_intrinsics")) true_intr[v.at("id")] = v.at("camera");
  std::map<std::string, nlohmann::json> true_pose;
  for (const auto& v : truth.at("object_views")) true_pose[v.at("id")] = v;
  int n_views = 0, n_between = 0;
  for (const auto& v : j.at("views")) {
    const std::string id = v.at("id");
    const auto& in = v.at("intrinsics");
    ASSERT_EQ(in.at("covariance").at("names").size(), 9u) << id;
    const auto& names = in.at("covariance").at("names");
    for (int i = 0; i < 4; ++i) {
      const std::string k = names.at(i);
      const double e = in.at(k).get<double>() - true_intr.at(id).at(k).get<double>();
      const double s = std::sqrt(in.at("covariance").at("matrix").at(i).at(i).get<double>());
      EXPECT_LT(std::abs(e), kFlexSigmas * s)
          << id << " " << k << ": error " << e << " sigma " << s;
    }
    ++n_views;
    if (v.at("kind") != "object") continue;
    // The pose within 3 sigma, per parameter (rvec, t) of its 6x6 covariance.
    const auto& C = v.at("covariance_6x6");
    const auto& est = v.at("cam_from_object");
    const auto& tp = true_pose.at(id);
    for (int i = 0; i < 6; ++i) {
      const double x =
          i < 3 ? est.at("rvec").at(i).get<double>() : est.at("t_mm").at(i - 3).get<double>();
      const double t =
          i < 3 ? tp.at("rvec").at(i).get<double>() : tp.at("t_mm").at(i - 3).get<double>();
      const double s = std::sqrt(C.at(i).at(i).get<double>());
      EXPECT_LT(std::abs(x - t), kFlexSigmas * s) << id << " pose " << i;
    }
    const double p = v.at("primary_deg"), sec = v.at("secondary_deg");
    const bool between = std::abs(std::fmod(std::abs(p), 20.0)) > 1e-9 || sec != 0;
    n_between += between;
  }
  EXPECT_EQ(n_views, 36);
  EXPECT_EQ(n_between, 5);
  EXPECT_EQ(j.at("intrinsics_model").at("name"), "smooth");
  EXPECT_EQ(j.at("intrinsics_model").at("coefficients").at("names").size(), 21u);
  EXPECT_EQ(j.at("intrinsics_model").at("coefficients").at("covariance").size(), 21u);
  EXPECT_EQ(j.at("model_selection").at("recommended"), "smooth")
      << j.at("model_selection").at("why");
  EXPECT_EQ(j.at("model_selection").at("scores").size(), 3u);
  // Its keys as formats.md lists them: the joint result's table plus the flex table, and every
  // key of the flex table written.
  {
    const MarkdownDoc formats = ReadMarkdownDoc(kSource + "/src/docs/formats.md");
    ASSERT_TRUE(formats.tables.count("json-result-joint") &&
                formats.tables.count("json-result-joint-flex"));
    const auto& flex_rows = formats.tables.at("json-result-joint-flex");
    std::set<std::string> documented(flex_rows.begin(), flex_rows.end());
    const std::set<std::string> flex_keys = documented;
    for (const auto& k : formats.tables.at("json-result-joint")) documented.insert(k);
    std::set<std::string> written;
    FlattenJsonKeys(j, "", 2, &written);
    EXPECT_TRUE(Minus(written, documented).empty())
        << "written, not in formats.md: " << JoinSet(Minus(written, documented));
    std::set<std::string> missing;  // the `...error` keys are written only when a check fails
    for (const auto& k : Minus(flex_keys, written)) {
      if (k.size() < 5 || k.compare(k.size() - 5, 5, "error") != 0) missing.insert(k);
    }
    EXPECT_TRUE(missing.empty()) << "in the flex table, not written: " << JoinSet(missing);
  }
  const std::string md = ReadTextFile(dir.File("out/report.md"));
  EXPECT_NE(md.find("## Intrinsics per view (C-arm angles)"), std::string::npos);
  EXPECT_NE(md.find("## Intrinsics model selection"), std::string::npos);
  EXPECT_NE(md.find("**Recommended: `smooth`**"), std::string::npos);
  // The intrinsics against the angle, drawn by the report layer into report.html.
  EXPECT_NE(ReadTextFile(dir.File("out/report.html")).find("data-plot=\"intrinsics-vs-angle\""),
            std::string::npos);

  // Bad input, one corruption at a time: no output, a one-line error.
  const std::string angles = ReadTextFile(scene + "/views.csv");
  auto expect_error = [&](const std::string& csv,
                          const std::string& model,
                          const std::string& what) {
    ScratchDir bad;
    bad.Write("views.csv", csv);
    bad.Write("problem.yaml", Replace(Replace(problem, scene + "/views.csv", bad.File("views.csv")),
                                      "model: smooth", "model: " + model));
    auto e = RunCarmba("solve --problem " + bad.File("problem.yaml") + config + " --out " +
                       bad.File("out"));
    EXPECT_NE(e.exit_code, 0);
    EXPECT_NE(e.err.find(what), std::string::npos) << e.err;
    EXPECT_EQ(std::count(e.err.begin(), e.err.end(), '\n'), 1) << e.err;
    EXPECT_FALSE(std::filesystem::exists(bad.File("out")));
  };
  expect_error(
      Replace(angles, "obj_pp10_sp10,10,10\n", ""),
      "smooth",
      "object view 'obj_pp10_sp10' has no C-arm angles; intrinsics model smooth needs them");
  expect_error(
      Replace(angles, "obj_pp10_sp10,10,10\n", ""),
      "per_group",
      "object view 'obj_pp10_sp10' has no C-arm angles; intrinsics model per_group without groups");
  // Plate views at 3 orientations only (primary +-40 -> +-20, secondary +-20 -> 0).
  std::string three = Replace(Replace(angles, ",-40,0\n", ",-20,0\n"), ",40,0\n", ",20,0\n");
  three = Replace(Replace(three, ",0,-20\n", ",0,0\n"), ",0,20\n", ",0,0\n");
  // One secondary angle: the smooth model takes secondary_degree 0 itself and says so, and the
  // object views at secondary angles it was not calibrated at are named.
  {
    ScratchDir one;
    one.Write("views.csv", three);
    one.Write("problem.yaml", Replace(problem, scene + "/views.csv", one.File("views.csv")));
    auto e = RunCarmba("solve --problem " + one.File("problem.yaml") + config +
                       " --no-plots --no-mrcal --out " + one.File("out"));
    ASSERT_EQ(e.exit_code, 0) << e.err;
    EXPECT_NE(e.err.find("warning: every plate view is at secondary angle 0 deg: the smooth model "
                         "takes secondary_degree 0"),
              std::string::npos)
        << e.err;
    EXPECT_NE(e.err.find("warning: object view 'obj_pp10_sp10' (primary 10 deg, secondary 10 deg) "
                         "is outside the calibrated angles of the smooth intrinsics model"),
              std::string::npos)
        << e.err;
    const nlohmann::json j1 = ReadJsonFile(one.File("out/result.json"));
    bool said = false;
    for (const auto& w : j1.at("warnings"))
      said |= w.get<std::string>().find("secondary_degree 0") != std::string::npos;
    EXPECT_TRUE(said);
  }
  // Asked for explicitly, a degree the angles cannot support is an error that says what to do.
  {
    ScratchDir bad;
    bad.Write("views.csv", three);
    bad.Write("problem.yaml",
              Replace(Replace(problem, scene + "/views.csv", bad.File("views.csv")),
                      "intrinsics: {model: smooth}",
                      "intrinsics: {model: smooth, secondary_degree: 1}"));
    auto e = RunCarmba("solve --problem " + bad.File("problem.yaml") + config + " --out " +
                       bad.File("out"));
    EXPECT_NE(e.exit_code, 0);
    EXPECT_NE(e.err.find("intrinsics.secondary_degree 1: every plate view is at secondary angle 0 "
                         "deg, so no dependence on it can be estimated; set secondary_degree: 0"),
              std::string::npos)
        << e.err;
    EXPECT_EQ(std::count(e.err.begin(), e.err.end(), '\n'), 1) << e.err;
    EXPECT_FALSE(std::filesystem::exists(bad.File("out")));
  }
  // Too few orientations for the primary order: an error.
  std::string two = Replace(Replace(three, ",-20,0\n", ",0,0\n"), ",20,0\n", ",0,0\n");
  expect_error(
      two,
      "smooth",
      "model smooth has 3 coefficients per intrinsic (Fourier order 1 in the primary angle, "
      "degree 0 in the secondary) but the plate views cover 1 orientation group(s); it "
      "needs at least 3");
  expect_error(
      angles + "nosuchview,0,0\n", "smooth", "view 'nosuchview' is not a view of the problem");
}

}  // namespace
}  // namespace carmba::test
