// result.json and report.md of a joint solve (report/joint_report.h).
#include <cmath>
#include <cstdio>
#include <sstream>

#include "analysis/calibrated_range.h"
#include "ba/view_intrinsics.h"
#include "calib/conditioning.h"
#include "geometry/rotation.h"
#include "report/joint_report.h"

#include "report/engine_json.h"
#include "util/format.h"
#include "report/plots.h"
#include "report/pose_report.h"
#include "report/relative_tre_report.h"
#include "report/result_json.h"
#include "report/lens_report.h"
#include "report/variance_report.h"

namespace carmba {
namespace {


// The group's intrinsics as camera.json writes them, with the joint covariance (a smooth group:
// its coefficients, FlexModelJson).
nlohmann::json GroupJson(const JointSolution& s, int g) {
  if (s.ba_problem.groups[g].smooth) return FlexModelJson(s);
  Camera c;
  c.params = s.result.GroupIntrinsics(g);
  c.width = s.ba_problem.groups[g].width;
  c.height = s.ba_problem.groups[g].height;
  const Eigen::MatrixXd C = s.result.GroupIntrinsicsCovariance(g);
  c.covariance_names.assign(kIntrinsicNames, kIntrinsicNames + kNumIntrinsics);
  c.covariance.assign(kNumIntrinsics, std::vector<double>(kNumIntrinsics));
  for (int i = 0; i < kNumIntrinsics; ++i) {
    for (int j = 0; j < kNumIntrinsics; ++j) c.covariance[i][j] = C(i, j);
  }
  nlohmann::json j = CameraToJson(c);
  nlohmann::json sig;
  for (int i = 0; i < kNumIntrinsics; ++i)
    sig[kIntrinsicNames[i]] = std::sqrt(std::max(0.0, C(i, i)));
  j["sigmas"] = sig;
  j["group"] = s.ba_problem.groups[g].name;
  return j;
}

}  // namespace

GeometrySet JointSolutionGeometry(const Problem& problem, const JointSolution& s) {
  GeometrySet g;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& m : problem.fiducials) centroid += m.p_in_object;
  if (!problem.fiducials.empty()) g.reference_point_ct_mm = centroid / problem.fiducials.size();
  for (size_t v = 0; v < s.ba_problem.views.size(); ++v) {
    const ba::BaView& bv = s.ba_problem.views[v];
    if (bv.kind != ba::ViewKind::kObject) continue;
    ViewGeometry vg;
    vg.id = bv.id;
    // The view's intrinsics: its group's, or at its angles (a smooth group, ba/view_intrinsics.h).
    const ba::IntrinsicsGroup& grp = s.ba_problem.groups[bv.group];
    vg.camera.params = ba::IntrinsicsValueOfView(s.ba_problem, s.result, static_cast<int>(v));
    vg.camera.width = grp.width;
    vg.camera.height = grp.height;
    vg.cam_from_ct = s.result.ViewPose(static_cast<int>(v));
    g.views.push_back(vg);
  }
  return g;
}

