// The joint problem's front end: initial values, the engine's problem, error budget and the
// two-step comparison (joint_solver.h).
#include "joint/joint_solver.h"

#include <algorithm>
#include <cmath>
#include <set>

#include "analysis/lens_models.h"
#include "calib/calibrate.h"
#include "problem/ba_assembly.h"
#include "util/format.h"

namespace carmba {
namespace {

std::string GroupOfPlateView(const Problem& p, size_t v) {
  if (!p.per_group) return "shared";
  auto it = p.group_of_view.find(p.plate_view_ids[v]);
  if (it == p.group_of_view.end()) it = p.group_of_view.find(std::to_string(v));
  return it->second;
}

std::string GroupOfObjectView(const Problem& p, const std::string& id) {
  return p.per_group ? p.group_of_view.at(id) : "shared";
}

// The object views' poses and their sigmas in a solved engine problem.
PoseSigmas SigmasOf(const std::string& method,
                    const ba::BaProblem& bp,
                    const ba::BaResult& r,
                    const std::vector<std::pair<int, int>>& pairs) {
  PoseSigmas s;
  s.method = method;
  const auto rows = ba::ComputeErrorBudget(bp, r, pairs);
  for (size_t v = 0; v < bp.views.size(); ++v) {
    if (bp.views[v].kind != ba::ViewKind::kObject) continue;
    Eigen::Vector3d rot, t;
    for (int a = 0; a < 3; ++a) {
      rot[a] =
          ba::FindBudgetRow(rows, ba::QuantityKey::ViewRotation(static_cast<int>(v), a))->sigma;
      t[a] =
          ba::FindBudgetRow(rows, ba::QuantityKey::ViewTranslation(static_cast<int>(v), a))->sigma;
    }
    s.sigma_rotation_deg.push_back(rot);
    s.sigma_translation_mm.push_back(t);
    s.cam_from_object.push_back(r.ViewPose(static_cast<int>(v)));
  }
  for (const auto& [a, b] : pairs) {
    const auto* row = ba::FindBudgetRow(rows, ba::QuantityKey::PairRelativeRotation(a, b));
    s.sigma_relative_rotation_deg.push_back(row->sigma);
    s.relative_rotation_deg.push_back(row->quantity.value);
  }
  return s;
}

// A copy of `bp` with only its object views (pairs re-indexed), for the two-step comparison.
ba::BaProblem ObjectViewsOnly(const ba::BaProblem& bp,
                              const std::vector<std::pair<int, int>>& pairs,
                              std::vector<std::pair<int, int>>* new_pairs) {
  ba::BaProblem out = bp;
  out.views.clear();
  std::map<int, int> index;
  for (size_t v = 0; v < bp.views.size(); ++v) {
    if (bp.views[v].kind != ba::ViewKind::kObject) continue;
    index[static_cast<int>(v)] = static_cast<int>(out.views.size());
    out.views.push_back(bp.views[v]);
  }
  out.plate = ba::BaPlate();
  new_pairs->clear();
  for (const auto& [a, b] : pairs) new_pairs->emplace_back(index.at(a), index.at(b));
  return out;
}

}  // namespace

namespace {

// The smooth model's basis for the plate views' angles: plate views at one secondary angle (a
// C-arm calibrated along its orbit only) cannot determine a dependence on it, so the model takes
// secondary_degree 0 and says so in `note`; when the file asked for more, an error that says what
// to do.
StatusOr<ba::SmoothBasis> SmoothBasisForPlateAngles(const Problem& problem,
                                                    const ba::BaProblem& bp,
                                                    std::string* note) {
  ba::SmoothBasis basis = problem.smooth_basis;
  std::set<double> secondaries;
  for (const auto& v : bp.views) {
    if (v.kind == ba::ViewKind::kPlate && v.has_angles) secondaries.insert(v.secondary_deg);
  }
  if (secondaries.size() != 1 || basis.secondary_degree == 0) return basis;
  const std::string at = Fmt("%g", *secondaries.begin());
  if (problem.secondary_degree_given) {
    return Status::Error("intrinsics.secondary_degree " + std::to_string(basis.secondary_degree) +
                         ": every plate view is at secondary angle " + at +
                         " deg, so no dependence on it can be estimated; set secondary_degree: 0 "
                         "(the intrinsics follow the primary angle only) or add plate views at "
                         "another secondary angle");
  }
  basis.secondary_degree = 0;
  *note = "every plate view is at secondary angle " + at +
          " deg: the smooth model takes secondary_degree 0 (the intrinsics follow the primary "
          "angle only); object views at other secondary angles are extrapolated";
  return basis;
}

// The distortion models compared on the plate views (analysis/lens_models.h), for one shared group;
// with distortion: auto the recommended one is applied to `bp`.
void SelectDistortion(const Problem& problem,
                      const SolverConfig& config,
                      const ba::BaOptions& options,
                      ba::BaProblem* bp,
                      JointSolution* sol) {
  if (problem.plate.views.empty()) return;
  if (problem.smooth || problem.per_group || bp->groups.size() != 1) {
    if (config.distortion_auto) {
      sol->distortion_error =
          std::string("distortion: auto is for one shared intrinsics group (model ") +
          IntrinsicsModelName(problem) + "): the distortion terms are those `fix` leaves free";
    }
    return;
  }
  auto sel = analysis::SelectDistortionModel(*bp, options);
  if (!sel.ok()) {
    sol->distortion_error = sel.status().message();
    return;
  }
  sol->distortion = *sel;
  if (config.distortion_auto) {
    // The solve starts at the recommended model's fit of the plate views.
    analysis::ApplyDistortionModel(sel->recommended, bp);
    analysis::StartFromFit(*sel->Score(sel->recommended), bp);
  }
}

Status CheckJointConfig(const SolverConfig& config) {
  std::string err;
  if (!config.Check(&err)) return Status::Error(config.path + ": " + err);
  if (!config.refine) {
    return Status::Error(config.path + ": refine: false has no meaning for a joint problem");
  }
  if (config.covariance_algorithm != ba::CovarianceAlgorithm::kSchur) {
    return Status::Error(config.path + ": covariance.algorithm '" +
                         NameOf(ba::kCovarianceAlgorithmNames, config.covariance_algorithm) +
                         "': joint problems use the engine's Schur covariance (schur), which the "
                         "error budget is built on; ceres::Covariance is its test reference");
  }
  return Status::Ok();
}

// The intrinsics groups, in order of first appearance, and each view's group.
struct GroupAssignment {
  std::vector<std::string> names;
  std::vector<int> of_plate_view, of_object_view;
  std::vector<std::vector<int>> plate_views;  // per group

