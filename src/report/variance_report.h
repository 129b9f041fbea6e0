// The variance components of a solve (ba/variance_components.h) in result.json and in the
// report: one writer for every problem kind.
#pragma once

#include <nlohmann/json.hpp>

#include "ba/bundle_adjuster.h"
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

}  // namespace carmba