namespace {

// Every view: its pose, RMS and, for object views, the covariance and sigmas (the budget's).
std::vector<ViewRecord> ViewRecords(const JointSolution& s) {
  const ba::BaResult& r = s.result;
  std::vector<ViewRecord> views;
  for (size_t v = 0; v < s.ba_problem.views.size(); ++v) {
    const ba::BaView& bv = s.ba_problem.views[v];
    ViewRecord rec;
    rec.id = bv.id;
    rec.plate = bv.kind == ba::ViewKind::kPlate;
    rec.group = s.ba_problem.groups[bv.group].name;
    rec.pose = r.ViewPose(static_cast<int>(v));
    rec.rms_px = r.views[v].rms_px;
    rec.num_observations = r.views[v].num_observations;
    if (bv.rig < 0) rec.initial = bv.initial;  // a rig view's is its rig's
    rec.initial_rms_px = r.initial_view_rms_px.at(v);
    if (!rec.plate) {
      rec.covariance = r.ViewPoseCovariance(static_cast<int>(v));
      for (int a = 0; a < 3; ++a) {
        const int iv = static_cast<int>(v);
        rec.sigma_rotation_deg[a] =
            ba::FindBudgetRow(s.budget, ba::QuantityKey::ViewRotation(iv, a))->sigma;
        rec.sigma_translation_mm[a] =
            ba::FindBudgetRow(s.budget, ba::QuantityKey::ViewTranslation(iv, a))->sigma;
      }
    }
    views.push_back(rec);
  }
  return views;
}

// The validation pairs' relative rotations and view-direction angles with their sigmas.
std::vector<PairRecord> PairRecords(const Problem& problem, const JointSolution& s) {
  std::vector<PairRecord> pairs;
  for (size_t k = 0; k < problem.validation.size(); ++k) {
    const auto& vp = problem.validation[k];
    const auto [ia, ib] = s.pairs[k];
    const ba::BudgetRow* rr =
        ba::FindBudgetRow(s.budget, ba::QuantityKey::PairRelativeRotation(ia, ib));
    const ba::BudgetRow* vd =
        ba::FindBudgetRow(s.budget, ba::QuantityKey::PairViewDirections(ia, ib));
    PairRecord rec;
    rec.a = vp.a, rec.b = vp.b, rec.expected_deg = vp.expected_deg;
    rec.relative_rotation_deg = rr->quantity.value;
    rec.sigma_relative_rotation_deg = rr->sigma;
    rec.angle_view_dirs_deg = vd->quantity.value;
    rec.sigma_view_dirs_deg = vd->sigma;
    pairs.push_back(rec);
  }
  return pairs;
}

nlohmann::json TwoStepComparisonJson(const JointSolution& s) {
  nlohmann::json cmp = nlohmann::json::array();
  for (const auto& c : s.comparison) {
    nlohmann::json cj;
    cj["method"] = c.method;
    nlohmann::json pv = nlohmann::json::array();
    for (size_t k = 0; k < c.sigma_rotation_deg.size(); ++k) {
      pv.push_back({{"sigma_rotation_deg", JsonVector(c.sigma_rotation_deg[k])},
                    {"sigma_translation_mm", JsonVector(c.sigma_translation_mm[k])}});
    }
    cj["object_views"] = pv;
    cj["sigma_relative_rotation_deg"] = c.sigma_relative_rotation_deg;
    cj["relative_rotation_deg"] = c.relative_rotation_deg;
    cmp.push_back(cj);
  }
  return cmp;
}

}  // namespace

nlohmann::json JointSolutionToJson(const Problem& problem,
                                   const SolverConfig& config,
                                   const JointSolution& s) {
  const ba::StateLayout& L = *s.result.layout;
  ResultContent c;
  c.problem = {{"name", problem.name},
               {"file", problem.path},
               {"kind", "joint"},
               {"plate_views", problem.plate.views.size()},
               {"object_views", problem.object_views.size()},
               {"plate_sigma_px", problem.plate_sigma_px},
               {"object_sigma_px", problem.object_sigma_px},
               {"intrinsics_model", IntrinsicsModelName(problem)},
               {"initial_intrinsics_from", s.initial_intrinsics_from}};
  c.engine_problem = &s.ba_problem;
  c.engine_result = &s.result;
  c.config_name = config.name;
  c.views = ViewRecords(s);
  c.validation = PairRecords(problem, s);
  c.error_budget = s.budget;
  c.warnings = JointWarnings(s);
  c.relative_poses = s.relative_poses;
  c.tre = s.tre;
  nlohmann::json& k = c.kind_sections;
  if (s.ba_problem.groups.size() == 1) {
    k["intrinsics"] = GroupJson(s, 0);
  } else {
    nlohmann::json a = nlohmann::json::array();
    for (size_t g = 0; g < s.ba_problem.groups.size(); ++g)
      a.push_back(GroupJson(s, static_cast<int>(g)));
    k["intrinsics"] = a;
  }
  nlohmann::json layout = nlohmann::json::array();
  for (int i = 0; i < L.num_free(); ++i) layout.push_back(L.FreeName(i));
  k["state_layout"] = layout;
  k["two_step_comparison"] = TwoStepComparisonJson(s);
  if (!s.comparison_error.empty()) k["two_step_comparison_error"] = s.comparison_error;
  if (s.distortion || !s.distortion_error.empty()) {
    k["distortion_selection"] =
        DistortionSelectionJson(s.distortion ? &*s.distortion : nullptr, s.distortion_error,
                                config.distortion_auto);
  }
  nlohmann::json j = ResultJson(c, problem.truth);
  AddFlexJson(problem, s, &j);  // the flex model's keys in the views and beside them
  return j;
}

