// A real, cheap run function for testing the study runner: estimating the mean of a Gaussian
// from `samples` seeded draws. Its answers are known in closed form (the mean's standard error
// is sigma / sqrt(n)), so tests can check the summaries' statistics, not just their plumbing.
//
// Problem file (YAML):  true_mean: 3.0     samples: 50
// Config file (YAML):   estimator: mean | median     repeat: 1  (passes over the data, for load)
//                       throw_on_trial: -1 (>= 0: throw std::runtime_error in that trial)
// Swept variable: noise_sd (default 1).
#pragma once

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "study/runner.h"
#include "util/file_util.h"
#include "util/yaml_reader.h"

namespace carmba::testing {

// Gaussian draws from a 64-bit Mersenne twister via Box-Muller (portable across standard
// libraries, unlike std::normal_distribution).
inline double Gaussian(std::mt19937_64* rng) {
  constexpr double kTwoPi = 6.283185307179586;
  const double u1 = (static_cast<double>((*rng)() >> 11) + 0.5) * 0x1.0p-53;
  const double u2 = (static_cast<double>((*rng)() >> 11) + 0.5) * 0x1.0p-53;
  return std::sqrt(-2 * std::log(u1)) * std::cos(kTwoPi * u2);
}

inline StatusOr<nlohmann::json> MeanRun(const RunSpec& run) {
  double true_mean = 0;
  int samples = 0;
  {
    YamlMap p = YamlMap::Load(run.problem->file);
    p.Get("true_mean", &true_mean, /*required=*/true);
    p.Get("samples", &samples, /*required=*/true);
    if (p.status().ok() && samples < 2) p.Fail("samples", "expected an integer >= 2");
    CARMBA_RETURN_IF_ERROR(p.Finish());
  }
  std::string estimator = "mean";
  int repeat = 1, throw_on_trial = -1;
  {
    YamlMap c = YamlMap::Load(run.config->file);
    c.GetEnum("estimator", {"mean", "median"}, &estimator, /*required=*/true);
    if (c.Has("repeat")) c.Get("repeat", &repeat);
    if (c.Has("throw_on_trial")) c.Get("throw_on_trial", &throw_on_trial);
    CARMBA_RETURN_IF_ERROR(c.Finish());
  }
  if (run.trial == throw_on_trial) throw std::runtime_error("trial " + std::to_string(run.trial));
  const double sigma = run.SweepValue("noise_sd", 1.0);
  std::vector<double> x;
  double estimate = 0;
  for (int pass = 0; pass < std::max(1, repeat); ++pass) {
    std::mt19937_64 rng(run.seed);
    x.assign(samples, 0);
    for (double& v : x) v = true_mean + sigma * Gaussian(&rng);
    if (estimator == "mean") {
      double s = 0;
      for (double v : x) s += v;
      estimate = s / samples;
    } else {
      std::vector<double> y = x;
      std::nth_element(y.begin(), y.begin() + samples / 2, y.end());
      estimate = y[samples / 2];
    }
  }
  double ss = 0;
  for (double v : x) ss += (v - estimate) * (v - estimate);
  const double sd = std::sqrt(ss / (samples - 1));
  // Standard error of the mean; the median's is sqrt(pi/2) times larger for Gaussian data.
  const double se = sd / std::sqrt(static_cast<double>(samples)) *
                    (estimator == "mean" ? 1.0 : std::sqrt(M_PI / 2));
  nlohmann::json residuals = nlohmann::json::array();
  for (size_t i = 0; i < x.size() && i < 20; ++i) residuals.push_back(x[i] - estimate);
  nlohmann::json r;
  r["converged"] = true;
  r["errors"] = {{"abs_error", std::fabs(estimate - true_mean)}};
  r["signed_errors"] = {{"mean", estimate - true_mean}};
  r["sigmas"] = {{"mean", se}};
  r["values"] = {{"sample_sd", sd}, {"iterations", 1}};
  r["residuals_px"] = residuals;
  r["budget"] = {{"noise", sigma / std::sqrt(static_cast<double>(samples))}};
  return r;
}

}  // namespace carmba::testing