  explicit GroupAssignment(const Problem& problem) {
    for (size_t v = 0; v < problem.plate.views.size(); ++v) {
      of_plate_view.push_back(Index(GroupOfPlateView(problem, v)));
    }
    for (const auto& v : problem.object_views)
      of_object_view.push_back(Index(GroupOfObjectView(problem, v.id)));
    plate_views.resize(names.size());
    for (size_t v = 0; v < of_plate_view.size(); ++v)
      plate_views[of_plate_view[v]].push_back(static_cast<int>(v));
  }

 private:
  int Index(const std::string& g) {
    auto it = std::find(names.begin(), names.end(), g);
    if (it != names.end()) return static_cast<int>(it - names.begin());
    names.push_back(g);
    return static_cast<int>(names.size()) - 1;
  }
};

// camera.json's intrinsics and their variances > 0 as a prior on a group.
void SetCameraPrior(const Camera& c, ba::IntrinsicsGroup* grp) {
  grp->has_prior = true;
  std::copy(c.params.begin(), c.params.end(), grp->prior.mean.begin());
  std::vector<int> names_index;
  for (size_t i = 0; i < c.covariance_names.size(); ++i) {
    const int k = IntrinsicIndexOf(c.covariance_names[i]);
    if (k >= 0 && c.covariance[i][i] > 0) {
      grp->prior.indices.push_back(k);
      names_index.push_back(static_cast<int>(i));
    }
  }
  const int n = static_cast<int>(names_index.size());
  grp->prior.covariance.resize(n, n);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j)
      grp->prior.covariance(i, j) = c.covariance[names_index[i]][names_index[j]];
  }
}

