// result.json for pose and joint problems: one writer (result_json.h).
#include "report/result_json.h"

#include "geometry/rotation.h"
#include "report/engine_json.h"
#include "report/pose_report.h"
#include "report/relative_tre_report.h"
#include "report/variance_report.h"
#include "util/format.h"

namespace carmba {

nlohmann::json PoseToJson(const Pose6& p) {
  const Eigen::Matrix3d R = RotationOf(p.head<3>());
  nlohmann::json Rj = nlohmann::json::array();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) Rj.push_back(R(i, j));
  }
  return {{"R", Rj}, {"rvec", JsonVector(p.head<3>())}, {"t_mm", JsonVector(p.tail<3>())}};
}

nlohmann::json ViewJson(const ViewRecord& v, const ProblemTruth& truth) {
  nlohmann::json j;
  j["id"] = v.id;
  j["kind"] = v.plate ? "plate" : "object";
  j["group"] = v.group;
  j[v.plate ? "cam_from_plate" : "cam_from_object"] = PoseToJson(v.pose);
  j["rms_px"] = JsonNumber(v.rms_px);
  j["num_observations"] = v.num_observations;
  if (v.initial) j["initial"] = PoseToJson(*v.initial);
  j["initial_rms_px"] = JsonNumber(v.initial_rms_px);
  if (v.plate) return j;
  j["covariance_6x6"] = v.covariance ? JsonRows(*v.covariance) : nlohmann::json();
  j["covariance_order"] = "rx ry rz (rad, rotation vector), tx ty tz (mm)";
  j["sigma_rotation_deg"] = JsonVector(v.sigma_rotation_deg);
  j["sigma_translation_mm"] = JsonVector(v.sigma_translation_mm);
  const auto it = truth.object_poses.find(v.id);
  if (it != truth.object_poses.end()) {
    const Pose6& t = it->second;
    j["truth"] = PoseToJson(t);
    j["rotation_error_deg"] =
        AngleBetweenRotations(RotationOf(v.pose.head<3>()), RotationOf(t.head<3>())) * kRadToDeg;
    j["translation_error_mm"] = (v.pose.tail<3>() - t.tail<3>()).norm();
  }
  return j;
}

nlohmann::json PairJson(const PairRecord& p, const ProblemTruth& truth) {
  nlohmann::json j = {
      {"a", p.a},
      {"b", p.b},
      {"relative_rotation_deg", JsonNumber(p.relative_rotation_deg)},
      {"sigma_relative_rotation_deg", JsonNumber(p.sigma_relative_rotation_deg)},
      {"angle_view_dirs_deg", JsonNumber(p.angle_view_dirs_deg)},
      {"sigma_view_dirs_deg", JsonNumber(p.sigma_view_dirs_deg)},
      {"expected_deg", p.expected_deg ? nlohmann::json(*p.expected_deg) : nlohmann::json()}};
  const auto ta = truth.object_poses.find(p.a), tb = truth.object_poses.find(p.b);
  if (ta != truth.object_poses.end() && tb != truth.object_poses.end()) {
    j["true_relative_rotation_deg"] =
        RelativeRotationAngle(ta->second.data(), tb->second.data()) * kRadToDeg;
  }
  return j;
}

nlohmann::json ResultJson(const ResultContent& c, const ProblemTruth& truth) {
  const ba::BaProblem& bp = *c.engine_problem;
  const ba::BaResult& br = *c.engine_result;
  nlohmann::json j;
  j["problem"] = c.problem;
  j["warnings"] = c.warnings;
  nlohmann::json views = nlohmann::json::array();
  for (const ViewRecord& v : c.views) views.push_back(ViewJson(v, truth));
  j["views"] = views;
  nlohmann::json validation = nlohmann::json::array();
  for (const PairRecord& p : c.validation) validation.push_back(PairJson(p, truth));
  j["validation"] = validation;
  j["relative_poses"] = RelativePosesJson(bp, c.relative_poses, truth.object_poses);
  if (c.tre) j["tre"] = TreJson(*c.tre);
  MarkersAndOutliersJson(bp, br, &j);
  j["error_budget"] = ErrorBudgetJson(c.error_budget);
  j["statistics"] = StatisticsJson(bp, br);
  j["statistics"].update(c.statistics_extra);
  j["variance_components"] = VarianceComponentsJson(br);
  j["shadow_correction"] = ShadowCorrectionJson(br);
  j["solver"] = SolverJson(c.config_name, br);
  j["solver"].update(c.solver_extra);
  j.update(c.kind_sections);
  return j;
}

}  // namespace carmba
