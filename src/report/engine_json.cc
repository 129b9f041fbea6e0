#include "report/engine_json.h"

#include "util/format.h"

namespace carmba {

void MarkersAndOutliersJson(const ba::BaProblem& problem, const ba::BaResult& result,
                            nlohmann::json* out) {
  nlohmann::json& j = *out;
  const ba::StateLayout& L = *result.layout;
  nlohmann::json markers = nlohmann::json::array();
  for (size_t m = 0; m < problem.markers.size(); ++m) {
    const int b = L.marker_block(static_cast<int>(m));
    nlohmann::json mj = {{"id", problem.markers[m].id},
                         {"p_in_object_mm", JsonVector(Eigen::Map<const Eigen::Vector3d>(result.block(b)))}};
    if (result.covariance) mj["covariance_mm2"] = JsonRows(result.Covariance({b}));
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

}  // namespace carmba
