// DIR/report.html: a self-contained page (inline SVG, no external file, no server, no network)
// with the plots of a study:
//   data-plot="error-vs-noise"      median error (and p95 band ends as markers) against each swept
//                                   variable with >= 2 values, one line per config; other swept
//                                   variables held at their first value
//   data-plot="sigma-consistency"   reported sigma (x) vs empirical spread (y) per parameter and
//                                   group, log-log, with the y = x line of honest uncertainty
//   data-plot="residual-histogram"  histogram of the pooled "residuals_px" per problem x config
//   data-plot="error-budget"        bars of the mean "budget" contributions per problem x config,
//                                   or, when runs give no budget, of the median errors
// Every plot is an <svg class="plot" data-plot=...>. A script at the end of the page counts the
// plots the browser laid out with a non-empty bounding box into
// <body data-plots-rendered=N data-plots-total=M>, and any script error into data-js-error, so a
// headless browser's --dump-dom shows whether the page rendered.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "study/summary.h"

namespace carmba {

std::string StudyReportHtml(const nlohmann::json& info, const std::vector<GroupSummary>& groups);

}  // namespace carmba
