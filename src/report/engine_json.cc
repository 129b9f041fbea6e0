#include "report/engine_json.h"

#include "util/format.h"

namespace carmba {

void MarkersAndOutliersJson(const ba::BaProblem& problem, const ba::BaResult& result,
                            nlohmann::json* out) {
  nlohmann::json& j = *out;
  nlohmann::json markers = nlohmann::json::array();
  for (size_t m = 0; m < problem.markers.size(); ++m) {
    const int mi = static_cast<int>(m);
    nlohmann::json mj = {{"id", problem.markers[m].id},
                         {"p_in_object_mm", JsonVector(result.MarkerPosition(mi))}};
    if (result.covariance) mj["covariance_mm2"] = JsonRows(result.MarkerCovariance(mi));
    markers.push_back(mj);
  }
  j["markers"] = markers;
  nlohmann::json outliers = nlohmann::json::array();
  for (const auto& o : result.outliers) {
    outliers.push_back({{"view", o.view},
                        {o.plate ? "point" : "marker", o.id},
                        {"residual_sigma", JsonNumber(o.residual_sigma)},
                        {"du_px", JsonNumber(o.du_px)},
                        {"dv_px", JsonNumber(o.dv_px)}});
  }
  j["outliers"] = outliers;
  nlohmann::json rejected = nlohmann::json::array();
  for (const auto& o : result.rejected) {
    rejected.push_back({{"view", o.view}, {o.plate ? "point" : "marker", o.id},
                        {"residual_sigma", JsonNumber(o.residual_sigma)}});
  }
  j["rejected"] = rejected;
}

nlohmann::json StatisticsJson(const ba::BaProblem& problem, const ba::BaResult& result) {
  bool plate = false, object = false;
  for (const ba::BaView& v : problem.views) {
    (v.kind == ba::ViewKind::kPlate ? plate : object) = true;
  }
  nlohmann::json j = {{"sigma0", JsonNumber(result.sigma0)},
                      {"chi2", JsonNumber(result.chi2)},
                      {"dof", result.dof},
                      {"chi2_p_value", JsonNumber(result.chi2_p_value)},
                      {"num_residuals", result.num_residuals},
                      {"num_parameters", result.num_free},
                      {"covariance_scale", NameOf(ba::kCovarianceScaleNames, result.scale_mode)}};
  if (plate) j["rms_plate_px"] = JsonNumber(result.rms_plate_px);
  if (object) j["rms_object_px"] = JsonNumber(result.rms_object_px);
  return j;
}

nlohmann::json SolverJson(const std::string& config_name, const ba::BaResult& result) {
  return {{"config", config_name},
          {"engine", std::string(NameOf(ba::kBackendNames, result.backend)) + " (src/ba)"},
          {"iterations", result.iterations},
          {"termination", result.TerminationText()},
          {"converged", result.converged()},
          {"initial_cost", JsonNumber(result.initial_cost)},
          {"final_cost", JsonNumber(result.final_cost)},
          {"time_s", JsonNumber(result.time_s)}};
}

}  // namespace carmba
