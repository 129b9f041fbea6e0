// result.json for pose problems.
#include <algorithm>
#include <cmath>

#include "problem/pose_solver.h"
#include "report/pose_report.h"
#include "report/result_json.h"
#include "util/format.h"

namespace carmba {
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
  // The engine's problem and result: SolvePoseProblem always sets both.
  ResultContent c;
  c.problem = {
      {"name", problem.name},
      {"file", problem.path},
      {"sigma_px", problem.object_sigma_px},
      {"handedness", problem.handedness == Handedness::kMirrored ? "mirrored" : "as_given"},
      {"camera", CameraToJson(*problem.camera)}};
  c.engine_problem = s.ba_problem.get();
  c.engine_result = s.ba_result.get();
  c.config_name = s.config_name;
  const std::string& group = s.ba_problem->groups[0].name;
  for (const auto& v : s.views) {
    ViewRecord rec;
    rec.id = v.id;
    rec.group = group;
    rec.pose = v.cam_from_object;
    rec.rms_px = v.rms_px;
    rec.num_observations = v.num_observations;
    rec.initial = v.initial;
    rec.initial_rms_px = v.initial_rms_px;
    if (s.has_covariance) rec.covariance = v.covariance;
    rec.sigma_rotation_deg = v.sigma_rotation_deg;
    rec.sigma_translation_mm = v.sigma_translation_mm;
    c.views.push_back(rec);
  }
  for (const auto& p : s.validation) {
    PairRecord rec;
    rec.a = p.a, rec.b = p.b, rec.expected_deg = p.expected_deg;
    rec.relative_rotation_deg = p.relative_rotation_deg;
    rec.sigma_relative_rotation_deg = p.sigma_relative_rotation_deg;
    rec.angle_view_dirs_deg = p.angle_view_dirs_deg;
    rec.sigma_view_dirs_deg = p.sigma_view_dirs_deg;
    c.validation.push_back(rec);
  }
  c.error_budget = PoseErrorBudget(s);
  c.warnings = PoseWarnings(s);
  c.relative_poses = s.relative_poses;
  c.tre = s.tre;
  c.statistics_extra = {
      {"rms_px", JsonNumber(s.ba_result->rms_object_px)},
      {"sigma_aposteriori_px", JsonNumber(s.ba_result->sigma0 * problem.object_sigma_px)}};
  // Where the pose front end differs: NOT_REFINED and the initial cost for refine: false, and its
  // wall time (initial poses, solve and covariance).
  c.solver_extra = {{"termination", s.termination},
                    {"final_cost", JsonNumber(s.final_cost)},
                    {"time_s", s.time_s}};
  if (s.has_covariance) c.kind_sections["joint_covariance"] = JsonRows(s.joint_covariance);
  return ResultJson(c, problem.truth);
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
