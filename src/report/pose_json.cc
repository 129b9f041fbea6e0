// result.json for pose problems.
#include <algorithm>
#include <cmath>

#include "geometry/rotation.h"
#include "problem/pose_solver.h"
#include "report/engine_json.h"
#include "report/pose_report.h"
#include "report/relative_tre_report.h"
#include "report/variance_report.h"
#include "util/format.h"

namespace carmba {
nlohmann::json PoseToJson(const Pose6& p) {
  const Eigen::Matrix3d R = RotationFromRvec(p.head<3>());
  nlohmann::json Rj = nlohmann::json::array();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) Rj.push_back(R(i, j));
  }
  return {{"R", Rj}, {"rvec", JsonVector(p.head<3>())}, {"t_mm", JsonVector(p.tail<3>())}};
}

std::vector<ba::BudgetRow> PoseErrorBudget(const PoseSolution& s) {
  if (!s.ba_problem || !s.ba_result || !s.ba_result->covariance) return {};
  std::vector<ba::BudgetRow> budget =
      ba::ComputeErrorBudget(*s.ba_problem, *s.ba_result, s.validation_pairs);
  // The held intrinsics' centre projection has no uncertainty unless the calibration's is
  // considered: rows without a sigma say nothing.
  budget.erase(std::remove_if(budget.begin(), budget.end(),
                              [](const ba::BudgetRow& row) { return !(row.sigma > 0); }),
               budget.end());
  return budget;
}

nlohmann::json PoseSolutionToJson(const Problem& problem, const PoseSolution& s) {
  nlohmann::json j;
  j["problem"] = {
      {"name", problem.name},
      {"file", problem.path},
      {"sigma_px", problem.object_sigma_px},
      {"handedness", problem.handedness == Handedness::kMirrored ? "mirrored" : "as_given"},
      {"camera", CameraToJson(*problem.camera)}};
  nlohmann::json views = nlohmann::json::array();
  for (const auto& v : s.views) {
    nlohmann::json vj;
    vj["id"] = v.id;
    vj["kind"] = "object";
    vj["group"] = s.ba_problem && !s.ba_problem->groups.empty() ? s.ba_problem->groups[0].name
                                                                : std::string("shared");
    vj["cam_from_object"] = PoseToJson(v.cam_from_object);
    vj["covariance_6x6"] = s.has_covariance ? JsonRows(v.covariance) : nlohmann::json();
    vj["covariance_order"] = "rx ry rz (rad, rotation vector), tx ty tz (mm)";
    vj["sigma_rotation_deg"] = JsonVector(v.sigma_rotation_deg);
    vj["sigma_translation_mm"] = JsonVector(v.sigma_translation_mm);
    vj["rms_px"] = JsonNumber(v.rms_px);
    vj["num_observations"] = v.num_observations;
    vj["initial"] = PoseToJson(v.initial);
    vj["initial_rms_px"] = JsonNumber(v.initial_rms_px);
    if (problem.truth.object_poses.count(v.id)) {
      const Pose6& t = problem.truth.object_poses.at(v.id);
      vj["truth"] = PoseToJson(t);
      vj["rotation_error_deg"] =
          AngleBetweenRotations(RotationFromRvec(v.cam_from_object.head<3>()),
                                RotationFromRvec(t.head<3>())) *
          kRadToDeg;
      vj["translation_error_mm"] = (v.cam_from_object.tail<3>() - t.tail<3>()).norm();
    }
    views.push_back(vj);
  }
  j["views"] = views;
  nlohmann::json val = nlohmann::json::array();
  for (const auto& p : s.validation) {
    val.push_back({{"a", p.a},
                   {"b", p.b},
                   {"angle_view_dirs_deg", JsonNumber(p.angle_view_dirs_deg)},
                   {"sigma_view_dirs_deg", JsonNumber(p.sigma_view_dirs_deg)},
                   {"relative_rotation_deg", JsonNumber(p.relative_rotation_deg)},
                   {"sigma_relative_rotation_deg", JsonNumber(p.sigma_relative_rotation_deg)},
                   {"expected_deg", p.expected_deg ? nlohmann::json(*p.expected_deg)
                                                   : nlohmann::json()}});
  }
  j["validation"] = val;
  // The engine's problem and result: SolvePoseProblem always sets both.
  const ba::BaProblem& bp = *s.ba_problem;
  const ba::BaResult& br = *s.ba_result;
  MarkersAndOutliersJson(bp, br, &j);  // as every problem kind writes them
  j["statistics"] = StatisticsJson(bp, br);
  j["statistics"]["rms_px"] = JsonNumber(s.rms_px);
  j["statistics"]["sigma_aposteriori_px"] = JsonNumber(s.sigma_aposteriori_px);
  if (s.ba_result) {
    j["error_budget"] = ErrorBudgetJson(PoseErrorBudget(s));
    j["variance_components"] = VarianceComponentsJson(*s.ba_result);
    j["shadow_correction"] = ShadowCorrectionJson(*s.ba_result);
  }
  j["warnings"] = PoseWarnings(s);
  j["solver"] = SolverJson(s.config_name, br);
  // Where the pose front end differs: NOT_REFINED and the initial cost for refine: false, and its
  // wall time (initial poses, solve and covariance).
  j["solver"]["termination"] = s.termination;
  j["solver"]["final_cost"] = JsonNumber(s.final_cost);
  j["solver"]["time_s"] = s.time_s;
  if (s.has_covariance) j["joint_covariance"] = JsonRows(s.joint_covariance);
  if (s.ba_problem)
    j["relative_poses"] =
        RelativePosesJson(*s.ba_problem, s.relative_poses, problem.truth.object_poses);
  if (s.tre) j["tre"] = TreJson(*s.tre);
  return j;
}

GeometrySet PoseSolutionGeometry(const Problem& problem, const PoseSolution& s) {
  GeometrySet g;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& m : problem.fiducials) centroid += m.p_in_object;
  if (!problem.fiducials.empty()) g.reference_point_ct_mm = centroid / problem.fiducials.size();
  for (const auto& v : s.views) {
    ViewGeometry vg;
    vg.id = v.id;
    vg.camera = *problem.camera;  // one camera for all views in a pose problem
    vg.cam_from_ct = v.cam_from_object;
    vg.ct_mirrored = problem.handedness == Handedness::kMirrored;
    g.views.push_back(vg);
  }
  return g;
}

}  // namespace carmba
