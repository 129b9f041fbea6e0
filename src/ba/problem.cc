#include "ba/problem.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "camera/camera.h"

namespace carmba {
namespace ba {

const char* SourceName(Source s) {
  switch (s) {
    case Source::kPlatePixels: return "plate pixels";
    case Source::kObjectPixels: return "object pixels";
    case Source::kCt: return "CT localisation";
    case Source::kPlateManufacturing: return "plate manufacturing";
    case Source::kIntrinsicsPrior: return "intrinsics prior";
    case Source::kCalibration: return "calibration (intrinsics)";
  }
  return "?";
}

namespace {

// One intrinsics group on its own: finite intrinsics with fx, fy > 0, a consistent smooth model,
// aspect-ratio tie and prior.
Status CheckIntrinsicsGroup(const IntrinsicsGroup& g) {
  for (double x : g.initial) {
    if (!std::isfinite(x)) return Status::Error("group '" + g.name + "': non-finite intrinsics");
  }
  if (!(g.initial[kFx] > 0) || !(g.initial[kFy] > 0)) {
    return Status::Error("group '" + g.name + "': fx and fy must be > 0");
  }
  if (g.smooth && g.has_prior) {
    return Status::Error("group '" + g.name + "': an intrinsics prior is not supported with the "
                         "smooth (angle-dependent) model");
  }
  if (g.smooth && (g.basis.primary_order < 0 || g.basis.secondary_degree < 0)) {
    return Status::Error("group '" + g.name + "': the smooth basis needs orders >= 0");
  }
  if (g.smooth && !g.initial_coefficients.empty() &&
      static_cast<int>(g.initial_coefficients.size()) != g.basis.BlockSize()) {
    return Status::Error("group '" + g.name +
                         "': " + std::to_string(g.initial_coefficients.size()) +
                         " initial coefficients, expected " + std::to_string(g.basis.BlockSize()));
  }
  if (g.smooth && g.fy_over_fx != 0) {
    return Status::Error("group '" + g.name + "': a fixed aspect ratio (fy_over_fx) is not "
                         "supported with the smooth (angle-dependent) model");
  }
  if (g.fy_over_fx != 0) {
    if (!(g.fy_over_fx > 0) || !std::isfinite(g.fy_over_fx)) {
      return Status::Error("group '" + g.name + "': fy_over_fx must be > 0 (0: fy free)");
    }
    if (std::abs(g.initial[kFy] - g.fy_over_fx * g.initial[kFx]) > 1e-9 * g.initial[kFy]) {
      return Status::Error("group '" + g.name + "': the initial fy is not fy_over_fx * fx");
    }
    if (g.free[kFx] != g.free[kFy]) {
      return Status::Error("group '" + g.name +
                           "': with a fixed aspect ratio fx and fy are free or held together");
    }
  }
  if (g.has_prior) {
    const auto n = static_cast<Eigen::Index>(g.prior.indices.size());
    if (n == 0 || g.prior.covariance.rows() != n || g.prior.covariance.cols() != n ||
        !g.prior.covariance.allFinite()) {
      return Status::Error("group '" + g.name + "': the intrinsics prior needs a finite " +
                           std::to_string(n) + "x" + std::to_string(n) + " covariance");
    }
    Eigen::LLT<Eigen::MatrixXd> llt(g.prior.covariance);
    if (llt.info() != Eigen::Success) {
      return Status::Error("group '" + g.name +
                           "': the intrinsics prior's covariance is not positive definite");
    }
  }
  return Status::Ok();
}

// A group's considered calibration: a finite, symmetric positive semi-definite covariance over
// distinct held intrinsics.
Status CheckConsideredCalibration(const IntrinsicsGroup& g) {
  const auto n = static_cast<Eigen::Index>(g.consider_indices.size());
  if (n == 0 && g.consider_covariance.size() == 0) return Status::Ok();
  if (n == 0 || g.consider_covariance.rows() != n || g.consider_covariance.cols() != n ||
      !g.consider_covariance.allFinite()) {
    return Status::Error("group '" + g.name + "': the considered calibration needs a finite " +
                         std::to_string(n) + "x" + std::to_string(n) + " covariance");
  }
  if (g.smooth) {
    return Status::Error("group '" + g.name + "': a considered calibration is not supported with "
                         "the smooth (angle-dependent) model");
  }
  std::set<int> distinct;
  for (int i : g.consider_indices) {
    if (i < 0 || i >= kNumIntrinsics || !distinct.insert(i).second) {
      return Status::Error("group '" + g.name + "': considered intrinsic index " +
                           std::to_string(i) + " is out of range or given twice");
    }
    const bool held = !g.free[i] && !(i == kFy && g.fy_over_fx > 0 && g.free[kFx]);
    if (!held) {
      return Status::Error("group '" + g.name + "': intrinsic " + kIntrinsicNames[i] +
                           " is free: only held intrinsics are considered");
    }
  }
  if (!g.consider_covariance.isApprox(g.consider_covariance.transpose(), 1e-9) ||
      Eigen::LDLT<Eigen::MatrixXd>(g.consider_covariance).info() != Eigen::Success ||
      !(Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(g.consider_covariance)
            .eigenvalues()
            .minCoeff() >= 0)) {
    return Status::Error("group '" + g.name +
                         "': the considered calibration covariance is not symmetric positive "
                         "semi-definite");
  }
  return Status::Ok();
}

// One view against the problem: its group and rig, sigmas and covariances, at least 4
// observations (1 in a rig), each of a known point or marker, once, with a finite pixel; C-arm
// angles when its group is smooth.
Status CheckBaView(const BaProblem& p,
                   const BaView& v,
                   const std::map<int, const BaMarker*>& marker_by_id,
                   std::vector<int>* rig_observations) {
  const auto& groups = p.groups;
  const auto& rigs = p.rigs;
  const auto& plate = p.plate;
  if (v.group < 0 || v.group >= static_cast<int>(groups.size())) {
    return Status::Error("view '" + v.id + "': unknown intrinsics group");
  }
  if (!(v.sigma_px > 0) || !std::isfinite(v.sigma_px)) {
    return Status::Error("view '" + v.id + "': sigma_px must be > 0");
  }
  if (v.point_ids.size() != v.uv_px.size()) {
    return Status::Error("view '" + v.id + "': ids and pixels differ in number");
  }
  if (!v.obs_sigma_px.empty() && v.obs_sigma_px.size() != v.uv_px.size()) {
    return Status::Error("view '" + v.id + "': per-observation sigmas and pixels differ in number");
  }
  for (double s : v.obs_sigma_px) {
    if (!(s > 0) || !std::isfinite(s)) {
      return Status::Error("view '" + v.id + "': a per-observation sigma_px is not > 0");
    }
  }
  if (!v.obs_covariance_px2.empty() && v.obs_covariance_px2.size() != v.uv_px.size()) {
    return Status::Error("view '" + v.id +
                         "': per-observation covariances and pixels differ in number");
  }
  for (const Eigen::Matrix2d& C : v.obs_covariance_px2) {
    if (!C.allFinite() || std::abs(C(0, 1) - C(1, 0)) > 1e-12 * (C(0, 0) + C(1, 1)) ||
        !(C(0, 0) > 0) || !(C.determinant() > 0)) {
      return Status::Error("view '" + v.id +
                           "': a per-observation pixel covariance is not symmetric positive "
                           "definite");
    }
  }
  if (v.rig >= static_cast<int>(rigs.size()) || v.rig < -1) {
    return Status::Error("view '" + v.id + "': unknown rig " + std::to_string(v.rig));
  }
  if (v.rig >= 0) {
    if (v.kind != ViewKind::kObject)
      return Status::Error("view '" + v.id + "': only object views can be in a rig");
    if (!v.cam_from_rig.allFinite())
      return Status::Error("view '" + v.id + "': non-finite cam_from_rig");
    if (groups[v.group].smooth) {
      return Status::Error("view '" + v.id + "': a rig view's intrinsics group cannot be smooth");
    }
    (*rig_observations)[v.rig] += static_cast<int>(v.point_ids.size());
  }
  if (v.point_ids.size() < (v.rig >= 0 ? 1u : 4u)) {
    return Status::Error("view '" + v.id + "': " + std::to_string(v.point_ids.size()) +
                         " observation(s), at least " + (v.rig >= 0 ? "1" : "4") + " needed");
  }
  if (!v.initial.allFinite()) return Status::Error("view '" + v.id + "': no initial pose");
  std::set<int> seen;
  for (size_t i = 0; i < v.point_ids.size(); ++i) {
    const int id = v.point_ids[i];
    if (!seen.insert(id).second) {
      return Status::Error("view '" + v.id + "': point " + std::to_string(id) +
                           " observed twice");
    }
    if (!v.uv_px[i].allFinite()) {
      return Status::Error("view '" + v.id + "': non-finite pixel of point " +
                           std::to_string(id));
    }
    if (v.kind == ViewKind::kPlate) {
      if (id < 0 || id >= static_cast<int>(plate.points.size())) {
        return Status::Error("view '" + v.id + "': plate point " + std::to_string(id) +
                             " is not on the plate (" + std::to_string(plate.points.size()) +
                             " points)");
      }
    } else if (!marker_by_id.count(id)) {
      return Status::Error("view '" + v.id + "': marker " + std::to_string(id) +
                           " is not among the fiducials");
    }
  }
  if (groups[v.group].smooth) {
    if (!v.has_angles) {
      return Status::Error("view '" + v.id + "' has no C-arm angles, but its intrinsics group '" +
                           groups[v.group].name +
                           "' is smooth (intrinsics as functions of the angles)");
    }
    if (!std::isfinite(v.primary_deg) || !std::isfinite(v.secondary_deg)) {
      return Status::Error("view '" + v.id + "': non-finite C-arm angles");
    }
  }
  return Status::Ok();
}

// A smooth group's plate views cover enough orientations, primary and secondary angles for its
// basis.
Status CheckSmoothCoverage(const IntrinsicsGroup& group, int g, const std::vector<BaView>& views) {
  const SmoothBasis& basis = group.basis;
  std::set<std::pair<long, long>> orientations;
  std::set<long> primaries, secondaries;
  for (const auto& v : views) {
    if (v.group != g || v.kind != ViewKind::kPlate) continue;
    const long a = std::lround(v.primary_deg * 100), b = std::lround(v.secondary_deg * 100);
    orientations.insert({a, b});
    primaries.insert(a);
    secondaries.insert(b);
  }
  const int K = basis.NumTerms();
  if (static_cast<int>(orientations.size()) < K) {
    return Status::Error(
        "intrinsics group '" + group.name + "': model smooth has " + std::to_string(K) +
        " coefficients per intrinsic (Fourier order " + std::to_string(basis.primary_order) +
        " in the primary angle, degree " + std::to_string(basis.secondary_degree) +
        " in the secondary) but the plate views cover " + std::to_string(orientations.size()) +
        " orientation group(s); it needs at least " + std::to_string(K));
  }
  if (static_cast<int>(primaries.size()) < 2 * basis.primary_order + 1 ||
      static_cast<int>(secondaries.size()) < basis.secondary_degree + 1) {
    return Status::Error(
        "intrinsics group '" + group.name + "': model smooth needs plate views at >= " +
        std::to_string(2 * basis.primary_order + 1) + " distinct primary angles (have " +
        std::to_string(primaries.size()) + ") and >= " +
        std::to_string(basis.secondary_degree + 1) + " distinct secondary angles (have " +
        std::to_string(secondaries.size()) + ")");
  }
  return Status::Ok();
}

}  // namespace

Status BaProblem::Check() const {
  if (groups.empty()) return Status::Error("no intrinsics group");
  if (views.empty()) return Status::Error("no views");
  std::set<std::string> group_names;
  for (const auto& g : groups) {
    if (!group_names.insert(g.name).second) {
      return Status::Error("intrinsics group '" + g.name + "' is given twice");
    }
    CARMBA_RETURN_IF_ERROR(CheckIntrinsicsGroup(g));
  }
  for (const auto& g : groups) CARMBA_RETURN_IF_ERROR(CheckConsideredCalibration(g));
  std::set<std::string> view_ids;
  std::map<int, const BaMarker*> marker_by_id;
  for (const auto& m : markers) {
    if (!marker_by_id.emplace(m.id, &m).second) {
      return Status::Error("marker " + std::to_string(m.id) + " is given twice");
    }
    if (!m.p_ct.allFinite() || !m.covariance.allFinite()) {
      return Status::Error("marker " + std::to_string(m.id) +
                           ": non-finite position or covariance");
    }
  }
  std::set<std::string> rig_ids;
  for (const auto& r : rigs) {
    if (!rig_ids.insert(r.id).second) return Status::Error("rig '" + r.id + "' is given twice");
    if (!r.initial.allFinite()) return Status::Error("rig '" + r.id + "': no initial pose");
  }
  std::vector<int> rig_observations(rigs.size(), 0);
  std::vector<int> plate_views_of(groups.size(), 0), views_of(groups.size(), 0);
  for (const auto& v : views) {
    if (!view_ids.insert(v.id).second) return Status::Error("view '" + v.id + "' is given twice");
    CARMBA_RETURN_IF_ERROR(CheckBaView(*this, v, marker_by_id, &rig_observations));
    ++views_of[v.group];
    if (v.kind == ViewKind::kPlate) ++plate_views_of[v.group];
  }
  for (size_t g = 0; g < groups.size(); ++g) {
    if (groups[g].smooth)
      CARMBA_RETURN_IF_ERROR(CheckSmoothCoverage(groups[g], static_cast<int>(g), views));
  }
  for (size_t r = 0; r < rigs.size(); ++r) {
    if (rig_observations[r] < 4) {
      return Status::Error("rig '" + rigs[r].id + "': " + std::to_string(rig_observations[r]) +
                           " observation(s) over its views, at least 4 needed");
    }
  }
  for (size_t g = 0; g < groups.size(); ++g) {
    if (views_of[g] == 0) {
      return Status::Error("intrinsics group '" + groups[g].name + "' has no views");
    }
    bool any_free = false;
    for (bool f : groups[g].free) any_free |= f;
    if (any_free && plate_views_of[g] == 0 && !groups[g].has_prior) {
      return Status::Error("intrinsics group '" + groups[g].name +
                           "' has no plate views and no prior: its intrinsics are not "
                           "calibrated (add plate views of that group, or a camera prior)");
    }
  }
  if (plate.free && !(plate.sigma_mm >= 0 && std::isfinite(plate.sigma_mm))) {
    return Status::Error("the plate's manufacturing sigma_mm must be >= 0 (0: no prior)");
  }
  for (double r : {marker_radius_mm, plate.sphere_radius_mm}) {
    if (!(r >= 0 && r <= 100)) {
      return Status::Error("a sphere radius must be in 0 .. 100 mm (0: unknown), not " +
                           std::to_string(r));
    }
  }
  return Status::Ok();
}

StateLayout::StateLayout(const BaProblem& problem) {
  auto add = [&](BlockKind kind, int index, int size, std::string label, bool constant,
                 std::vector<int> free) {
    BlockInfo b;
    b.kind = kind;
    b.index = index;
    b.offset = buffer_size_;
    b.size = size;
    b.label = std::move(label);
    b.constant = constant || free.empty();
    if (!b.constant) {
      b.basis = Eigen::MatrixXd::Zero(size, static_cast<Eigen::Index>(free.size()));
      for (size_t c = 0; c < free.size(); ++c) b.basis(free[c], static_cast<Eigen::Index>(c)) = 1.0;
      b.free = std::move(free);
      b.free_offset = num_free_;
      for (size_t i = 0; i < b.free.size(); ++i) {
        free_index_.emplace_back(static_cast<int>(blocks_.size()), b.free[i]);
      }
      num_free_ += static_cast<int>(b.free.size());
    }
    buffer_size_ += size;
    blocks_.push_back(std::move(b));
    return static_cast<int>(blocks_.size()) - 1;
  };
  auto all = [](int n) {
    std::vector<int> v(n);
    for (int i = 0; i < n; ++i) v[i] = i;
    return v;
  };
  const bool one_group = problem.groups.size() == 1;
  int nc = 0;
  for (const auto& grp : problem.groups) nc += static_cast<int>(grp.consider_indices.size());
  consider_covariance_ = Eigen::MatrixXd::Zero(nc, nc);
  for (size_t g = 0; g < problem.groups.size(); ++g) {
    const IntrinsicsGroup& grp = problem.groups[g];
    // A smooth group's block holds its basis coefficients (coefficient j free if its intrinsic
    // is); a fixed aspect ratio ties fy to fx (refused with smooth by Check()).
    const bool tied = !grp.smooth && grp.fy_over_fx > 0;
    std::vector<int> free;
    for (int i = 0; i < grp.BlockSize(); ++i) {
      const int intrinsic = grp.smooth ? grp.basis.IntrinsicOf(i) : i;
      if (grp.free[intrinsic] && !(tied && intrinsic == kFy)) free.push_back(i);
    }
    const int b = add(BlockKind::kIntrinsics, static_cast<int>(g), grp.BlockSize(),
                      one_group ? "" : grp.name, false, free);
    group_block_.push_back(b);
    BlockInfo& bi = blocks_[b];
    if (grp.smooth) {
      for (int i = 0; i < grp.BlockSize(); ++i)
        bi.parameter_names.push_back(grp.basis.ParameterName(i));
    }
    const auto fx = std::find(bi.free.begin(), bi.free.end(), kFx);
    if (tied && fx != bi.free.end()) {
      bi.basis(kFy, fx - bi.free.begin()) = grp.fy_over_fx;
      bi.selection = false;
    }
    if (!grp.consider_indices.empty()) {
      const auto k = static_cast<Eigen::Index>(grp.consider_indices.size());
      bi.consider = grp.consider_indices;
      bi.consider_offset = num_consider_;
      consider_covariance_.block(num_consider_, num_consider_, k, k) = grp.consider_covariance;
      for (int i : grp.consider_indices) consider_index_.emplace_back(b, i);
      num_consider_ += static_cast<int>(k);
    }
  }
  view_block_.assign(problem.views.size(), -1);
  for (ViewKind kind : {ViewKind::kPlate, ViewKind::kObject}) {
    for (size_t v = 0; v < problem.views.size(); ++v) {
      if (problem.views[v].kind != kind || problem.views[v].rig >= 0) continue;
      view_block_[v] =
          add(kind == ViewKind::kPlate ? BlockKind::kPlatePose : BlockKind::kObjectPose,
              static_cast<int>(v),
              6,
              (kind == ViewKind::kPlate ? "plate " : "view ") + problem.views[v].id,
              false,
              all(6));
    }
  }
  for (size_t r = 0; r < problem.rigs.size(); ++r) {
    rig_block_.push_back(add(BlockKind::kRigPose, static_cast<int>(r), 6,
                             "rig " + problem.rigs[r].id, problem.rigs[r].constant, all(6)));
  }
  for (size_t v = 0; v < problem.views.size(); ++v) {
    if (problem.views[v].rig >= 0) view_block_[v] = rig_block_[problem.views[v].rig];
  }
  for (size_t m = 0; m < problem.markers.size(); ++m) {
    marker_block_.push_back(add(BlockKind::kMarker, static_cast<int>(m), 3,
                                "marker " + std::to_string(problem.markers[m].id),
                                !problem.markers_free, all(3)));
  }
  for (size_t p = 0; p < problem.plate.points.size(); ++p) {
    plate_point_block_.push_back(add(BlockKind::kPlatePoint, static_cast<int>(p), 3,
                                     "plate point " + std::to_string(p), !problem.plate.free,
                                     all(3)));
  }
}

double BaView::SigmaPx(size_t i) const {
  if (!obs_covariance_px2.empty()) {
    const Eigen::Matrix2d& C = obs_covariance_px2[i];
    // Larger eigenvalue of a symmetric 2x2, closed form.
    const double m = 0.5 * (C(0, 0) + C(1, 1));
    const double d = 0.5 * (C(0, 0) - C(1, 1));
    return std::sqrt(m + std::sqrt(d * d + C(0, 1) * C(0, 1)));
  }
  return obs_sigma_px.empty() ? sigma_px : obs_sigma_px[i];
}

Eigen::Matrix2d BaView::CovariancePx2(size_t i) const {
  if (!obs_covariance_px2.empty()) return obs_covariance_px2[i];
  const double s = obs_sigma_px.empty() ? sigma_px : obs_sigma_px[i];
  return s * s * Eigen::Matrix2d::Identity();
}

std::vector<int> BlockInfo::Moving() const {
  std::vector<int> out;
  for (int i = 0; i < static_cast<int>(basis.rows()); ++i) {
    if (!basis.row(i).isZero()) out.push_back(i);
  }
  return out;
}

std::string StateLayout::ParameterName(int b, int i) const {
  static const char* const kPose[6] = {"rx", "ry", "rz", "tx", "ty", "tz"};
  static const char* const kPoint[3] = {"x", "y", "z"};
  const BlockInfo& blk = blocks_[b];
  std::string p;
  if (!blk.parameter_names.empty()) {
    p = blk.parameter_names[i];
    return blk.label.empty() ? p : blk.label + " " + p;
  }
  switch (blk.kind) {
    case BlockKind::kIntrinsics: p = kIntrinsicNames[i]; break;
    case BlockKind::kPlatePose:
    case BlockKind::kObjectPose:
    case BlockKind::kRigPose: p = kPose[i]; break;
    case BlockKind::kMarker:
    case BlockKind::kPlatePoint: p = kPoint[i]; break;
  }
  return blk.label.empty() ? p : blk.label + " " + p;
}

std::string StateLayout::FreeName(int k) const {
  const auto [b, i] = free_index_[k];
  return ParameterName(b, i);
}

CalibrationUncertainty CalibrationUncertaintyOf(const BaProblem& problem) {
  bool considered = false;
  for (const auto& g : problem.groups) {
    for (bool f : g.free) {
      if (f) return CalibrationUncertainty::kEstimated;
    }
    considered |= !g.consider_indices.empty();
  }
  return considered ? CalibrationUncertainty::kConsidered : CalibrationUncertainty::kLeftOut;
}

const char* CalibrationUncertaintyNote(CalibrationUncertainty c) {
  switch (c) {
    case CalibrationUncertainty::kEstimated:
      return "The intrinsics are estimated in the solve: the covariances include the "
             "calibration's uncertainty.";
    case CalibrationUncertainty::kConsidered:
      return "The intrinsics are held at camera.json's values and its covariance is considered: "
             "the covariances include the calibration's uncertainty (its share is the source "
             "'calibration (intrinsics)').";
    case CalibrationUncertainty::kLeftOut:
      return "The intrinsics are held and camera.json has no covariance (or consider_calibration: "
             "false): the covariances leave the calibration's uncertainty out.";
  }
  return "";
}

BaView KeepObservations(const BaView& view, const std::vector<char>& keep) {
  BaView out = view;
  out.point_ids.clear();
  out.uv_px.clear();
  out.obs_sigma_px.clear();
  out.obs_covariance_px2.clear();
  for (size_t i = 0; i < view.point_ids.size(); ++i) {
    if (!keep[i]) continue;
    out.point_ids.push_back(view.point_ids[i]);
    out.uv_px.push_back(view.uv_px[i]);
    if (!view.obs_sigma_px.empty()) out.obs_sigma_px.push_back(view.obs_sigma_px[i]);
    if (!view.obs_covariance_px2.empty())
      out.obs_covariance_px2.push_back(view.obs_covariance_px2[i]);
  }
  return out;
}

std::string StateLayout::ConsiderName(int k) const {
  const auto [b, i] = consider_index_[k];
  return ParameterName(b, i);
}

std::vector<double> InitialState(const BaProblem& problem, const StateLayout& layout) {
  std::vector<double> x(layout.buffer_size());
  for (const BlockInfo& b : layout.blocks()) {
    double* dst = x.data() + b.offset;
    switch (b.kind) {
      case BlockKind::kIntrinsics: {
        const IntrinsicsGroup& g = problem.groups[b.index];
        if (g.smooth) {
          const std::vector<double> c = g.initial_coefficients.empty()
                                            ? g.basis.ConstantCoefficients(g.initial)
                                            : g.initial_coefficients;
          std::copy(c.begin(), c.end(), dst);
        } else {
          std::copy(g.initial.begin(), g.initial.end(), dst);
        }
        break;
      }
      case BlockKind::kPlatePose:
      case BlockKind::kObjectPose:
        for (int i = 0; i < 6; ++i) dst[i] = problem.views[b.index].initial[i];
        break;
      case BlockKind::kRigPose:
        for (int i = 0; i < 6; ++i) dst[i] = problem.rigs[b.index].initial[i];
        break;
      case BlockKind::kMarker:
        for (int i = 0; i < 3; ++i) dst[i] = problem.markers[b.index].p_ct[i];
        break;
      case BlockKind::kPlatePoint:
        for (int i = 0; i < 3; ++i) dst[i] = problem.plate.points[b.index][i];
        break;
    }
  }
  return x;
}

const char* NoiseGroupName(NoiseGroup g) {
  switch (g) {
    case NoiseGroup::kPlatePixels:
      return "plate pixels";
    case NoiseGroup::kObjectPixels:
      return "object pixels";
    case NoiseGroup::kDetectedBlobs:
      return "detected blobs";
    case NoiseGroup::kCt:
      return "CT fiducials";
    case NoiseGroup::kPlateManufacturing:
      return "plate manufacturing";
    case NoiseGroup::kIntrinsicsPrior:
      return "intrinsics prior";
  }
  return "?";
}

const char* NoiseGroupKey(NoiseGroup g) {
  switch (g) {
    case NoiseGroup::kPlatePixels:
      return "plate_pixels";
    case NoiseGroup::kObjectPixels:
      return "object_pixels";
    case NoiseGroup::kDetectedBlobs:
      return "detected_blobs";
    case NoiseGroup::kCt:
      return "ct";
    case NoiseGroup::kPlateManufacturing:
      return "plate_manufacturing";
    case NoiseGroup::kIntrinsicsPrior:
      return "intrinsics_prior";
  }
  return "?";
}

NoiseGroup GroupOf(Source source, const BaView* view) {
  switch (source) {
    case Source::kPlatePixels:
      return NoiseGroup::kPlatePixels;
    case Source::kObjectPixels:
      return view && !view->obs_covariance_px2.empty() ? NoiseGroup::kDetectedBlobs
                                                       : NoiseGroup::kObjectPixels;
    case Source::kCt:
      return NoiseGroup::kCt;
    case Source::kPlateManufacturing:
      return NoiseGroup::kPlateManufacturing;
    case Source::kIntrinsicsPrior:
    case Source::kCalibration:
      return NoiseGroup::kIntrinsicsPrior;
  }
  return NoiseGroup::kIntrinsicsPrior;
}

}  // namespace ba
}  // namespace carmba