std::vector<std::string> JointWarnings(const JointSolution& s) {
  std::vector<std::string> out;
  const ba::BaProblem& bp = s.ba_problem;
  for (size_t g = 0; g < bp.groups.size(); ++g) {
    std::string label = bp.groups.size() > 1 ? bp.groups[g].name : "";
    Eigen::MatrixXd cov;
    if (bp.groups[g].smooth) {
      // A smooth group's block holds coefficients (the 1 and cos p terms of one intrinsic always
      // correlate): the intrinsics themselves at the group's view nearest to (0, 0) instead.
      int nearest = -1;
      double best = 0;
      for (size_t v = 0; v < bp.views.size(); ++v) {
        if (bp.views[v].group != static_cast<int>(g)) continue;
        const double d = std::hypot(bp.views[v].primary_deg, bp.views[v].secondary_deg);
        if (nearest < 0 || d < best) nearest = static_cast<int>(v), best = d;
      }
      if (nearest < 0) continue;
      cov = ba::IntrinsicsOfView(bp, s.result, nearest).covariance;
      label = (label.empty() ? "" : label + ", ") + "smooth model at primary " +
              Fmt("%g", bp.views[nearest].primary_deg) + " deg, secondary " +
              Fmt("%g", bp.views[nearest].secondary_deg) + " deg";
    } else {
      cov = s.result.GroupIntrinsicsCovariance(static_cast<int>(g));
    }
    const auto w = IntrinsicsCorrelationWarnings(cov, label);
    out.insert(out.end(), w.begin(), w.end());
  }
  for (auto& w : ba::SolveWarnings(s.result)) out.push_back(std::move(w));
  for (auto& w : analysis::CalibratedRangeWarnings(bp, s.result)) out.push_back(std::move(w));
  if (!s.model_note.empty()) out.push_back(s.model_note);
  if (!s.distortion_warning.empty()) out.push_back(s.distortion_warning);
  return out;
}

