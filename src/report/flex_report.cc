// C-arm flex in result.json and the report (report/joint_report.h): per-view intrinsics, the smooth
// model's coefficients, the model selection, the plot's data.
#include <algorithm>
#include <cmath>
#include <limits>

#include "ba/view_intrinsics.h"
#include "report/joint_report.h"
#include "util/format.h"

namespace carmba {
namespace {

bool AnyAngles(const JointSolution& s) {
  for (const auto& v : s.ba_problem.views) {
    if (v.has_angles) return true;
  }
  return false;
}

Camera ToCamera(const ba::ViewIntrinsics& vi, const ba::IntrinsicsGroup& g) {
  Camera c;
  c.params = vi.value;
  c.width = g.width;
  c.height = g.height;
  c.covariance_names.assign(kIntrinsicNames, kIntrinsicNames + kNumIntrinsics);
  c.covariance.assign(kNumIntrinsics, std::vector<double>(kNumIntrinsics));
  for (int i = 0; i < kNumIntrinsics; ++i) {
    for (int k = 0; k < kNumIntrinsics; ++k) c.covariance[i][k] = vi.covariance(i, k);
  }
  return c;
}

}  // namespace

nlohmann::json FlexModelJson(const JointSolution& s) {
  const ba::IntrinsicsGroup& g = s.ba_problem.groups[0];
  const int b = s.result.layout->group_block(0);
  const Eigen::MatrixXd C = s.result.Covariance({b});
  nlohmann::json names = nlohmann::json::array(), values = nlohmann::json::array(),
                 sigmas = nlohmann::json::array(), cov = nlohmann::json::array(),
                 terms = nlohmann::json::array();
  for (int k = 0; k < g.basis.NumTerms(); ++k) terms.push_back(g.basis.TermName(k));
  for (int i = 0; i < g.basis.BlockSize(); ++i) {
    names.push_back(g.basis.ParameterName(i));
    values.push_back(JsonNumber(s.result.block(b)[i]));
    sigmas.push_back(JsonNumber(std::sqrt(std::max(0.0, C(i, i)))));
    nlohmann::json row = nlohmann::json::array();
    for (int k = 0; k < g.basis.BlockSize(); ++k) row.push_back(JsonNumber(C(i, k)));
    cov.push_back(row);
  }
  return {{"model", "smooth"},
          {"group", g.name},
          {"basis",
           {{"primary_order", g.basis.primary_order},
            {"secondary_degree", g.basis.secondary_degree},
            {"terms", terms},
            {"definition",
             "fx = sum_k fx_k phi_k(p, sec) (likewise fy, cx, cy); phi = [1, cos p, sin p, .., "
             "sec, sec^2, ..], p = primary, sec = secondary angle in radians; distortion shared"}}},
          {"names", names},
          {"values", values},
          {"sigmas", sigmas},
          {"covariance", cov},
          {"image_size", {g.width, g.height}}};
}

void AddFlexJson(const Problem& problem, const JointSolution& s, nlohmann::json* j) {
  const ba::BaProblem& bp = s.ba_problem;
  for (size_t v = 0; v < bp.views.size(); ++v) {
    nlohmann::json& vj = (*j)["views"][v];
    const ba::BaView& bv = bp.views[v];
    const ba::ViewIntrinsics vi = ba::IntrinsicsOfView(bp, s.result, static_cast<int>(v));
    vj["intrinsics"] = CameraToJson(ToCamera(vi, bp.groups[bv.group]));
    if (bv.has_angles) {
      vj["primary_deg"] = bv.primary_deg;
      vj["secondary_deg"] = bv.secondary_deg;
    }
    auto t = problem.truth.view_intrinsics.find(bv.id);
    if (t != problem.truth.view_intrinsics.end()) {
      nlohmann::json z;
      for (int i = 0; i < 4; ++i) {
        const double sg = std::sqrt(std::max(0.0, vi.covariance(i, i)));
        z[kIntrinsicNames[i]] = JsonNumber(sg > 0 ? (vi.value[i] - t->second[i]) / sg : NAN);
      }
      vj["true_intrinsics"] = std::vector<double>(t->second.begin(), t->second.end());
      vj["intrinsics_error_sigma"] = z;
    }
  }
  nlohmann::json model = {{"name", IntrinsicsModelName(problem)}};
  if (problem.smooth) model["coefficients"] = FlexModelJson(s);
  (*j)["intrinsics_model"] = model;
  if (s.selection) {
    nlohmann::json scores = nlohmann::json::array();
    for (const auto& sc : s.selection->scores) {
      nlohmann::json held = nlohmann::json::array();
      for (const auto& h : sc.held_out) {
        held.push_back({{"orientation", h.orientation},
                        {"rms_px", JsonNumber(h.rms_px)},
                        {"chi2_per_residual", JsonNumber(h.chi2_per_residual)},
                        {"mahalanobis_d2", JsonNumber(h.d2)}});
      }
      nlohmann::json sj = {{"model", analysis::IntrinsicsModelName(sc.model)}, {"ok", sc.ok}};
      if (!sc.ok) sj["error"] = sc.error;
      sj["num_parameters"] = sc.num_free;
      sj["num_residuals"] = sc.num_residuals;
      sj["chi2"] = JsonNumber(sc.chi2);
      sj["aic"] = JsonNumber(sc.aic);
      sj["bic"] = JsonNumber(sc.bic);
      sj["held_out_rms_px"] = JsonNumber(sc.held_out_rms_px);
      sj["held_out_mahalanobis_d2_mean"] = JsonNumber(sc.held_out_d2_mean);
      sj["held_out"] = held;
      scores.push_back(sj);
    }
    (*j)["model_selection"] = {
        {"recommended", analysis::IntrinsicsModelName(s.selection->recommended)},
        {"why", s.selection->why},
        {"used", IntrinsicsModelName(problem)},
        {"scores", scores}};
  } else if (!s.selection_error.empty()) {
    (*j)["model_selection"] = {{"error", s.selection_error}};
  }
  // The intrinsics along the primary angle at each plate secondary angle (smooth or shared).
  if (AnyAngles(s) && bp.groups.size() == 1) {
    double lo = 1e9, hi = -1e9;
    std::vector<double> secondaries;
    for (const auto& v : bp.views) {
      if (!v.has_angles) continue;
      lo = std::min(lo, v.primary_deg);
      hi = std::max(hi, v.primary_deg);
      if (v.kind == ba::ViewKind::kPlate &&
          std::find(secondaries.begin(), secondaries.end(), v.secondary_deg) == secondaries.end()) {
        secondaries.push_back(v.secondary_deg);
      }
    }
    nlohmann::json curves = nlohmann::json::array();
    for (double sec : secondaries) {
      nlohmann::json pts = nlohmann::json::array();
      const int n = 73;
      for (int k = 0; k < n; ++k) {
        const double a = lo + (hi - lo) * k / (n - 1);
        const ba::ViewIntrinsics vi = ba::GroupIntrinsicsAt(bp, s.result, 0, a, sec);
        nlohmann::json x = nlohmann::json::array(), sg = nlohmann::json::array();
        for (int i = 0; i < 4; ++i) {
          x.push_back(JsonNumber(vi.value[i]));
          sg.push_back(JsonNumber(std::sqrt(std::max(0.0, vi.covariance(i, i)))));
        }
        pts.push_back({{"primary_deg", a}, {"fx_fy_cx_cy", x}, {"sigma", sg}});
      }
      curves.push_back({{"secondary_deg", sec}, {"points", pts}});
    }
    (*j)["intrinsics_curve"] = curves;
  }
}

ReportDoc FlexReportDoc(const Problem& problem, const JointSolution& s) {
  ReportDoc d;
  if (!AnyAngles(s) && !problem.smooth) return d;
  const ba::BaProblem& bp = s.ba_problem;
  d.Heading(2, "Intrinsics per view (C-arm angles)");
  std::string text = std::string("Model `") + IntrinsicsModelName(problem) + "`";
  if (problem.smooth) {
    text +=
        ": fx, fy, cx, cy as functions of the angles (Fourier order " +
        std::to_string(s.smooth_basis.primary_order) + " in the primary angle, degree " +
        std::to_string(s.smooth_basis.secondary_degree) +
        " in the secondary), distortion shared; a view's intrinsics and their sigma follow from "
        "the coefficients' covariance, also between the calibrated angles";
  }
  d.Paragraph(text + ". Values +- 1 sigma (px); the plot of the intrinsics against the primary "
                     "angle is in report.html.");
  d.Figures({"intrinsics-vs-angle"});
  const bool truth = !problem.truth.view_intrinsics.empty();
  std::vector<std::string> header = {"view", "kind", "primary (deg)", "secondary (deg)",
                                     "fx", "fy", "cx", "cy"};
  if (truth) header.push_back("max abs(error) / sigma");
  std::vector<std::vector<std::string>> rows;
  for (size_t v = 0; v < bp.views.size(); ++v) {
    const ba::BaView& bv = bp.views[v];
    const ba::ViewIntrinsics vi = ba::IntrinsicsOfView(bp, s.result, static_cast<int>(v));
    std::vector<std::string> row = {bv.id, bv.kind == ba::ViewKind::kPlate ? "plate" : "object",
                                    bv.has_angles ? Fmt("%.1f", bv.primary_deg) : "",
                                    bv.has_angles ? Fmt("%.1f", bv.secondary_deg) : ""};
    double worst = 0;
    auto t = problem.truth.view_intrinsics.find(bv.id);
    for (int i = 0; i < 4; ++i) {
      const double sg = std::sqrt(std::max(0.0, vi.covariance(i, i)));
      row.push_back(Fmt("%.2f", vi.value[i]) + " +- " + Fmt("%.2f", sg));
      if (t != problem.truth.view_intrinsics.end() && sg > 0) {
        worst = std::max(worst, std::abs(vi.value[i] - t->second[i]) / sg);
      }
    }
    if (truth) row.push_back(t != problem.truth.view_intrinsics.end() ? Fmt("%.2f", worst) : "");
    rows.push_back(row);
  }
  d.Table(header, rows);
  if (problem.smooth) {
    const nlohmann::json m = FlexModelJson(s);
    d.Paragraph("Coefficients (angles in radians):");
    rows.clear();
    for (size_t i = 0; i < m["names"].size(); ++i) {
      const auto num = [](const nlohmann::json& x) {
        return x.is_number() ? x.get<double>() : std::numeric_limits<double>::quiet_NaN();
      };
      rows.push_back({m["names"][i].get<std::string>(), Fmt("%.6g", num(m["values"][i])),
                      Fmt("%.3g", num(m["sigmas"][i]))});
    }
    d.Table({"coefficient", "value", "sigma"}, rows);
  }
  d.Heading(2, "Intrinsics model selection");
  if (!s.selection) {
    d.Paragraph(s.selection_error.empty()
                    ? "Not run (it needs C-arm angles for every view; intrinsics.select)."
                    : "Not available: " + s.selection_error + ".");
    return d;
  }
  d.Paragraph(
      "Each plate orientation group is left out in turn; the model fitted to the other groups' "
      "plate views predicts its intrinsics and its plate observations (poses refitted, "
      "intrinsics held at the prediction). `d2` is the Mahalanobis distance of the predicted fx, "
      "fy, cx, cy from the group's own calibration with both covariances (4 on average when the "
      "model is right); the held-out RMS is in px per coordinate (a pose absorbs most of an "
      "intrinsics error, so it moves little). AIC = chi2 + 2k, BIC = chi2 + k ln n on all plate "
      "views.");
  rows.clear();
  for (const auto& sc : s.selection->scores) {
    if (!sc.ok) {
      rows.push_back(
          {analysis::IntrinsicsModelName(sc.model), "failed: " + sc.error, "", "", "", "", ""});
      continue;
    }
    rows.push_back({analysis::IntrinsicsModelName(sc.model), std::to_string(sc.num_free),
                    Fmt("%.1f", sc.chi2), Fmt("%.1f", sc.aic), Fmt("%.1f", sc.bic),
                    Fmt("%.4f", sc.held_out_rms_px), Fmt("%.2f", sc.held_out_d2_mean)});
  }
  d.Table({"model", "parameters", "chi2", "AIC", "BIC", "held-out RMS (px)", "mean held-out d2"},
          rows);
  d.Paragraph("Held-out d2 per orientation group:");
  const auto& first = s.selection->scores.front();
  header = {"model"};
  for (const auto& h : first.held_out) header.push_back(h.orientation);
  rows.clear();
  for (const auto& sc : s.selection->scores) {
    if (!sc.ok) continue;
    std::vector<std::string> row = {analysis::IntrinsicsModelName(sc.model)};
    for (const auto& h : sc.held_out) row.push_back(Fmt("%.2f", h.d2));
    row.resize(header.size());
    rows.push_back(row);
  }
  d.Table(header, rows);
  std::string rec = std::string("**Recommended: `") +
                    analysis::IntrinsicsModelName(s.selection->recommended) + "`** -- " +
                    s.selection->why + ".";
  if (std::string(analysis::IntrinsicsModelName(s.selection->recommended)) !=
      IntrinsicsModelName(problem)) {
    rec += std::string(" This solve used `") + IntrinsicsModelName(problem) +
           "` (intrinsics.model in the problem).";
  }
  d.Paragraph(rec);
  return d;
}

void AddFlexPlotData(const nlohmann::json& result, nlohmann::json* plot_data) {
  if (!result.contains("intrinsics_model") || !result.contains("views")) return;
  nlohmann::json views = nlohmann::json::array();
  for (const auto& v : result.at("views")) {
    if (!v.contains("primary_deg") || !v.contains("intrinsics")) continue;
    nlohmann::json pv = {{"id", v.value("id", std::string())},
                         {"kind", v.value("kind", std::string())},
                         {"primary_deg", v.at("primary_deg")},
                         {"secondary_deg", v.at("secondary_deg")},
                         {"intrinsics", v.at("intrinsics")}};
    if (v.contains("true_intrinsics")) pv["true_intrinsics"] = v.at("true_intrinsics");
    views.push_back(pv);
  }
  if (views.empty()) return;
  (*plot_data)["intrinsics_vs_angle"] = {
      {"model", result.at("intrinsics_model").value("name", std::string("?"))},
      {"views", views},
      {"curves", result.value("intrinsics_curve", nlohmann::json::array())}};
}

}  // namespace carmba
