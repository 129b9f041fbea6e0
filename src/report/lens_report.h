// The distortion models compared (analysis/lens_models.h) in result.json and in the report, for the
// joint solve and the calibration alike.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "analysis/lens_models.h"
#include "report/report_doc.h"

namespace carmba {

// result.json's "distortion_selection": {recommended, why, folds, applied, scores[]}, or
// {"error": error} without a selection.
nlohmann::json DistortionSelectionJson(const analysis::DistortionSelection* selection,
                                       const std::string& error, bool applied);

// The report's section (nothing when there is neither a selection nor an error); `warning`: the
// solved model's principal point against the recommended one's (analysis::DistortionWarning).
ReportDoc DistortionSelectionDoc(const analysis::DistortionSelection* selection,
                                 const std::string& error,
                                 bool applied,
                                 const std::string& warning);

}  // namespace carmba