namespace {

// The title and what was solved how.
void JointIntroDoc(const Problem& problem, const SolverConfig& config, ReportDoc* doc) {
  ReportDoc& d = *doc;
  d.Heading(1, "Joint bundle adjustment: " + problem.name);
  if (!problem.description.empty()) d.Paragraph(problem.description);
  d.Paragraph(
      "Calibration and pose as one bundle adjustment (src/ba): " +
      std::to_string(problem.plate.views.size()) + " plate views (sigma " +
      Fmt("%g", problem.plate_sigma_px) + " px), " + std::to_string(problem.object_views.size()) +
      " object views (sigma " + Fmt("%g", problem.object_sigma_px) + " px), " +
      std::to_string(problem.fiducials.size()) + " CT fiducials as priors. Config `" + config.name +
      "`; uncertainties: " + CovarianceScaleNote(config.covariance_scale) + ".");
  if (!problem.skipped_images.empty()) {
    d.Paragraph("Plate images without a usable grid (" +
                std::to_string(problem.skipped_images.size()) + "):");
    d.List(problem.skipped_images);
  }
}

// The fit: RMS, chi-square, the solver; the variance components and the shadow correction.
void JointStatisticsDoc(const JointSolution& s, ReportDoc* doc) {
  ReportDoc& d = *doc;
  const ba::BaResult& r = s.result;
  d.Heading(2, "Statistics");
  d.Table({"", ""},
          {{"RMS plate views (px per coordinate)", Fmt("%.4f", r.rms_plate_px)},
           {"RMS object views (px per coordinate)", Fmt("%.4f", r.rms_object_px)},
           {"chi-square / dof",
            Fmt("%.2f", r.chi2) + " / " + std::to_string(r.dof) +
                " (P = " + Fmt("%.3f", r.chi2_p_value) + ", sigma0 " + Fmt("%.3f", r.sigma0) + ")"},
           {"iterations, termination", std::to_string(r.iterations) + ", " + r.TerminationText()},
           {"time", Fmt("%.1f", r.time_s * 1e3) + " ms"}});
  if (!r.converged()) d.Warning("the solve did not converge (" + r.TerminationText() + ").");
  d.Figures({"residuals-per-view", "residual-field"});
  d.Append(VarianceComponentsDoc(r));
  d.Append(ShadowCorrectionDoc(r));

}

// The intrinsics of each group (not smooth: FlexReportDoc) against the truth when known.
void JointIntrinsicsDoc(const Problem& problem, const JointSolution& s, ReportDoc* doc) {
  ReportDoc& d = *doc;
  const ba::BaResult& r = s.result;
  d.Heading(2, "Intrinsics");
  std::vector<std::string> header = {"group", "parameter", "value", "sigma"};
  if (problem.truth.camera) {
    header.push_back("truth");
    header.push_back("error / sigma");
  }
  std::vector<std::vector<std::string>> rows;
  for (size_t g = 0; g < s.ba_problem.groups.size(); ++g) {
    if (s.ba_problem.groups[g].smooth) continue;  // FlexReportDoc
    const Eigen::MatrixXd C = r.GroupIntrinsicsCovariance(static_cast<int>(g));
    const std::array<double, kNumIntrinsics> K = r.GroupIntrinsics(static_cast<int>(g));
    for (int i = 0; i < kNumIntrinsics; ++i) {
      const double x = K[i], sg = std::sqrt(std::max(0.0, C(i, i)));
      std::vector<std::string> row = {s.ba_problem.groups[g].name, kIntrinsicNames[i],
                                      Fmt("%.6g", x), sg > 0 ? Fmt("%.3g", sg) : "held"};
      if (problem.truth.camera) {
        const double t = problem.truth.camera->params[i];
        row.push_back(Fmt("%.6g", t));
        row.push_back(sg > 0 ? Fmt("%.2f", (x - t) / sg) : "");
      }
      rows.push_back(row);
    }
  }
  d.Table(header, rows);
}

// What the sigmas are and the warnings.
void JointSigmaWarningsDoc(const SolverConfig& config, const JointSolution& s, ReportDoc* doc) {
  ReportDoc& d = *doc;
  const auto warnings = JointWarnings(s);
  const std::string used = "Sigmas: " + CovarianceScaleNote(config.covariance_scale) + ".";
  if (warnings.empty()) {
    d.Paragraph(used + " No two intrinsics correlate beyond " +
                Fmt("%.2f", kIntrinsicsCorrelationWarn) + ".");
  } else {
    d.Paragraph(used);
    for (const auto& w : warnings) d.Warning(w);
  }
}

// The validation pairs against their expected angles and the truth.
void JointValidationDoc(const Problem& problem,
                        const JointSolution& s,
                        const std::string& sigma_note,
                        ReportDoc* doc) {
  ReportDoc& d = *doc;
  d.Heading(2, "Validation pairs (object views)");
  d.Paragraph(sigma_note);
  const bool truth_poses = !problem.truth.object_poses.empty();
  std::vector<std::string> header = {"a", "b", "expected (deg)", "relative rotation (deg)", "sigma",
                                     "view directions (deg)", "sigma"};
  if (truth_poses) {
    header.push_back("true relative rotation");
    header.push_back("error / sigma");
  }
  std::vector<std::vector<std::string>> rows;
  for (size_t k = 0; k < problem.validation.size(); ++k) {
    const auto& vp = problem.validation[k];
    const auto [ia, ib] = s.pairs[k];
    const ba::BudgetRow* rr =
        ba::FindBudgetRow(s.budget, ba::QuantityKey::PairRelativeRotation(ia, ib));
    const ba::BudgetRow* vd =
        ba::FindBudgetRow(s.budget, ba::QuantityKey::PairViewDirections(ia, ib));
    std::vector<std::string> row = {vp.a,
                                    vp.b,
                                    vp.expected_deg ? Fmt("%g", *vp.expected_deg) : "",
                                    Fmt("%.3f", rr->quantity.value),
                                    Fmt("%.3f", rr->sigma),
                                    Fmt("%.3f", vd->quantity.value),
                                    Fmt("%.3f", vd->sigma)};
    auto ta = problem.truth.object_poses.find(vp.a), tb = problem.truth.object_poses.find(vp.b);
    if (truth_poses) {
      if (ta != problem.truth.object_poses.end() && tb != problem.truth.object_poses.end()) {
        const double t = RelativeRotationAngle(ta->second.data(), tb->second.data()) * kRadToDeg;
        row.push_back(Fmt("%.3f", t));
        row.push_back(Fmt("%.2f", (rr->quantity.value - t) / rr->sigma));
      } else {
        row.push_back("");
        row.push_back("");
      }
    }
    rows.push_back(row);
  }
  d.Table(header, rows);
}

// The joint sigmas against the two-step ones.
void JointTwoStepDoc(const Problem& problem, const JointSolution& s, ReportDoc* doc) {
  ReportDoc& d = *doc;
  d.Heading(2, "Joint against two-step");
  if (!s.comparison_error.empty()) {
    d.Paragraph("Not shown: " + s.comparison_error + ".");
  } else {
    d.Paragraph(
        "Sigma of each validation pair's relative rotation (deg) and the mean rotation / "
        "translation sigma of the object poses. Two-step with the intrinsics held leaves the "
        "calibration's uncertainty out (its sigmas are too small); with the calibration's "
        "covariance as a prior it equals the joint result to first order.");
    std::vector<std::string> header = {"method"};
    for (const auto& vp : problem.validation) header.push_back(vp.a + "-" + vp.b);
    header.push_back("mean rotation sigma (deg)");
    header.push_back("mean translation sigma (mm)");
    std::vector<std::vector<std::string>> rows;
    for (const auto& c : s.comparison) {
      std::vector<std::string> cells = {c.method};
      for (double x : c.sigma_relative_rotation_deg) cells.push_back(Fmt("%.4f", x));
      double mr = 0, mt = 0;
      for (size_t k = 0; k < c.sigma_rotation_deg.size(); ++k) {
        mr += c.sigma_rotation_deg[k].norm() / std::sqrt(3.0);
        mt += c.sigma_translation_mm[k].norm() / std::sqrt(3.0);
      }
      const double n = std::max<size_t>(1, c.sigma_rotation_deg.size());
      cells.push_back(Fmt("%.4f", mr / n));
      cells.push_back(Fmt("%.4f", mt / n));
      rows.push_back(cells);
    }
    d.Table(header, rows);
  }
}

// Outliers and rejected observations.
void JointOutliersDoc(const SolverConfig& config, const JointSolution& s, ReportDoc* doc) {
  ReportDoc& d = *doc;
  const ba::BaResult& r = s.result;
  d.Heading(2, "Outliers");
  if (r.outliers.empty()) {
    d.Paragraph("None above " + Fmt("%g", config.outlier_sigma) + " sigma.");
  } else {
    std::vector<std::vector<std::string>> rows;
    for (const auto& out : r.outliers) {
      rows.push_back({out.view, (out.plate ? "point " : "marker ") + std::to_string(out.id),
                      Fmt("%.1f", out.residual_sigma), Fmt("%.3f", out.du_px),
                      Fmt("%.3f", out.dv_px)});
    }
    d.Table({"view", "point / marker", "residual (sigma)", "du (px)", "dv (px)"}, rows);
  }
  if (!r.rejected.empty()) {
    std::string text = "Rejected (reject_sigma " + Fmt("%g", config.reject_sigma) +
                       ", solved again without them):";
    for (const auto& out : r.rejected) {
      text += " " + out.view + "/" + (out.plate ? "point " : "marker ") + std::to_string(out.id) +
              " (" + Fmt("%.1f", out.residual_sigma) + " sigma);";
    }
    d.Paragraph(text);
  }
}

}  // namespace