// Group g's initial intrinsics and plate poses: carmba's calibration of the group's plate views
// (Zhang, then its bundle adjustment), from camera.json's intrinsics when given.
StatusOr<ba::IntrinsicsGroup> InitialGroup(const Problem& problem,
                                           const SolverConfig& config,
                                           const GroupAssignment& groups,
                                           size_t g,
                                           std::vector<Pose6>* plate_poses) {
  ba::IntrinsicsGroup grp;
  grp.name = groups.names[g];
  grp.free.fill(true);
  for (const auto& n : config.fix) grp.free[IntrinsicIndexOf(n)] = false;
  if (problem.camera) {
    std::copy(problem.camera->params.begin(), problem.camera->params.end(), grp.initial.begin());
    grp.width = problem.camera->width;
    grp.height = problem.camera->height;
  }
  if (!groups.plate_views[g].empty()) {
    ObservationSet sub;
    sub.grid = problem.plate.grid;
    sub.width = problem.plate.width;
    sub.height = problem.plate.height;
    for (int v : groups.plate_views[g]) sub.views.push_back(problem.plate.views[v]);
    CalibrationOptions co;
    co.solve.fix = config.fix;
    co.pixel_sigma_px = problem.plate_sigma_px;
    co.min_views = 1;
    co.solve.max_iterations = std::max(config.max_iterations, 1);
    if (problem.camera) co.initial_intrinsics.assign(grp.initial.begin(), grp.initial.end());
    auto cal = Calibrate(sub, co);
    if (!cal.ok()) {
      return Status::Error(problem.path + ": plate views of group '" + grp.name +
                           "': " + cal.status().message());
    }
    std::copy(cal->camera.params.begin(), cal->camera.params.end(), grp.initial.begin());
    grp.width = problem.plate.width;
    grp.height = problem.plate.height;
    *plate_poses = cal->cam_from_plate;
  } else if (!problem.camera) {
    return Status::Error(problem.path + ": intrinsics group '" + grp.name +
                         "' has no plate views and no camera file");
  }
  if (problem.camera_prior) SetCameraPrior(*problem.camera, &grp);
  return grp;
}

// The plate views, each initialised by its group's calibration.
std::vector<ba::BaView> PlateViews(const Problem& problem,
                                   const GroupAssignment& groups,
                                   const std::vector<std::vector<Pose6>>& plate_poses) {
  std::vector<ba::BaView> views;
  std::vector<size_t> next_pose(groups.names.size(), 0);
  for (size_t v = 0; v < problem.plate.views.size(); ++v) {
    const int g = groups.of_plate_view[v];
    views.push_back(ToBaPlateView(problem.plate.views[v],
                                  problem.plate_view_ids[v],
                                  g,
                                  plate_poses[g][next_pose[g]++],
                                  problem.plate_sigma_px));
  }
  return views;
}

