#include "report/lens_report.h"

#include <cmath>

#include "util/format.h"

namespace carmba {

nlohmann::json DistortionSelectionJson(const analysis::DistortionSelection* selection,
                                       const std::string& error, bool applied) {
  if (!selection) return {{"error", error}};
  const analysis::DistortionSelection& d = *selection;
  nlohmann::json scores = nlohmann::json::array();
  for (const auto& sc : d.scores) {
    nlohmann::json o = {{"model", analysis::DistortionModelName(sc.model)}, {"ok", sc.ok}};
    if (!sc.ok) {
      o["error"] = sc.error;
    } else {
      o.update({{"num_free", sc.num_free},
                {"num_residuals", sc.num_residuals},
                {"chi2", JsonNumber(sc.chi2)},
                {"aic", JsonNumber(sc.aic)},
                {"bic", JsonNumber(sc.bic)},
                {"held_out_chi2_per_residual", JsonNumber(sc.held_out_chi2_per_residual)},
                {"held_out_rms_px", JsonNumber(sc.held_out_rms_px)},
                {"cx", JsonNumber(sc.principal_point[0])},
                {"cy", JsonNumber(sc.principal_point[1])},
                {"sigma_cx", JsonNumber(std::sqrt(sc.principal_point_covariance(0, 0)))},
                {"sigma_cy", JsonNumber(std::sqrt(sc.principal_point_covariance(1, 1)))}});
    }
    scores.push_back(o);
  }
  return {{"recommended", analysis::DistortionModelName(d.recommended)},
          {"why", d.why},
          {"folds", d.folds},
          {"applied", applied},
          {"scores", scores}};
}

ReportDoc DistortionSelectionDoc(const analysis::DistortionSelection* selection,
                                 const std::string& error,
                                 bool applied,
                                 const std::string& warning) {
  ReportDoc d;
  if (!selection && error.empty()) return d;
  d.Heading(2, "Distortion model: which terms the plate views support");
  if (!selection) {
    d.Paragraph("Not compared: " + error + ".");
    return d;
  }
  const analysis::DistortionSelection& sel = *selection;
  const std::string sigma =
      sel.sigma_estimated
          ? "; chi-squares at the pixel sigma the full model's residuals give, " +
                Fmt("%.3g", sel.sigma_px) + " px"
          : "";
  d.Paragraph(
      "Each candidate fitted to the plate views alone (AIC = chi-square + 2 x free "
      "parameters" +
      sigma + "), and by " + std::to_string(sel.folds) +
      "-fold held-out plate views (the intrinsics without them, one Gauss-Newton step "
      "from the full fit; their poses refitted with those intrinsics held). Recommended: **" +
      analysis::DistortionModelName(sel.recommended) + "**: " + sel.why + ". " +
      (applied ? "Applied (`distortion: auto`)."
               : "Not applied: the config gives the terms (`distortion: given`)."));
  std::vector<std::vector<std::string>> rows;
  for (const auto& sc : sel.scores) {
    if (!sc.ok) {
      rows.push_back(
          {analysis::DistortionModelName(sc.model), "failed: " + sc.error, "", "", "", "", ""});
      continue;
    }
    rows.push_back({analysis::DistortionModelName(sc.model), Fmt("%.1f", sc.chi2),
                    std::to_string(sc.num_free), Fmt("%.1f", sc.aic), Fmt("%.1f", sc.bic),
                    Fmt("%.4f", sc.held_out_chi2_per_residual) + " (" +
                        Fmt("%.4f", sc.held_out_rms_px) + " px)",
                    Fmt("%.2f", sc.principal_point[0]) + " +- " +
                        Fmt("%.2f", std::sqrt(sc.principal_point_covariance(0, 0))) + ", " +
                        Fmt("%.2f", sc.principal_point[1]) + " +- " +
                        Fmt("%.2f", std::sqrt(sc.principal_point_covariance(1, 1)))});
  }
  d.Table({"model", "chi-square", "free", "AIC", "BIC", "held-out chi-square / residual (RMS)",
           "cx, cy (px)"},
          rows);
  if (!warning.empty()) d.Warning(warning);
  return d;
}

}  // namespace carmba