ReportDoc JointReportDoc(const Problem& problem,
                         const SolverConfig& config,
                         const JointSolution& s) {
  ReportDoc d;
  JointIntroDoc(problem, config, &d);
  JointStatisticsDoc(s, &d);
  JointIntrinsicsDoc(problem, s, &d);
  d.Figures({"distortion", "projection-uncertainty"});
  d.Append(FlexReportDoc(problem, s));  // C-arm flex: intrinsics per view, model selection
  d.Append(DistortionSelectionDoc(s.distortion ? &*s.distortion : nullptr, s.distortion_error,
                                   config.distortion_auto, s.distortion_warning));
  JointSigmaWarningsDoc(config, s, &d);
  const std::string sigma_note = "Sigmas: " + CovarianceScaleNote(config.covariance_scale) + ".";
  JointValidationDoc(problem, s, sigma_note, &d);
  d.Figures({"poses", "markers"});
  AppendRelativePoses(&d, s.ba_problem, s.relative_poses, problem.truth.object_poses);
  if (s.tre) AppendTre(&d, *s.tre);
  d.Append(ErrorBudgetDoc(s.budget, sigma_note));
  JointTwoStepDoc(problem, s, &d);
  JointOutliersDoc(config, s, &d);
  return d;
}

nlohmann::json JointPlotData(const JointSolution& s) {
  nlohmann::json d = BaPlotData(s.ba_problem, s.result, &s.budget);
  d["kind"] = "joint";
  return d;
}

