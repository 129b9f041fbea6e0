// The joint problem's mrcal cross-check (joint_solver.h).
#include <algorithm>
#include <cmath>
#include <filesystem>

#include "calib/crosscheck.h"
#include "joint/joint_solver.h"
#include "util/format.h"

namespace carmba {

namespace {

// The 9 x k basis of the free intrinsics (ba::BlockInfo::basis) as rows; null when it is the
// identity (all nine free: mrcal's own free set).
nlohmann::json FreeBasisJson(const Eigen::MatrixXd& basis) {
  if (basis.rows() == basis.cols() && basis.isIdentity(0)) return nullptr;
  return JsonRows(basis);
}

// "all nine intrinsics free", or e.g. "p1 p2 k3 held (mrcal: Gauss-Newton with that free set)".
std::string FreeIntrinsicsText(const ba::IntrinsicsGroup& g) {
  const std::string text = HeldIntrinsicsText(g.free, g.fy_over_fx > 0);
  return text.empty() ? "all nine intrinsics free"
                      : text + " (mrcal: Gauss-Newton on its residuals and Jacobian with that "
                               "free set)";
}

}  // namespace

StatusOr<nlohmann::json> JointMrcalCrossCheck(const Problem& problem,
                                              const JointSolution& solution,
                                              const MrcalCrossCheckOptions& mrcal_options) {
  const ba::BaProblem& joint = solution.ba_problem;
  if (joint.groups.size() != 1 || problem.plate.views.empty() || problem.object_views.empty()) {
    return Status::Error("the mrcal cross-check needs one intrinsics group and both plate and "
                         "object views");
  }
  if (joint.groups[0].smooth) {
    return Status::Error("the mrcal cross-check needs intrinsics that do not depend on the "
                         "C-arm angles (model shared)");
  }
  // carmba's variant: markers held at their CT centres, the solve's free intrinsics (all nine
  // when it held every one), no priors, the same initial values (joint.* hold the initial values,
  // the solution is in solution.result). mrcal's optimizer frees all nine; with some held, the
  // script solves with carmba's free set on mrcal's residuals and Jacobian (like with like).
  ba::BaProblem variant = joint;
  variant.markers_free = false;
  const auto& free = variant.groups[0].free;
  if (std::none_of(free.begin(), free.end(), [](bool f) { return f; })) {
    variant.groups[0].free.fill(true);
    variant.groups[0].fy_over_fx = 0;
  }
  variant.groups[0].has_prior = false;
  variant.plate.free = false;
  ba::BaOptions options;
  options.function_tolerance = 1e-15;
  options.gradient_tolerance = 1e-15;
  options.parameter_tolerance = 1e-15;
  options.max_iterations = 200;
  auto r = ba::SolveBundleAdjustment(variant, options);
  if (!r.ok()) return Status::Error("carmba, markers held: " + r.status().message());
  const ba::StateLayout& L = *r->layout;

  nlohmann::json in;
  in["mode"] = "joint";
  in["image_size"] = {joint.groups[0].width, joint.groups[0].height};
  in["grid"] = {{"rows", problem.plate.grid.rows},
                {"cols", problem.plate.grid.cols},
                {"spacing_mm", problem.plate.grid.spacing_mm}};
  std::map<int, int> point_index;
  nlohmann::json points = nlohmann::json::array();
  for (size_t m = 0; m < joint.markers.size(); ++m) {
    point_index[joint.markers[m].id] = static_cast<int>(m);
    const auto& p = joint.markers[m].p_ct;
    points.push_back({p.x(), p.y(), p.z()});
  }
  in["points"] = points;
  nlohmann::json plate_views = nlohmann::json::array(), object_views = nlohmann::json::array();
  nlohmann::json init_plate = nlohmann::json::array(), init_object = nlohmann::json::array();
  nlohmann::json sol_plate = nlohmann::json::array(), sol_object = nlohmann::json::array();
  auto pose_json = [](const double* p) { return nlohmann::json(std::vector<double>(p, p + 6)); };
  for (size_t v = 0; v < variant.views.size(); ++v) {
    const ba::BaView& view = variant.views[v];
    nlohmann::json obs = nlohmann::json::array();
    for (size_t i = 0; i < view.point_ids.size(); ++i) {
      const int id =
          view.kind == ba::ViewKind::kPlate ? view.point_ids[i] : point_index.at(view.point_ids[i]);
      // The pixels the solve saw: minus the cone-beam shadow offsets it subtracted (mrcal has no
      // model of them).
      const Eigen::Vector2d uv = r->shadow_offsets.empty()
                                     ? view.uv_px[i]
                                     : Eigen::Vector2d(view.uv_px[i] - r->shadow_offsets[v][i]);
      obs.push_back({id, uv.x(), uv.y()});
    }
    const Pose6 pose = r->ViewPose(static_cast<int>(v));
    const double* sol = pose.data();
    if (view.kind == ba::ViewKind::kPlate) {
      plate_views.push_back(obs);
      init_plate.push_back(pose_json(view.initial.data()));
      sol_plate.push_back(pose_json(sol));
    } else {
      object_views.push_back(obs);
      init_object.push_back(pose_json(view.initial.data()));
      sol_object.push_back(pose_json(sol));
    }
  }
  in["plate_views"] = plate_views;
  in["object_views"] = object_views;
  in["weight_object"] = problem.plate_sigma_px / problem.object_sigma_px;
  const std::array<double, kNumIntrinsics> x = r->GroupIntrinsics(0);
  in["initial"] = {{"intrinsics", joint.groups[0].initial},
                   {"plate_poses", init_plate},
                   {"object_poses", init_object}};
  in["carmba"] = {{"intrinsics", std::vector<double>(x.begin(), x.end())},
                  {"plate_poses", sol_plate},
                  {"object_poses", sol_object},
                  {"free_basis", FreeBasisJson(L.block(L.group_block(0)).basis)}};
  auto out = RunMrcalScript(in, mrcal_options);
  if (!out.ok()) return out.status();
  const Eigen::MatrixXd C = r->GroupIntrinsicsCovariance(0);
  double max_rel_core = 0, max_sigmas = 0;
  nlohmann::json rel = nlohmann::json::object();
  std::vector<double> mrcal_intr = out->at("intrinsics").get<std::vector<double>>();
  for (int i = 0; i < kNumIntrinsics; ++i) {
    const double d = std::abs(x[i] - mrcal_intr[i]);
    if (i < 4) max_rel_core = std::max(max_rel_core, d / std::abs(x[i]));
    rel[kIntrinsicNames[i]] = x[i] != 0 ? d / std::abs(x[i]) : d;
    const double sigma = std::sqrt(std::max(C(i, i), 0.0));
    if (sigma > 0) max_sigmas = std::max(max_sigmas, d / sigma);
  }
  // mrcal seeded at carmba's optimum (the script re-optimises from it): how far mrcal moves.
  // Relative moves are large for a term near zero or in the flat valley of the radial terms
  // (k2, k3 trade off); the move in sigmas says whether it matters.
  double max_rel_at_carmba = 0, max_sig_at_carmba = 0;
  if (out->contains("intrinsics_seeded_at_carmba")) {
    const auto at = out->at("intrinsics_seeded_at_carmba").get<std::vector<double>>();
    for (int i = 0; i < kNumIntrinsics && i < static_cast<int>(at.size()); ++i) {
      const double d = std::abs(x[i] - at[i]);
      max_rel_at_carmba = std::max(max_rel_at_carmba, x[i] != 0 ? d / std::abs(x[i]) : d);
      const double sigma = std::sqrt(std::max(C(i, i), 0.0));
      if (sigma > 0) max_sig_at_carmba = std::max(max_sig_at_carmba, d / sigma);
    }
  }
  nlohmann::json j;
  j["max_relative_move_of_mrcal_seeded_at_carmba"] = max_rel_at_carmba;
  j["max_move_in_sigmas_of_mrcal_seeded_at_carmba"] = max_sig_at_carmba;
  j["what"] = "markers held at their CT centres, " + FreeIntrinsicsText(variant.groups[0]) +
              ", one intrinsics, seeded from carmba's initial values";
  j["carmba"] = {{"intrinsics", std::vector<double>(x.begin(), x.end())},
                 {"iterations", r->iterations},
                 {"termination", r->TerminationText()}};
  j["mrcal"] = *out;
  j["max_relative_difference_fx_fy_cx_cy"] = max_rel_core;
  j["max_difference_in_sigmas"] = max_sigmas;
  j["relative_difference"] = rel;
  j["rms_px_mrcal"] = out->at("rms_px_of_mrcal_solution");
  j["rms_px_carmba_in_mrcal"] = out->at("rms_px_of_carmba_solution");
  return j;
}

nlohmann::json JointMrcalCrossCheckJson(const Problem& problem,
                                        const JointSolution& solution,
                                        const MrcalCrossCheckOptions& options) {
  auto mrcal = JointMrcalCrossCheck(problem, solution, options);
  std::error_code ec;
  std::filesystem::remove_all(options.work_dir, ec);
  if (!mrcal.ok()) return {{"error", mrcal.status().message()}};
  return *mrcal;
}

}  // namespace carmba
