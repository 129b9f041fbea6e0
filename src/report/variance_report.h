// The noise model of a solve in result.json and in the report, one writer for every problem
// kind: the variance components (ba/variance_components.h), the error budget (ba/quantities.h)
// and the cone-beam shadow correction (ba/shadow_correction.h).
#pragma once

#include <nlohmann/json.hpp>

#include "ba/bundle_adjuster.h"
#include "ba/quantities.h"
#include "report/report_doc.h"

namespace carmba {

// What the sigmas are, in a few words: "the stated sigmas scaled per observation group by their
// estimated variance factors (covariance.scale: per_group)", ...
std::string CovarianceScaleNote(ba::CovarianceScale scale);

// result.json's "variance_components": {"scale", "iterations", "groups": [{group, name, rows,
// redundancy, chi2_stated, factor, factor_sigma, p_value, estimable, applied, outside_band}]}.
nlohmann::json VarianceComponentsJson(const ba::BaResult& result);

// The report's section: a table per group and what was done with it; the warnings of the
// groups outside their band.
ReportDoc VarianceComponentsDoc(const ba::BaResult& result);

// result.json's "shadow_correction" (ba/shadow_correction.h): {"evaluated", "applied",
// "observations", "max_px", "rms_px", "max_sigma"}; null when no sphere radius was known.
nlohmann::json ShadowCorrectionJson(const ba::BaResult& result);
// The report's paragraph on it (empty when not evaluated).
ReportDoc ShadowCorrectionDoc(const ba::BaResult& result);

// result.json's "error_budget": per quantity {quantity, unit, value, sigma, sources: [{source,
// sigma, share}]}.
nlohmann::json ErrorBudgetJson(const std::vector<ba::BudgetRow>& rows);
// The report's section: each quantity's variance by noise source; `sigma_note` says which sigmas
// the covariance rests on.
ReportDoc ErrorBudgetDoc(const std::vector<ba::BudgetRow>& rows, const std::string& sigma_note);

}  // namespace carmba
