// Does an answer leave the range its calibration was made in? Object views of a solve compared
// with the plate views that calibrated their intrinsics: their depth (the markers' centroid
// against the plate centre, along the optical axis) and, for an angle-dependent (smooth) model,
// their C-arm angles. One sentence per view outside, naming it and the range.
#pragma once

#include <string>
#include <vector>

#include "ba/bundle_adjuster.h"

namespace carmba {
namespace analysis {

// An object view nearer than kDepthRangeLow x the plate views' nearest depth, or farther than
// kDepthRangeHigh x their farthest, is outside; an angle more than kAngleToleranceDeg outside the
// plate views' angles of its smooth group is outside.
constexpr double kDepthRangeLow = 0.8;
constexpr double kDepthRangeHigh = 1.25;
constexpr double kAngleToleranceDeg = 1.0;

std::vector<std::string> CalibratedRangeWarnings(const ba::BaProblem& problem,
                                                 const ba::BaResult& result);

}  // namespace analysis
}  // namespace carmba
