#include "report/variance_report.h"

#include <algorithm>

#include "util/format.h"

namespace carmba {

std::string CovarianceScaleNote(ba::CovarianceScale scale) {
  switch (scale) {
    case ba::CovarianceScale::kPerGroup:
      return "the stated sigmas scaled per observation group by their estimated variance factors "
             "(covariance.scale: per_group)";
    case ba::CovarianceScale::kApriori:
      return "the stated (a-priori) sigmas (covariance.scale: apriori)";
    case ba::CovarianceScale::kGlobal:
      return "the stated sigmas times the a-posteriori factor sigma0 (covariance.scale: global)";
  }
  return "";
}

nlohmann::json VarianceComponentsJson(const ba::BaResult& result) {
  const ba::CovarianceScale scale = result.scale_mode;
  nlohmann::json groups = nlohmann::json::array();
  for (const ba::VarianceComponent& c : result.variance_components) {
    groups.push_back({{"group", ba::NoiseGroupKey(c.group)},
                      {"name", ba::NoiseGroupName(c.group)},
                      {"rows", c.num_rows},
                      {"redundancy", JsonNumber(c.redundancy)},
                      {"chi2_stated", JsonNumber(c.chi2_stated)},
                      {"factor", JsonNumber(c.factor)},
                      {"factor_sigma", JsonNumber(c.factor_sigma)},
                      {"p_value", JsonNumber(c.p_value)},
                      {"estimable", c.estimable},
                      {"applied", c.applied},
                      {"outside_band", c.outside_band}});
  }
  return {{"scale", NameOf(ba::kCovarianceScaleNames, scale)},
          {"iterations", result.variance_iterations},
          {"min_redundancy", ba::kMinVarianceComponentRedundancy},
          {"groups", groups}};
}

namespace {

std::string WhatWasDone(const ba::VarianceComponent& c, ba::CovarianceScale scale) {
  if (c.applied) return "sigmas x " + Fmt("%.3f", c.SigmaScale());
  if (!c.estimable)
    return "stated (redundancy < " + Fmt("%g", ba::kMinVarianceComponentRedundancy) + ")";
  return scale == ba::CovarianceScale::kGlobal ? "global sigma0^2" : "stated (apriori)";
}

}  // namespace

ReportDoc VarianceComponentsDoc(const ba::BaResult& result) {
  const ba::CovarianceScale scale = result.scale_mode;
  ReportDoc d;
  d.Heading(2, "Noise model: variance components per observation group");
  if (result.variance_components.empty()) {
    d.Paragraph("Not estimated (no covariance was computed).");
    return d;
  }
  std::string how;
  switch (scale) {
    case ba::CovarianceScale::kPerGroup:
      how = "`covariance.scale: per_group`: each group whose redundancy is at least " +
            Fmt("%g", ba::kMinVarianceComponentRedundancy) +
            " has its sigmas scaled by the square root of its factor, and the problem is solved "
            "again until the factors settle (" + std::to_string(result.variance_iterations) +
            " re-solves); the estimates, covariances and error budget are those of the rescaled "
            "problem.";
      break;
    case ba::CovarianceScale::kApriori:
      how = "`covariance.scale: apriori`: the covariances use the stated sigmas; the factors "
            "are reported only.";
      break;
    case ba::CovarianceScale::kGlobal:
      how = "`covariance.scale: global`: every covariance is multiplied by sigma0^2 = " +
            Fmt("%.3g", result.covariance_scale) + ".";
      break;
  }
  d.Paragraph(
      "Each group's variance factor f = (its chi-square at the stated sigmas) / (its redundancy, "
      "its share of the degrees of freedom): 1 when the stated sigmas hold, 4 when the true "
      "sigmas are twice the stated ones (Förstner's variance-component estimate). " + how);
  std::vector<std::vector<std::string>> rows;
  for (const ba::VarianceComponent& c : result.variance_components) {
    rows.push_back(
        {ba::NoiseGroupName(c.group),
         std::to_string(c.num_rows),
         Fmt("%.1f", c.redundancy),
         Fmt("%.1f", c.chi2_stated),
         c.redundancy > 0.5 ? Fmt("%.3g", c.factor) + " +- " + Fmt("%.2g", c.factor_sigma) : "-",
         Fmt("%.2g", c.p_value),
         c.outside_band ? "**outside**" : "inside",
         WhatWasDone(c, scale)});
  }
  d.Table({"group", "rows", "redundancy", "chi-square (stated)", "factor", "P", "band 0.5-99.5 %",
           "covariance"},
          rows);
  // The groups outside their band are warnings of the solve (ba::SolveWarnings), listed where
  // the report lists the solve's warnings.
  return d;
}

nlohmann::json ShadowCorrectionJson(const ba::BaResult& result) {
  const ba::ShadowCorrectionSummary& s = result.shadow;
  if (!s.evaluated) return nullptr;
  return {{"evaluated", s.evaluated}, {"applied", s.applied}, {"observations", s.num_observations},
          {"max_px", s.max_px},       {"rms_px", s.rms_px},   {"max_sigma", s.max_sigma}};
}

ReportDoc ShadowCorrectionDoc(const ba::BaResult& result) {
  ReportDoc d;
  const ba::ShadowCorrectionSummary& s = result.shadow;
  if (!s.evaluated) return d;
  d.Heading(3, "Cone-beam shadow centres");
  d.Paragraph(
      "A sphere's shadow in a cone beam is an ellipse centred slightly further from the principal "
      "point than the projection of the sphere's centre (Clackdoyle & Mennessier 2011), and the "
      "lens's curvature over the shadow moves its centre too (outwards under pincushion, inwards "
      "under barrel distortion); the detected centres follow the shadow. At the solution the "
      "offsets of the " +
      std::to_string(s.num_observations) + " sphere observations are at most " +
      Fmt("%.4f", s.max_px) + " px (" + Fmt("%.2f", s.max_sigma) + " sigma), RMS " +
      Fmt("%.4f", s.rms_px) + " px per coordinate: " +
      (s.applied
           ? "subtracted from the observed centres and the problem solved again (every "
             "figure of this report is of the corrected centres)."
           : "below " + Fmt("%g", ba::kShadowCorrectionMinSigma) + " sigma, so not applied."));
  return d;
}

nlohmann::json ErrorBudgetJson(const std::vector<ba::BudgetRow>& rows) {
  nlohmann::json budget = nlohmann::json::array();
  for (const auto& row : rows) {
    nlohmann::json src = nlohmann::json::array();
    for (int k = 0; k < ba::kNumSources; ++k) {
      src.push_back({{"source", ba::SourceName(static_cast<ba::Source>(k))},
                     {"sigma", JsonNumber(row.source_sigma[k])},
                     {"share", JsonNumber(row.share[k])}});
    }
    budget.push_back({{"quantity", row.quantity.name},
                      {"unit", row.quantity.unit},
                      {"value", JsonNumber(row.quantity.value)},
                      {"sigma", JsonNumber(row.sigma)},
                      {"sources", src}});
  }
  return budget;
}

ReportDoc ErrorBudgetDoc(const std::vector<ba::BudgetRow>& budget, const std::string& sigma_note) {
  ReportDoc d;
  d.Heading(2, "Error budget");
  const bool centre = std::any_of(budget.begin(), budget.end(), [](const ba::BudgetRow& row) {
    return row.quantity.key.kind == ba::QuantityKind::kCentreProjection;
  });
  d.Paragraph(
      "Share of each quantity's variance from each independent noise source "
      "(first order: Var(f) = sum_s G H^-1 J_s^T J_s H^-1 G^T; the shares add up to 100 %). "
      "Rotations are small rotations about the camera axes (their value is 0 by definition)" +
      std::string(centre ? "; `centre projection` is where the ray of the image centre, held fixed "
                           "at the object distance, projects with the estimated intrinsics (its "
                           "value is the image centre, its sigma the calibration's own uncertainty "
                           "there). "
                         : ". ") +
      sigma_note);
  std::vector<std::string> header = {"quantity", "unit", "value", "sigma"};
  const std::vector<ba::Source> active = ba::ActiveSources(budget);
  for (ba::Source k : active) header.push_back(ba::SourceName(k));
  std::vector<std::vector<std::string>> rows;
  for (const auto& row : budget) {
    std::vector<std::string> cells = {row.quantity.name, row.quantity.unit,
                                      Fmt("%.6g", row.quantity.value), Fmt("%.3g", row.sigma)};
    for (ba::Source k : active) {
      const double share = row.share[static_cast<int>(k)];
      cells.push_back(share > 0 ? Fmt("%.1f %%", 100 * share) : "-");
    }
    rows.push_back(cells);
  }
  d.Table(header, rows);
  d.Figures({"error-budget"});
  return d;
}

}  // namespace carmba