// The engine's problem (problem/ba_assembly.h) with the groups initialised by the calibration of
// their plate views (or camera.json), the plate views by theirs.
Status JointBaProblem(const Problem& problem, const SolverConfig& config, JointSolution* sol) {
  const GroupAssignment groups(problem);
  BaAssemblyInput input;
  std::vector<std::vector<Pose6>> plate_poses(groups.names.size());
  sol->initial_intrinsics_from = problem.camera ? "camera file" : "calibration of the plate views";
  for (size_t g = 0; g < groups.names.size(); ++g) {
    auto grp = InitialGroup(problem, config, groups, g, &plate_poses[g]);
    if (!grp.ok()) return grp.status();
    input.groups.push_back(*grp);
  }
  input.plate_views = PlateViews(problem, groups, plate_poses);
  input.object_view_groups = groups.of_object_view;
  auto assembled = ToBaProblem(problem, config, std::move(input));
  if (!assembled.ok()) return assembled.status();
  sol->ba_problem = std::move(assembled->problem);
  sol->pairs = std::move(assembled->validation_pairs);
  return Status::Ok();
}

// The intrinsics and distortion models: the distortion selection, the smooth model's basis,
// the comparison of the intrinsics models when asked, and the smooth model applied.
Status ApplyModels(const Problem& problem,
                   const SolverConfig& config,
                   const ba::BaOptions& options,
                   JointSolution* sol) {
  ba::BaProblem& bp = sol->ba_problem;
  SelectDistortion(problem, config, options, &bp, sol);
  sol->smooth_basis = problem.smooth_basis;
  if (problem.smooth) {
    auto basis = SmoothBasisForPlateAngles(problem, bp, &sol->model_note);
    if (!basis.ok()) return Status::Error(problem.path + ": " + basis.status().message());
    sol->smooth_basis = *basis;
  }
  if (problem.select_model && !problem.plate.views.empty()) {
    auto sel = analysis::SelectIntrinsicsModel(bp,
                                               sol->smooth_basis,
                                               options,
                                               {analysis::IntrinsicsModel::kShared,
                                                analysis::IntrinsicsModel::kPerGroup,
                                                analysis::IntrinsicsModel::kSmooth});
    if (sel.ok()) {
      sol->selection = *sel;
    } else {
      sol->selection_error = sel.status().message();
    }
  }
  if (problem.smooth) {
    const Status s =
        analysis::ApplyIntrinsicsModel(analysis::IntrinsicsModel::kSmooth, sol->smooth_basis, &bp);
    if (!s.ok()) return Status::Error(problem.path + ": " + s.message());
  }
  return Status::Ok();
}

// The object views alone with each group's intrinsics from `calibration`: held (two_step) or
// free with the calibration's covariance as prior (with_prior).
void TwoStepProblems(const ba::BaProblem& bp,
                     const ba::BaResult& calibration,
                     const std::vector<std::pair<int, int>>& pairs,
                     ba::BaProblem* two_step,
                     ba::BaProblem* with_prior,
                     std::vector<std::pair<int, int>>* two_step_pairs) {
  *two_step = ObjectViewsOnly(bp, pairs, two_step_pairs);
  *with_prior = *two_step;
  for (size_t g = 0; g < bp.groups.size(); ++g) {
    const std::array<double, kNumIntrinsics> x = calibration.GroupIntrinsics(static_cast<int>(g));
    const Eigen::MatrixXd C = calibration.GroupIntrinsicsCovariance(static_cast<int>(g));
    ba::IntrinsicsGroup& g2 = two_step->groups[g];
    g2.initial = x;
    g2.free.fill(false);
    g2.has_prior = false;
    ba::IntrinsicsGroup& g3 = with_prior->groups[g];
    g3.initial = x;
    g3.has_prior = true;
    g3.prior.mean = x;
    g3.prior.indices.clear();
    for (int i = 0; i < kNumIntrinsics; ++i) {
      if (g3.free[i]) g3.prior.indices.push_back(i);
    }
    const int n = static_cast<int>(g3.prior.indices.size());
    g3.prior.covariance.resize(n, n);
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < n; ++j)
        g3.prior.covariance(i, j) = C(g3.prior.indices[i], g3.prior.indices[j]);
    }
  }
}

