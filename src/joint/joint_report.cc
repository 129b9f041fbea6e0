// result.json and report.md of a joint solve (joint_problem.h).
#include <cmath>
#include <cstdio>
#include <sstream>

#include "geometry/rotation.h"
#include "joint/joint_problem.h"

namespace carmba {
namespace {

nlohmann::json Num(double x) { return std::isfinite(x) ? nlohmann::json(x) : nlohmann::json(); }

nlohmann::json Vec(const Eigen::VectorXd& v) {
  nlohmann::json j = nlohmann::json::array();
  for (Eigen::Index i = 0; i < v.size(); ++i) j.push_back(Num(v[i]));
  return j;
}

nlohmann::json Rows(const Eigen::MatrixXd& m) {
  nlohmann::json j = nlohmann::json::array();
  for (Eigen::Index r = 0; r < m.rows(); ++r) j.push_back(Vec(m.row(r).transpose()));
  return j;
}

std::string Fmt(const char* f, double x) {
  char b[64];
  std::snprintf(b, sizeof b, f, x);
  return b;
}

// The group's intrinsics as camera.json writes them, with the joint covariance (a smooth group:
// its coefficients, FlexModelJson).
nlohmann::json GroupJson(const JointSolution& s, int g) {
  if (s.ba_problem.groups[g].smooth) return FlexModelJson(s);
  const ba::StateLayout& L = *s.result.layout;
  const int b = L.group_block(g);
  Camera c;
  const double* x = s.result.block(b);
  std::copy(x, x + kNumIntrinsics, c.params.begin());
  c.width = s.ba_problem.groups[g].width;
  c.height = s.ba_problem.groups[g].height;
  const Eigen::MatrixXd C = s.result.Covariance({b});
  c.covariance_names.assign(kIntrinsicNames, kIntrinsicNames + kNumIntrinsics);
  c.covariance.assign(kNumIntrinsics, std::vector<double>(kNumIntrinsics));
  for (int i = 0; i < kNumIntrinsics; ++i) {
    for (int j = 0; j < kNumIntrinsics; ++j) c.covariance[i][j] = C(i, j);
  }
  nlohmann::json j = CameraToJson(c);
  nlohmann::json sig;
  for (int i = 0; i < kNumIntrinsics; ++i) sig[kIntrinsicNames[i]] = std::sqrt(std::max(0.0, C(i, i)));
  j["sigmas"] = sig;
  j["group"] = s.ba_problem.groups[g].name;
  return j;
}

const ba::BudgetRow* FindRow(const JointSolution& s, const std::string& name) {
  for (const auto& r : s.budget) {
    if (r.quantity.name == name) return &r;
  }
  return nullptr;
}

}  // namespace

nlohmann::json JointSolutionToJson(const JointProblem& problem,
                                   const SolverConfig& config,
                                   const JointSolution& s) {
  const ba::StateLayout& L = *s.result.layout;
  const ba::BaResult& r = s.result;
  nlohmann::json j;
  j["problem"] = {{"name", problem.name},
                  {"file", problem.path},
                  {"kind", "joint"},
                  {"plate_views", problem.plate.views.size()},
                  {"object_views", problem.object_views.size()},
                  {"plate_sigma_px", problem.plate_sigma_px},
                  {"object_sigma_px", problem.object_sigma_px},
                  {"intrinsics_model", problem.per_group ? "per_group" : "shared"},
                  {"initial_intrinsics_from", s.initial_intrinsics_from}};
  if (s.ba_problem.groups.size() == 1) {
    j["intrinsics"] = GroupJson(s, 0);
  } else {
    nlohmann::json a = nlohmann::json::array();
    for (size_t g = 0; g < s.ba_problem.groups.size(); ++g) a.push_back(GroupJson(s, static_cast<int>(g)));
    j["intrinsics"] = a;
  }
  nlohmann::json views = nlohmann::json::array();
  for (size_t v = 0; v < s.ba_problem.views.size(); ++v) {
    const ba::BaView& bv = s.ba_problem.views[v];
    const int b = L.view_block(static_cast<int>(v));
    Pose6 pose;
    for (int i = 0; i < 6; ++i) pose[i] = r.block(b)[i];
    nlohmann::json vj;
    vj["id"] = bv.id;
    vj["kind"] = bv.kind == ba::ViewKind::kPlate ? "plate" : "object";
    vj["group"] = s.ba_problem.groups[bv.group].name;
    vj[bv.kind == ba::ViewKind::kPlate ? "cam_from_plate" : "cam_from_object"] = {
        {"rvec", Vec(pose.head<3>())}, {"t_mm", Vec(pose.tail<3>())}};
    vj["rms_px"] = Num(r.views[v].rms_px);
    vj["num_observations"] = r.views[v].num_observations;
    if (bv.kind == ba::ViewKind::kObject) {
      vj["covariance_6x6"] = Rows(r.Covariance({b}));
      vj["covariance_order"] = "rx ry rz (rad, rotation vector), tx ty tz (mm)";
      static const char* const kAxis[3] = {"x", "y", "z"};
      nlohmann::json sr = nlohmann::json::array(), st = nlohmann::json::array();
      for (int a = 0; a < 3; ++a) {
        sr.push_back(Num(FindRow(s, "view " + bv.id + " rot " + kAxis[a])->sigma));
        st.push_back(Num(FindRow(s, "view " + bv.id + " t" + kAxis[a])->sigma));
      }
      vj["sigma_rotation_deg"] = sr;
      vj["sigma_translation_mm"] = st;
      auto it = problem.truth.object_poses.find(bv.id);
      if (it != problem.truth.object_poses.end()) {
        vj["truth"] = {{"rvec", Vec(it->second.head<3>())}, {"t_mm", Vec(it->second.tail<3>())}};
        vj["rotation_error_deg"] = AngleBetweenRotations(RotationFromRvec(pose.head<3>()),
                                                         RotationFromRvec(it->second.head<3>())) *
                                   kRadToDeg;
        vj["translation_error_mm"] = (pose.tail<3>() - it->second.tail<3>()).norm();
      }
    }
    views.push_back(vj);
  }
  j["views"] = views;
  AddFlexJson(problem, s, &j);
  nlohmann::json val = nlohmann::json::array();
  for (size_t k = 0; k < problem.validation.size(); ++k) {
    const auto& vp = problem.validation[k];
    const std::string name = "pair " + vp.a + "/" + vp.b;
    const ba::BudgetRow* rr = FindRow(s, name + " relative rotation");
    const ba::BudgetRow* vd = FindRow(s, name + " view directions");
    nlohmann::json pj = {{"a", vp.a},
                         {"b", vp.b},
                         {"relative_rotation_deg", Num(rr->quantity.value)},
                         {"sigma_relative_rotation_deg", Num(rr->sigma)},
                         {"angle_view_dirs_deg", Num(vd->quantity.value)},
                         {"sigma_view_dirs_deg", Num(vd->sigma)},
                         {"expected_deg", vp.expected_deg ? nlohmann::json(*vp.expected_deg)
                                                          : nlohmann::json()}};
    auto ta = problem.truth.object_poses.find(vp.a), tb = problem.truth.object_poses.find(vp.b);
    if (ta != problem.truth.object_poses.end() && tb != problem.truth.object_poses.end()) {
      pj["true_relative_rotation_deg"] = RelativeRotationAngle(ta->second.data(), tb->second.data()) * kRadToDeg;
    }
    val.push_back(pj);
  }
  j["validation"] = val;
  nlohmann::json markers = nlohmann::json::array();
  for (size_t m = 0; m < s.ba_problem.markers.size(); ++m) {
    const int b = L.marker_block(static_cast<int>(m));
    markers.push_back({{"id", s.ba_problem.markers[m].id},
                       {"p_in_object_mm", Vec(Eigen::Map<const Eigen::Vector3d>(r.block(b)))},
                       {"covariance_mm2", Rows(r.Covariance({b}))}});
  }
  j["markers"] = markers;
  nlohmann::json outliers = nlohmann::json::array();
  for (const auto& o : r.outliers) {
    outliers.push_back({{"view", o.view},
                        {o.plate ? "point" : "marker", o.id},
                        {"residual_sigma", Num(o.residual_sigma)},
                        {"du_px", Num(o.du_px)},
                        {"dv_px", Num(o.dv_px)}});
  }
  j["outliers"] = outliers;
  nlohmann::json rejected = nlohmann::json::array();
  for (const auto& o : r.rejected) {
    rejected.push_back({{"view", o.view}, {o.plate ? "point" : "marker", o.id},
                        {"residual_sigma", Num(o.residual_sigma)}});
  }
  j["rejected"] = rejected;
  nlohmann::json layout = nlohmann::json::array();
  for (int k = 0; k < L.num_free(); ++k) layout.push_back(L.FreeName(k));
  j["state_layout"] = layout;
  nlohmann::json budget = nlohmann::json::array();
  for (const auto& row : s.budget) {
    nlohmann::json src = nlohmann::json::array();
    for (int k = 0; k < ba::kNumSources; ++k) {
      src.push_back({{"source", ba::SourceName(static_cast<ba::Source>(k))},
                     {"sigma", Num(row.source_sigma[k])},
                     {"share", Num(row.share[k])}});
    }
    budget.push_back({{"quantity", row.quantity.name},
                      {"unit", row.quantity.unit},
                      {"value", Num(row.quantity.value)},
                      {"sigma", Num(row.sigma)},
                      {"sources", src}});
  }
  j["error_budget"] = budget;
  nlohmann::json cmp = nlohmann::json::array();
  for (const auto& c : s.comparison) {
    nlohmann::json cj;
    cj["method"] = c.method;
    nlohmann::json pv = nlohmann::json::array();
    for (size_t k = 0; k < c.sigma_rotation_deg.size(); ++k) {
      pv.push_back({{"sigma_rotation_deg", Vec(c.sigma_rotation_deg[k])},
                    {"sigma_translation_mm", Vec(c.sigma_translation_mm[k])}});
    }
    cj["object_views"] = pv;
    cj["sigma_relative_rotation_deg"] = c.sigma_relative_rotation_deg;
    cj["relative_rotation_deg"] = c.relative_rotation_deg;
    cmp.push_back(cj);
  }
  j["two_step_comparison"] = cmp;
  if (!s.comparison_error.empty()) j["two_step_comparison_error"] = s.comparison_error;
  j["statistics"] = {{"rms_plate_px", Num(r.rms_plate_px)},
                     {"rms_object_px", Num(r.rms_object_px)},
                     {"sigma0", Num(r.sigma0)},
                     {"chi2", Num(r.chi2)},
                     {"dof", r.dof},
                     {"chi2_p_value", Num(r.chi2_p_value)},
                     {"num_residuals", r.num_residuals},
                     {"num_parameters", r.num_free},
                     {"covariance_scale", config.covariance_aposteriori ? "aposteriori" : "apriori"}};
  j["solver"] = {{"config", config.name},
                 {"engine", "ceres (src/ba)"},
                 {"iterations", r.iterations},
                 {"termination", r.termination},
                 {"converged", r.converged},
                 {"initial_cost", Num(r.initial_cost)},
                 {"final_cost", Num(r.final_cost)},
                 {"time_s", Num(r.time_s)}};
  return j;
}

std::string JointReportMarkdown(const JointProblem& problem,
                                const SolverConfig& config,
                                const JointSolution& s) {
  const ba::BaResult& r = s.result;
  std::ostringstream o;
  o << "# Joint bundle adjustment: " << problem.name << "\n\n";
  if (!problem.description.empty()) o << problem.description << "\n\n";
  o << "Calibration and pose as one bundle adjustment (src/ba): " << problem.plate.views.size()
    << " plate views (sigma " << problem.plate_sigma_px << " px), " << problem.object_views.size()
    << " object views (sigma " << problem.object_sigma_px << " px), " << problem.fiducials.size()
    << " CT fiducials as priors. Config `" << config.name << "`; uncertainties use the "
    << (config.covariance_aposteriori ? "a-posteriori" : "a-priori") << " pixel sigmas.\n\n";
  if (!problem.skipped_images.empty()) {
    o << "Plate images without a usable grid (" << problem.skipped_images.size() << "):\n";
    for (const auto& sk : problem.skipped_images) o << "- " << sk << "\n";
    o << "\n";
  }
  o << "## Statistics\n\n| | |\n|---|---|\n";
  o << "| RMS plate views (px per coordinate) | " << Fmt("%.4f", r.rms_plate_px) << " |\n";
  o << "| RMS object views (px per coordinate) | " << Fmt("%.4f", r.rms_object_px) << " |\n";
  o << "| chi-square / dof | " << Fmt("%.2f", r.chi2) << " / " << r.dof << " (P = "
    << Fmt("%.3f", r.chi2_p_value) << ", sigma0 " << Fmt("%.3f", r.sigma0) << ") |\n";
  o << "| iterations, termination | " << r.iterations << ", " << r.termination << " |\n";
  o << "| time | " << Fmt("%.1f", r.time_s * 1e3) << " ms |\n\n";
  if (!r.converged) o << "**Warning:** the solve did not converge (" << r.termination << ").\n\n";

  o << "## Intrinsics\n\n| group | parameter | value | sigma |";
  if (problem.truth.camera) o << " truth | error / sigma |";
  o << "\n|---|---|---|---|" << (problem.truth.camera ? "---|---|" : "") << "\n";
  for (size_t g = 0; g < s.ba_problem.groups.size(); ++g) {
    const int b = r.layout->group_block(static_cast<int>(g));
    const Eigen::MatrixXd C = r.Covariance({b});
    if (s.ba_problem.groups[g].smooth) continue;  // FlexReportMarkdown
    for (int i = 0; i < kNumIntrinsics; ++i) {
      const double x = r.block(b)[i], sg = std::sqrt(std::max(0.0, C(i, i)));
      o << "| " << s.ba_problem.groups[g].name << " | " << kIntrinsicNames[i] << " | "
        << Fmt("%.6g", x) << " | " << (sg > 0 ? Fmt("%.3g", sg) : std::string("held")) << " |";
      if (problem.truth.camera) {
        const double t = problem.truth.camera->params[i];
        o << " " << Fmt("%.6g", t) << " | " << (sg > 0 ? Fmt("%.2f", (x - t) / sg) : std::string("")) << " |";
      }
      o << "\n";
    }
  }
  o << FlexReportMarkdown(problem, s);
  o << "\n## Validation pairs (object views)\n\n"
       "| a | b | expected (deg) | relative rotation (deg) | sigma | view directions (deg) | sigma |";
  const bool truth_poses = !problem.truth.object_poses.empty();
  if (truth_poses) o << " true relative rotation | error / sigma |";
  o << "\n|---|---|---|---|---|---|---|" << (truth_poses ? "---|---|" : "") << "\n";
  for (const auto& vp : problem.validation) {
    const std::string name = "pair " + vp.a + "/" + vp.b;
    const ba::BudgetRow* rr = FindRow(s, name + " relative rotation");
    const ba::BudgetRow* vd = FindRow(s, name + " view directions");
    o << "| " << vp.a << " | " << vp.b << " | "
      << (vp.expected_deg ? Fmt("%g", *vp.expected_deg) : std::string("")) << " | "
      << Fmt("%.3f", rr->quantity.value) << " | " << Fmt("%.3f", rr->sigma) << " | "
      << Fmt("%.3f", vd->quantity.value) << " | " << Fmt("%.3f", vd->sigma) << " |";
    auto ta = problem.truth.object_poses.find(vp.a), tb = problem.truth.object_poses.find(vp.b);
    if (truth_poses) {
      if (ta != problem.truth.object_poses.end() && tb != problem.truth.object_poses.end()) {
        const double t = RelativeRotationAngle(ta->second.data(), tb->second.data()) * kRadToDeg;
        o << " " << Fmt("%.3f", t) << " | " << Fmt("%.2f", (rr->quantity.value - t) / rr->sigma) << " |";
      } else {
        o << " | |";
      }
    }
    o << "\n";
  }
  o << "\n## Error budget\n\nShare of each quantity's variance from each independent noise source "
       "(first order: Var(f) = sum_s G H^-1 J_s^T J_s H^-1 G^T; the shares add up to 100 %). "
       "Rotations are small rotations about the camera axes (their value is 0 by definition); "
       "`centre projection` is where the ray of the image centre, held fixed at the object "
       "distance, projects with the estimated intrinsics (its value is the image centre, its "
       "sigma the calibration's own uncertainty there).\n\n"
       "| quantity | unit | value | sigma |";
  for (int k = 0; k < ba::kNumSources; ++k) o << " " << ba::SourceName(static_cast<ba::Source>(k)) << " |";
  o << "\n|---|---|---|---|";
  for (int k = 0; k < ba::kNumSources; ++k) o << "---|";
  o << "\n";
  for (const auto& row : s.budget) {
    o << "| " << row.quantity.name << " | " << row.quantity.unit << " | "
      << Fmt("%.6g", row.quantity.value) << " | " << Fmt("%.3g", row.sigma) << " |";
    for (int k = 0; k < ba::kNumSources; ++k) {
      o << " " << (row.share[k] > 0 ? Fmt("%.1f %%", 100 * row.share[k]) : std::string("-")) << " |";
    }
    o << "\n";
  }
  o << "\n## Joint against two-step\n\n";
  if (!s.comparison_error.empty()) {
    o << "Not shown: " << s.comparison_error << ".\n";
  } else {
    o << "Sigma of each validation pair's relative rotation (deg) and the mean rotation / "
         "translation sigma of the object poses. Two-step with the intrinsics held leaves the "
         "calibration's uncertainty out (its sigmas are too small); with the calibration's "
         "covariance as a prior it equals the joint result to first order.\n\n| method |";
    for (const auto& vp : problem.validation) o << " " << vp.a << "-" << vp.b << " |";
    o << " mean rotation sigma (deg) | mean translation sigma (mm) |\n|---|";
    for (size_t k = 0; k < problem.validation.size(); ++k) o << "---|";
    o << "---|---|\n";
    for (const auto& c : s.comparison) {
      o << "| " << c.method << " |";
      for (double x : c.sigma_relative_rotation_deg) o << " " << Fmt("%.4f", x) << " |";
      double mr = 0, mt = 0;
      for (size_t k = 0; k < c.sigma_rotation_deg.size(); ++k) {
        mr += c.sigma_rotation_deg[k].norm() / std::sqrt(3.0);
        mt += c.sigma_translation_mm[k].norm() / std::sqrt(3.0);
      }
      const double n = std::max<size_t>(1, c.sigma_rotation_deg.size());
      o << " " << Fmt("%.4f", mr / n) << " | " << Fmt("%.4f", mt / n) << " |\n";
    }
  }
  o << "\n## Outliers\n\n";
  if (r.outliers.empty()) {
    o << "None above " << config.outlier_sigma << " sigma.\n";
  } else {
    o << "| view | point / marker | residual (sigma) | du (px) | dv (px) |\n|---|---|---|---|---|\n";
    for (const auto& out : r.outliers) {
      o << "| " << out.view << " | " << (out.plate ? "point " : "marker ") << out.id << " | "
        << Fmt("%.1f", out.residual_sigma) << " | " << Fmt("%.3f", out.du_px) << " | "
        << Fmt("%.3f", out.dv_px) << " |\n";
    }
  }
  if (!r.rejected.empty()) {
    o << "\nRejected (reject_sigma " << config.reject_sigma << ", solved again without them):";
    for (const auto& out : r.rejected) {
      o << " " << out.view << "/" << (out.plate ? "point " : "marker ") << out.id << " ("
        << Fmt("%.1f", out.residual_sigma) << " sigma);";
    }
    o << "\n";
  }
  return o.str();
}

std::string JointMrcalMarkdown(const nlohmann::json& c) {
  std::ostringstream o;
  o << "\n## Cross-check with mrcal\n\n";
  if (c.contains("error")) {
    o << "Not run: " << c.at("error").get<std::string>() << ".\n";
    return o.str();
  }
  o << "The same plate and marker observations solved by carmba's engine and by mrcal "
    << c.at("mrcal").value("mrcal_version", std::string("2.2")) << "'s `mrcal.optimize` ("
    << c.at("what").get<std::string>() << "; mrcal cannot hold single distortion terms or tie "
       "points to priors, so this variant differs from the solve above).\n\n"
       "| | fx | fy | cx | cy | k1 | k2 | p1 | p2 | k3 | RMS (mrcal's definition, px) |\n"
       "|---|---|---|---|---|---|---|---|---|---|---|\n";
  auto row = [&](const std::string& who, const nlohmann::json& x, double rms) {
    o << "| " << who << " |";
    for (const auto& v : x) o << " " << Fmt("%.8g", v.get<double>()) << " |";
    o << " " << Fmt("%.8g", rms) << " |\n";
  };
  row("carmba", c.at("carmba").at("intrinsics"), c.at("rms_px_carmba_in_mrcal").get<double>());
  row("mrcal", c.at("mrcal").at("intrinsics"), c.at("rms_px_mrcal").get<double>());
  o << "| relative difference |";
  for (int i = 0; i < kNumIntrinsics; ++i) {
    o << " " << Fmt("%.1e", c.at("relative_difference").at(kIntrinsicNames[i]).get<double>()) << " |";
  }
  o << " " << Fmt("%.1e", std::abs(c.at("rms_px_mrcal").get<double>() / c.at("rms_px_carmba_in_mrcal").get<double>() - 1)) << " |\n";
  o << "\nLargest difference: " << Fmt("%.2e", c.at("max_relative_difference_fx_fy_cx_cy").get<double>())
    << " relative in fx, fy, cx, cy; " << Fmt("%.2e", c.at("max_difference_in_sigmas").get<double>())
    << " sigma over all nine intrinsics.\n";
  return o.str();
}

}  // namespace carmba
