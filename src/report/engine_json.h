// result.json sections written from the engine's problem and result alone (ba/), the same for
// every problem kind that solves with it (pose and joint problems).
#pragma once

#include <nlohmann/json.hpp>

#include "ba/bundle_adjuster.h"

namespace carmba {

// "markers": per CT marker {id, p_in_object_mm, covariance_mm2 (with the engine's covariance)};
// "outliers": observations beyond the outlier threshold {view, marker | point, residual_sigma,
// du_px, dv_px}; "rejected": observations dropped by reject_sigma {view, marker | point,
// residual_sigma}. Written into `out`.
void MarkersAndOutliersJson(const ba::BaProblem& problem, const ba::BaResult& result,
                            nlohmann::json* out);

// "statistics" as the engine computes them: chi2 (at the stated sigmas, priors included), dof,
// chi2_p_value, sigma0, num_residuals, num_parameters, covariance_scale; rms_plate_px and
// rms_object_px (per coordinate) where the problem has views of that kind.
nlohmann::json StatisticsJson(const ba::BaProblem& problem, const ba::BaResult& result);

// "solver": config (its name), engine (the minimiser that ran, in src/ba), iterations,
// termination, converged, initial_cost, final_cost, time_s (the engine's).
nlohmann::json SolverJson(const std::string& config_name, const ba::BaResult& result);

}  // namespace carmba