// The joint solve against the two-step one (calibration alone, then the object views with its
// intrinsics held, or with its covariance as prior): sol->comparison, or why it is missing.
void CompareWithTwoStep(const Problem& problem, const ba::BaOptions& options, JointSolution* sol) {
  if (problem.object_views.empty() || problem.plate.views.empty()) {
    sol->comparison_error = "needs both plate and object views";
    return;
  }
  if (problem.smooth) {
    sol->comparison_error = "not built for the smooth intrinsics model";
    return;
  }
  const ba::BaProblem& bp = sol->ba_problem;
  sol->comparison.push_back(SigmasOf("joint", bp, sol->result, sol->pairs));
  ba::BaProblem calib = bp;
  calib.views.erase(
      std::remove_if(calib.views.begin(),
                     calib.views.end(),
                     [](const ba::BaView& v) { return v.kind == ba::ViewKind::kObject; }),
      calib.views.end());
  calib.markers.clear();
  auto rc = ba::SolveBundleAdjustment(calib, options);
  if (!rc.ok()) {
    sol->comparison_error = "calibration alone: " + rc.status().message();
    return;
  }
  std::vector<std::pair<int, int>> pairs2;
  ba::BaProblem two_step, with_prior;
  TwoStepProblems(bp, *rc, sol->pairs, &two_step, &with_prior, &pairs2);
  auto r2 = ba::SolveBundleAdjustment(two_step, options);
  auto r3 = ba::SolveBundleAdjustment(with_prior, options);
  if (!r2.ok() || !r3.ok()) {
    sol->comparison_error =
        "two-step: " + (r2.ok() ? r3.status().message() : r2.status().message());
    return;
  }
  sol->comparison.push_back(SigmasOf("two-step (intrinsics fixed)", two_step, *r2, pairs2));
  sol->comparison.push_back(
      SigmasOf("two-step with the calibration's covariance as prior", with_prior, *r3, pairs2));
}

}  // namespace

StatusOr<JointSolution> SolveJointProblem(const Problem& problem, const SolverConfig& config) {
  CARMBA_RETURN_IF_ERROR(CheckJointConfig(config));
  if (!problem.plate.views.empty() && !(problem.plate_sigma_px > 0)) {
    return Status::Error(problem.path +
                         ": key 'plate_views.sigma_px': missing (the plate points' detection "
                         "noise in px, 1 sigma per coordinate; `carmba solve` needs it)");
  }
  JointSolution sol;
  CARMBA_RETURN_IF_ERROR(JointBaProblem(problem, config, &sol));
  const ba::BaOptions options = config.ToBaOptions();
  CARMBA_RETURN_IF_ERROR(ApplyModels(problem, config, options, &sol));
  const ba::BaProblem& bp = sol.ba_problem;
  auto r = ba::SolveBundleAdjustment(bp, options);
  if (!r.ok()) return Status::Error(problem.path + ": " + r.status().message());
  sol.result = std::move(*r);
  analysis::DistortionModel solved;
  if (sol.distortion && !config.distortion_auto &&
      analysis::DistortionModelOf(bp.groups[0].free, &solved)) {
    const std::array<double, kNumIntrinsics> K = sol.result.GroupIntrinsics(0);
    sol.distortion_warning =
        analysis::DistortionWarning(*sol.distortion, solved, Eigen::Vector2d(K[kCx], K[kCy]));
  }
  sol.budget = ba::ComputeErrorBudget(bp, sol.result, sol.pairs);
  sol.relative_poses =
      analysis::EstimateRelativePoses(sol.result, analysis::RelativePosePairs(bp, sol.pairs));
  if (config.tre) {
    auto tre = analysis::LeaveOneMarkerOut(bp, sol.result, options);
    if (!tre.ok()) return Status::Error(problem.path + ": " + tre.status().message());
    sol.tre = *tre;
  }
  CompareWithTwoStep(problem, options, &sol);
  return sol;
}

}  // namespace carmba