ReportDoc JointMrcalDoc(const nlohmann::json& c) {
  ReportDoc d;
  d.Heading(2, "Cross-check with mrcal");
  if (c.contains("error")) {
    d.Paragraph("Not run: " + c.at("error").get<std::string>() + ".");
    return d;
  }
  d.Paragraph("The same plate and marker observations solved by carmba's engine and by mrcal " +
              c.at("mrcal").value("mrcal_version", std::string("2.2")) + "'s `mrcal.optimize` (" +
              c.at("what").get<std::string>() +
              "; mrcal cannot tie points to priors, and its optimizer frees all nine intrinsics, "
              "so held intrinsics are solved with carmba's free set on mrcal's own residuals and "
              "Jacobian: the same model on both sides, a variant of the solve above).");
  std::vector<std::vector<std::string>> rows;
  auto row = [&](const std::string& who, const nlohmann::json& x, double rms) {
    std::vector<std::string> cells = {who};
    for (const auto& v : x) cells.push_back(Fmt("%.8g", v.get<double>()));
    cells.push_back(Fmt("%.8g", rms));
    rows.push_back(cells);
  };
  row("carmba", c.at("carmba").at("intrinsics"), c.at("rms_px_carmba_in_mrcal").get<double>());
  row("mrcal", c.at("mrcal").at("intrinsics"), c.at("rms_px_mrcal").get<double>());
  std::vector<std::string> diff = {"relative difference"};
  for (int i = 0; i < kNumIntrinsics; ++i) {
    diff.push_back(Fmt("%.1e", c.at("relative_difference").at(kIntrinsicNames[i]).get<double>()));
  }
  diff.push_back(Fmt("%.1e", std::abs(c.at("rms_px_mrcal").get<double>() /
                                          c.at("rms_px_carmba_in_mrcal").get<double>() -
                                      1)));
  rows.push_back(diff);
  d.Table({"", "fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3",
           "RMS (mrcal's definition, px)"},
          rows);
  d.Paragraph("Largest difference: " +
              Fmt("%.2e", c.at("max_relative_difference_fx_fy_cx_cy").get<double>()) +
              " relative in fx, fy, cx, cy; " +
              Fmt("%.2e", c.at("max_difference_in_sigmas").get<double>()) +
              " sigma over all nine intrinsics.");
  if (c.contains("max_move_in_sigmas_of_mrcal_seeded_at_carmba")) {
    const double rms_m = c.at("rms_px_mrcal").get<double>();
    const double rms_c = c.at("rms_px_carmba_in_mrcal").get<double>();
    std::string cost;
    if (rms_c < rms_m) {
      cost =
          "mrcal's own solve from the initial values stops slightly short of it (carmba's solution "
          "has the lower cost in mrcal's own residuals, by " +
          Fmt("%.1e", rms_m - rms_c) + " px RMS)";
    } else if (rms_c > rms_m) {
      cost = "mrcal's own solve from the initial values ends at a cost lower than carmba's by " +
             Fmt("%.1e", rms_c - rms_m) + " px RMS (" + Fmt("%.1e", (rms_c - rms_m) / rms_m) +
             " relative): both stop where the cost no longer changes";
    } else {
      cost = "mrcal's own solve from the initial values ends at the same cost";
    }
    d.Paragraph(
        "mrcal seeded at carmba's optimum stays there: it moves the nine intrinsics by at most " +
        Fmt("%.1e", c.at("max_move_in_sigmas_of_mrcal_seeded_at_carmba").get<double>()) +
        " sigma (" +
        Fmt("%.1e", c.at("max_relative_move_of_mrcal_seeded_at_carmba").get<double>()) +
        " relative, largest in the weakly determined terms). " + cost +
        "; the distortion terms' differences above are that stopping tolerance.");
  }
  return d;
}

}  // namespace carmba
