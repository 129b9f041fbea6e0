#include "ba/bundle_adjuster.h"

#include <ceres/ceres.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <limits>
#include <memory>

#include "ba/priors.h"
#include "ba/reprojection_error.h"
#include "ba/schur_lm.h"
#include "ba/smooth_intrinsics.h"
#include "ba/view_intrinsics.h"
#include "util/stats.h"

namespace carmba {
namespace ba {
namespace {

// Ceres's robust-loss correction of a block's Jacobian (ceres/internal/corrector.cc): with
// s = |r|^2 and rho = (rho(s), rho'(s), rho''(s)),
//   J <- sqrt(rho') (I - alpha r r^T / s) J,   alpha = 1 - sqrt(1 + 2 s rho'' / rho'),
// where alpha = 0 if s = 0 or rho'' <= 0.
void CorrectForLoss(const ceres::LossFunction& loss, const Eigen::VectorXd& r, Eigen::MatrixXd* J) {
  const double s = r.squaredNorm();
  double rho[3];
  loss.Evaluate(s, rho);
  const double sqrt_rho1 = std::sqrt(rho[1]);
  if (s == 0.0 || rho[2] <= 0.0) {
    *J *= sqrt_rho1;
    return;
  }
  const double alpha = 1.0 - std::sqrt(1.0 + 2.0 * s * rho[2] / rho[1]);
  const Eigen::MatrixXd P =
      Eigen::MatrixXd::Identity(r.size(), r.size()) - (alpha / s) * r * r.transpose();
  *J = sqrt_rho1 * (P * *J);
}

// A residual block whose rows are divided by `scale` (its group's sigmas times `scale`, the
// per_group variance components): residuals and Jacobians of `inner` times 1 / scale.
class ScaledCost final : public ceres::CostFunction {
 public:
  ScaledCost(const ceres::CostFunction* inner, double scale) : inner_(inner), w_(1.0 / scale) {
    set_num_residuals(inner->num_residuals());
    *mutable_parameter_block_sizes() = inner->parameter_block_sizes();
  }
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    if (!inner_->Evaluate(parameters, residuals, jacobians)) return false;
    const int nr = num_residuals();
    for (int i = 0; i < nr; ++i) residuals[i] *= w_;
    if (!jacobians) return true;
    const auto& sizes = parameter_block_sizes();
    for (size_t b = 0; b < sizes.size(); ++b) {
      if (!jacobians[b]) continue;
      for (int i = 0; i < nr * sizes[b]; ++i) jacobians[b][i] *= w_;
    }
    return true;
  }

 private:
  const ceres::CostFunction* inner_;
  double w_;
};

ceres::LossFunction* MakeLoss(const BaOptions& o, double sigma_px) {
  return MakeLossFunction(o.loss, o.loss_scale_px / sigma_px).release();  // residuals are whitened
}

// Ceres's own conversion (it upper-cases the name: dense_schur -> DENSE_SCHUR).
bool LinearSolverType(const std::string& name, ceres::LinearSolverType* t) {
  return ceres::StringToLinearSolverType(name, t);
}

// One residual block as built: its cost, loss, source, the layout blocks of its parameters and,
// for reprojections, which observation it is.
struct BuiltBlock {
  BuiltBlock(ceres::CostFunction* c, ceres::LossFunction* l, Source s, std::vector<int> b,
             int v = -1, int o = -1, int zero = 0)
      : cost(c), loss(l), source(s), blocks(std::move(b)), view(v), obs(o), zero_rows(zero) {}
  ceres::CostFunction* cost = nullptr;
  ceres::LossFunction* loss = nullptr;
  Source source;
  std::vector<int> blocks;
  int view = -1, obs = -1;
  int zero_rows = 0;  // rows that are zero by construction (the split point prior's third block)
  NoiseGroup group = NoiseGroup::kPlatePixels;
  // A PlateViewReprojection block: the observations of `view` it holds (2 rows each); obs = -1.
  std::vector<int> view_obs;
};

// The residual blocks as built (owned here: a Ceres problem built on them must not take
// ownership) and the parameter buffer.
struct Assembly {
  std::vector<BuiltBlock> built;
  std::vector<double> buffer;
  std::vector<std::unique_ptr<ceres::CostFunction>> costs;
  std::vector<std::unique_ptr<ceres::LossFunction>> losses;
};

// x = x0 + A delta: an affine subspace of a block's parameters (held ones, tied ones such as
// fy = r fx), the block's StateLayout basis.
class AffineSubspaceManifold final : public ceres::Manifold {
 public:
  explicit AffineSubspaceManifold(const Eigen::MatrixXd& A)
      : A_(A), pinv_((A.transpose() * A).inverse() * A.transpose()) {}
  int AmbientSize() const override { return static_cast<int>(A_.rows()); }
  int TangentSize() const override { return static_cast<int>(A_.cols()); }
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override {
    Eigen::Map<Eigen::VectorXd>(x_plus_delta, A_.rows()) =
        Eigen::Map<const Eigen::VectorXd>(x, A_.rows()) +
        A_ * Eigen::Map<const Eigen::VectorXd>(delta, A_.cols());
    return true;
  }
  bool PlusJacobian(const double*, double* jacobian) const override {
    Eigen::Map<RowMat>(jacobian, A_.rows(), A_.cols()) = A_;
    return true;
  }
  bool Minus(const double* y, const double* x, double* y_minus_x) const override {
    Eigen::Map<Eigen::VectorXd>(y_minus_x, A_.cols()) =
        pinv_ * (Eigen::Map<const Eigen::VectorXd>(y, A_.rows()) -
                 Eigen::Map<const Eigen::VectorXd>(x, A_.rows()));
    return true;
  }
  bool MinusJacobian(const double*, double* jacobian) const override {
    Eigen::Map<RowMat>(jacobian, A_.cols(), A_.rows()) = pinv_;
    return true;
  }

 private:
  using RowMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  Eigen::MatrixXd A_, pinv_;
};

ceres::Problem::Options ProblemOptions(ceres::Context* context) {
  ceres::Problem::Options popts;
  popts.context = context;
  popts.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  popts.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  popts.manifold_ownership = ceres::TAKE_OWNERSHIP;
  popts.disable_all_safety_checks = true;
  return popts;
}

// Builds the residual blocks of `problem` (skipping observations in `dropped`) into an Assembly
// and adds them to `cp` unless it is null (the carmba_lm back end evaluates them without Ceres).
// One stage per kind of block; Assemble below runs them in order.
class Assembler {
 public:
  Assembler(const BaProblem& problem, const StateLayout& layout, const BaOptions& o,
            const std::vector<std::vector<char>>& dropped, Assembly* as, ceres::Problem* cp)
      : problem_(problem), layout_(layout), o_(o), dropped_(dropped), as_(as), cp_(cp) {
    for (size_t m = 0; m < problem.markers.size(); ++m)
      marker_index_[problem.markers[m].id] = static_cast<int>(m);
  }

  Status AddView(int v) {
    const BaView& view = problem_.views[v];
    const bool smooth = problem_.groups[view.group].smooth;
    if (view.kind == ViewKind::kPlate && !problem_.plate.free && o_.loss == Loss::kTrivial &&
        o_.analytic_jacobians && view.obs_sigma_px.empty() && view.obs_covariance_px2.empty() &&
        !smooth) {
      AddHeldPlateView(v);
      return Status::Ok();
    }
    const Eigen::MatrixXd A = smooth ? ViewIntrinsicsMap(problem_, v) : Eigen::MatrixXd();
    for (size_t i = 0; i < view.point_ids.size(); ++i) {
      if (dropped_[v][i]) continue;
      CARMBA_RETURN_IF_ERROR(AddObservation(v, static_cast<int>(i), A));
    }
    return Status::Ok();
  }

  Status AddMarkerPriors() {
    if (!problem_.markers_free || !problem_.marker_priors) return Status::Ok();
    for (size_t m = 0; m < problem_.markers.size(); ++m) {
      Eigen::Matrix3d S;
      if (!SqrtInformation(problem_.markers[m].covariance, &S)) {
        return Status::Error("marker " + std::to_string(problem_.markers[m].id) +
                             ": CT covariance is not symmetric positive definite");
      }
      AddPointPrior(
          layout_.marker_block(static_cast<int>(m)), problem_.markers[m].p_ct, S, Source::kCt);
    }
    return Status::Ok();
  }

  void AddPlatePriors() {
    if (!problem_.plate.free || !(problem_.plate.sigma_mm > 0)) return;
    const Eigen::Matrix3d S = Eigen::Matrix3d::Identity() / problem_.plate.sigma_mm;
    for (size_t p = 0; p < problem_.plate.points.size(); ++p) {
      AddPointPrior(layout_.plate_point_block(static_cast<int>(p)), problem_.plate.points[p], S,
                    Source::kPlateManufacturing);
    }
  }

  Status AddIntrinsicsPriors() {
    for (size_t g = 0; g < problem_.groups.size(); ++g) {
      const IntrinsicsGroup& grp = problem_.groups[g];
      if (!grp.has_prior) continue;
      Eigen::MatrixXd S;
      if (!SqrtInformationN(grp.prior.covariance, &S)) {
        return Status::Error("group '" + grp.name +
                             "': intrinsics prior covariance is not symmetric positive definite");
      }
      const int b = layout_.group_block(static_cast<int>(g));
      ceres::CostFunction* c =
          o_.analytic_jacobians
              ? static_cast<ceres::CostFunction*>(
                    new IntrinsicsPriorError(grp.prior.mean.data(), grp.prior.indices, S))
              : IntrinsicsPriorAutoDiff::Create(grp.prior.mean.data(), grp.prior.indices, S);
      AddPrior(c, Source::kIntrinsicsPrior, b, 0);
    }
    return Status::Ok();
  }

  // Held parameters: constant blocks, affine subspaces (ties), subsets.
  void HoldParameters() {
    if (!cp_) return;
    for (const BlockInfo& b : layout_.blocks()) {
      double* p = as_->buffer.data() + b.offset;
      if (!cp_->HasParameterBlock(p)) continue;
      if (b.constant) {
        cp_->SetParameterBlockConstant(p);
      } else if (!b.selection) {
        cp_->SetManifold(p, new AffineSubspaceManifold(b.basis));
      } else if (static_cast<int>(b.free.size()) < b.size) {
        std::vector<int> held;
        for (int i = 0; i < b.size; ++i) {
          if (std::find(b.free.begin(), b.free.end(), i) == b.free.end()) held.push_back(i);
        }
        cp_->SetManifold(p, new ceres::SubsetManifold(b.size, held));
      }
    }
  }

 private:
  double* Ptr(int b) const { return as_->buffer.data() + layout_.block(b).offset; }
  void Own(ceres::CostFunction* c, ceres::LossFunction* l) {
    as_->costs.emplace_back(c);
    if (l) as_->losses.emplace_back(l);
  }
  // The cost as solved: `c` (owned) with its group's sigma scale applied.
  ceres::CostFunction* Scaled(ceres::CostFunction* c, NoiseGroup g) {
    const double k = o_.group_sigma_scale[static_cast<int>(g)];
    if (k == 1.0) return c;
    auto* w = new ScaledCost(c, k);
    as_->costs.emplace_back(w);
    return w;
  }

  // The held plate without a loss: the whole view in one block (ba/reprojection_error.h; not for
  // a smooth group: the block takes the 9 intrinsics, the group holds coefficients).
  void AddHeldPlateView(int v) {
    const BaView& view = problem_.views[v];
    std::vector<Eigen::Vector3d> p;
    std::vector<Eigen::Vector2d> uv;
    std::vector<int> kept;
    for (size_t i = 0; i < view.point_ids.size(); ++i) {
      if (dropped_[v][i]) continue;
      p.push_back(problem_.plate.points[view.point_ids[i]]);
      uv.push_back(view.uv_px[i]);
      kept.push_back(static_cast<int>(i));
    }
    if (kept.empty()) return;
    const int pose_b = layout_.view_block(v), intr_b = layout_.group_block(view.group);
    auto* inner = new PlateViewReprojection(std::move(p), std::move(uv), view.sigma_px);
    Own(inner, nullptr);
    ceres::CostFunction* cost = Scaled(inner, NoiseGroup::kPlatePixels);
    if (cp_) cp_->AddResidualBlock(cost, nullptr, Ptr(pose_b), Ptr(intr_b));
    BuiltBlock bb(cost, nullptr, Source::kPlatePixels, {pose_b, intr_b}, v);
    bb.view_obs = std::move(kept);
    as_->built.push_back(std::move(bb));
  }

  // Observation i of view v: its reprojection residual (smooth, rig or plain; analytic or
  // autodiff), whitened by its 2x2 covariance or sigma. A smooth group's residual whitens
  // isotropically (SigmaPx: the larger eigenvalue of a 2x2 covariance, a conservative bound).
  Status AddObservation(int v, int i, const Eigen::MatrixXd& A) {
    const BaView& view = problem_.views[v];
    const int pose_b = layout_.view_block(v), intr_b = layout_.group_block(view.group);
    const int point_b = view.kind == ViewKind::kPlate
                            ? layout_.plate_point_block(view.point_ids[i])
                            : layout_.marker_block(marker_index_.at(view.point_ids[i]));
    const Eigen::Vector2d& q = view.uv_px[i];
    PixelWhitening w = PixelWhitening::Isotropic(view.SigmaPx(i));
    if (!view.obs_covariance_px2.empty() &&
        !PixelWhitening::FromCovariance(view.obs_covariance_px2[i], &w)) {
      return Status::Error("view '" + view.id + "' point " + std::to_string(view.point_ids[i]) +
                           ": the pixel covariance is not symmetric positive definite");
    }
    const Source source =
        view.kind == ViewKind::kPlate ? Source::kPlatePixels : Source::kObjectPixels;
    const NoiseGroup group = GroupOf(source, &view);
    const double sigma_scale = o_.group_sigma_scale[static_cast<int>(group)];
    const bool analytic = o_.analytic_jacobians;
    ceres::CostFunction* inner =
        problem_.groups[view.group].smooth
            ? (analytic ? static_cast<ceres::CostFunction*>(
                              new SmoothReprojectionError(q.x(), q.y(), view.SigmaPx(i), A))
                        : SmoothReprojectionErrorAutoDiff::Create(q.x(), q.y(), view.SigmaPx(i), A))
        : view.rig >= 0 ? (analytic ? static_cast<ceres::CostFunction*>(new RigReprojectionError(
                                          q.x(), q.y(), w, view.cam_from_rig.data()))
                                    : RigReprojectionErrorAutoDiff::Create(
                                          q.x(), q.y(), w, view.cam_from_rig.data()))
        : analytic      ? ReprojectionError::Create(q.x(), q.y(), w)
                        : ReprojectionErrorAutoDiff::Create(q.x(), q.y(), w);
    ceres::LossFunction* loss = MakeLoss(o_, view.SigmaPx(i) * sigma_scale);
    Own(inner, loss);
    ceres::CostFunction* cost = Scaled(inner, group);
    if (cp_) cp_->AddResidualBlock(cost, loss, Ptr(pose_b), Ptr(point_b), Ptr(intr_b));
    as_->built.emplace_back(cost, loss, source, std::vector<int>{pose_b, point_b, intr_b}, v, i);
    as_->built.back().group = group;
    return Status::Ok();
  }

  // A prior's residual block, scaled by its group's sigma scale.
  void AddPrior(ceres::CostFunction* c, Source s, int b, int zero_rows) {
    Own(c, nullptr);
    const NoiseGroup g = GroupOf(s, nullptr);
    ceres::CostFunction* cost = Scaled(c, g);
    if (cp_) cp_->AddResidualBlock(cost, nullptr, Ptr(b));
    as_->built.push_back({cost, nullptr, s, {b}, -1, -1, zero_rows});
    as_->built.back().group = g;
  }

  void AddPointPrior(int b, const Eigen::Vector3d& p, const Eigen::Matrix3d& S, Source s) {
    const auto [rows01, row2] = PointPriorRows::Split(p, S);
    if (o_.analytic_jacobians) {
      AddPrior(rows01, s, b, 0);
      AddPrior(row2, s, b, 1);
      return;
    }
    Eigen::Matrix<double, 2, 3> top = S.topRows<2>(), last = Eigen::Matrix<double, 2, 3>::Zero();
    last.row(0) = S.row(2);
    delete rows01;
    delete row2;
    int zero_rows = 0;
    for (const auto& A : {top, last}) {
      AddPrior(PointPriorRowsAutoDiff::Create(p, A), s, b, zero_rows);
      zero_rows = 1;
    }
  }

  const BaProblem& problem_;
  const StateLayout& layout_;
  const BaOptions& o_;
  const std::vector<std::vector<char>>& dropped_;
  Assembly* as_;
  ceres::Problem* cp_;
  std::map<int, int> marker_index_;
};

Status Assemble(const BaProblem& problem,
                const StateLayout& layout,
                const BaOptions& o,
                const std::vector<std::vector<char>>& dropped,
                Assembly* as,
                ceres::Problem* cp) {
  Assembler assembler(problem, layout, o, dropped, as, cp);
  for (size_t v = 0; v < problem.views.size(); ++v) {
    CARMBA_RETURN_IF_ERROR(assembler.AddView(static_cast<int>(v)));
  }
  CARMBA_RETURN_IF_ERROR(assembler.AddMarkerPriors());
  assembler.AddPlatePriors();
  CARMBA_RETURN_IF_ERROR(assembler.AddIntrinsicsPriors());
  assembler.HoldParameters();
  return Status::Ok();
}

// Evaluates one built block at the buffer: whitened residual and (optionally) the free-column
// Jacobians, corrected for its loss. False if not evaluable.
bool EvaluateBlock(const BuiltBlock& bb,
                   const StateLayout& layout,
                   const std::vector<double>& buffer,
                   Eigen::VectorXd* r,
                   LinearizedBlock* lin) {
  using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const int nr = bb.cost->num_residuals();
  const auto& sizes = bb.cost->parameter_block_sizes();
  constexpr size_t kMaxBlocks = 4;  // the residual kinds touch at most 3 blocks
  if (bb.blocks.size() > kMaxBlocks) return false;
  const double* params[kMaxBlocks];
  double* jac[kMaxBlocks];
  for (size_t i = 0; i < bb.blocks.size(); ++i) {
    params[i] = buffer.data() + layout.block(bb.blocks[i]).offset;
  }
  r->resize(nr);
  // Scratch for the ambient Jacobians (this is called once per residual block per solve).
  thread_local std::vector<double> scratch;
  if (lin) {
    size_t total = 0;
    for (int s : sizes) total += static_cast<size_t>(nr) * s;
    if (scratch.size() < total) scratch.resize(total);
    size_t at = 0;
    for (size_t i = 0; i < sizes.size(); ++i) {
      jac[i] = scratch.data() + at;
      at += static_cast<size_t>(nr) * sizes[i];
    }
  }
  if (!bb.cost->Evaluate(params, r->data(), lin ? jac : nullptr) || !r->allFinite()) {
    return false;
  }
  if (!lin) return true;
  lin->source = bb.source;
  lin->group = bb.group;
  lin->r = *r;
  lin->blocks.reserve(bb.blocks.size());
  lin->J.reserve(bb.blocks.size());
  for (size_t i = 0; i < bb.blocks.size(); ++i) {
    const BlockInfo& bi = layout.block(bb.blocks[i]);
    if (!bi.consider.empty()) {  // the considered (held) intrinsics' columns
      const Eigen::Map<const RowMajor> Ji(jac[i], nr, sizes[i]);
      lin->consider_block = bb.blocks[i];
      lin->J_consider.resize(nr, static_cast<Eigen::Index>(bi.consider.size()));
      for (size_t c = 0; c < bi.consider.size(); ++c)
        lin->J_consider.col(c) = Ji.col(bi.consider[c]);
      if (bb.loss) CorrectForLoss(*bb.loss, *r, &lin->J_consider);
    }
    if (bi.constant) continue;
    const Eigen::Map<const RowMajor> Ji(jac[i], nr, sizes[i]);
    Eigen::MatrixXd Jf(nr, bi.free.size());
    if (bi.selection) {
      for (size_t c = 0; c < bi.free.size(); ++c) Jf.col(c) = Ji.col(bi.free[c]);
    } else {
      Jf.noalias() = Ji * bi.basis;
    }
    if (bb.loss) CorrectForLoss(*bb.loss, *r, &Jf);
    lin->blocks.push_back(bb.blocks[i]);
    lin->J.push_back(std::move(Jf));
  }
  return true;
}

// The carmba_lm back end serves calibration-structured problems: one intrinsics group, plate
// views only with one pixel sigma, plate points held, no prior, trivial loss, no rejection.
Status CheckCarmbaLm(const BaProblem& p, const BaOptions& o) {
  std::string why;
  auto need = [&](bool ok, const char* what) {
    if (!ok && why.empty()) why = what;
  };
  need(p.groups.size() == 1, "one intrinsics group");
  need(p.groups.empty() || !p.groups[0].smooth, "intrinsics that do not depend on the angles");
  for (const auto& v : p.views) need(v.kind == ViewKind::kPlate, "plate views only");
  for (const auto& v : p.views) {
    need(
        v.sigma_px == p.views[0].sigma_px && v.obs_sigma_px.empty() && v.obs_covariance_px2.empty(),
        "one pixel sigma for all views");
  }
  need(!p.plate.free, "plate points held");
  need(p.groups.empty() || !p.groups[0].has_prior, "no intrinsics prior");
  need(o.loss == Loss::kTrivial, "the trivial loss");
  need(o.reject_sigma == 0, "no outlier rejection");
  if (!why.empty()) {
    return Status::Error("backend carmba_lm (calibration problems) needs " + why +
                         "; use backend: ceres");
  }
  return Status::Ok();
}

// Where a solve starts: at the problem's initial values (kCold), or at the optimum of a nearby
// problem (kWarm: the same observations with other weights, or with their shadow offsets
// removed), where Gauss-Newton steps are good from the first iteration.
enum class Start { kCold, kWarm };

// The trust region of the first step: the options' for a cold start, kNearOptimumTrustRegionRadius
// for a warm one.
double InitialTrustRegionRadius(const BaOptions& o, Start start) {
  return start == Start::kWarm ? kNearOptimumTrustRegionRadius : o.initial_trust_region_radius;
}

Status SolveWithCarmbaLm(const BaProblem& p,
                         const StateLayout& layout,
                         const BaOptions& o,
                         Start start,
                         std::vector<double>* buffer,
                         BaResult* res) {
  std::vector<std::vector<Eigen::Vector3d>> plate(p.views.size());
  std::vector<std::vector<Eigen::Vector2d>> uv(p.views.size());
  std::vector<Pose6> poses(p.views.size());
  for (size_t v = 0; v < p.views.size(); ++v) {
    for (int id : p.views[v].point_ids) plate[v].push_back(p.plate.points[id]);
    uv[v] = p.views[v].uv_px;
    const double* pose =
        buffer->data() + layout.block(layout.view_block(static_cast<int>(v))).offset;
    std::copy(pose, pose + 6, poses[v].begin());
  }
  const BlockInfo& g = layout.block(layout.group_block(0));
  std::array<double, kNumIntrinsics> x;
  std::copy(buffer->data() + g.offset, buffer->data() + g.offset + kNumIntrinsics, x.begin());
  const Eigen::MatrixXd A =
      g.constant ? Eigen::MatrixXd::Zero(kNumIntrinsics, 0) : g.basis;
  LmReport report;
  CARMBA_RETURN_IF_ERROR(SchurLevenbergMarquardt(plate,
                                                 uv,
                                                 A,
                                                 o.max_iterations,
                                                 o.function_tolerance,
                                                 1.0 / InitialTrustRegionRadius(o, start),
                                                 &x,
                                                 &poses,
                                                 &report));
  std::copy(x.begin(), x.end(), buffer->data() + g.offset);
  for (size_t v = 0; v < p.views.size(); ++v) {
    double* pose = buffer->data() + layout.block(layout.view_block(static_cast<int>(v))).offset;
    std::copy(poses[v].begin(), poses[v].end(), pose);
  }
  res->iterations += report.iterations;
  res->termination = report.termination;
  return Status::Ok();
}

}  // namespace

bool BaOptions::Check(std::string* error) const {
  ceres::LinearSolverType t;
  if (!LinearSolverType(linear_solver, &t)) {
    *error = "linear_solver '" + linear_solver + "' is unknown";
    return false;
  }
  if (!(loss_scale_px > 0) || !std::isfinite(loss_scale_px)) {
    *error = "loss scale_px must be > 0";
    return false;
  }
  if (!(initial_trust_region_radius > 0) || !std::isfinite(initial_trust_region_radius)) {
    *error = "initial_trust_region_radius must be > 0 and finite";
    return false;
  }
  if (max_iterations < 0 || num_threads < 1) {
    *error = "max_iterations must be >= 0 and num_threads >= 1";
    return false;
  }
  if (!(outlier_sigma > 0) || !(reject_sigma >= 0)) {
    *error = "outlier_sigma must be > 0 and reject_sigma >= 0";
    return false;
  }
  return true;
}

namespace {

// 0.5 chi2 of the assembled problem at its initial state, evaluated directly; a non-finite
// residual is an error naming where.
// Each observation of a reprojection block with its whitened residual r2 and its pixel residual
// (px; the residual is whitened by the stated sigmas times the group's scale): fn(obs, r2, e_px).
template <typename Fn>
void ForEachObservation(const BaProblem& problem, const BaOptions& o, const BuiltBlock& bb,
                        const Eigen::VectorXd& r, Fn fn) {
  if (bb.view < 0) return;
  const BaView& view = problem.views[bb.view];
  auto one = [&](int obs, const Eigen::Vector2d& r2) {
    PixelWhitening w = PixelWhitening::Isotropic(view.SigmaPx(obs));
    if (!view.obs_covariance_px2.empty() && !problem.groups[view.group].smooth) {
      PixelWhitening::FromCovariance(view.obs_covariance_px2[obs], &w);
    }
    fn(obs, r2, w.Unwhiten(r2 * o.group_sigma_scale[static_cast<int>(bb.group)]));
  };
  if (bb.obs >= 0) {
    one(bb.obs, r.head<2>());
  } else {
    for (size_t k = 0; k < bb.view_obs.size(); ++k) {
      one(bb.view_obs[k], r.segment<2>(2 * static_cast<Eigen::Index>(k)));
    }
  }
}

// The cost at the assembly's state (the initial values), and each view's pixel RMS there into
// `view_rms_px` (problem order; NaN for a view with no observation used).
StatusOr<double> InitialCost(const BaProblem& problem,
                             const BaOptions& o,
                             const StateLayout& layout,
                             const Assembly& as,
                             std::vector<double>* view_rms_px) {
  double chi2_0 = 0;
  std::vector<double> ss(problem.views.size(), 0.0);
  std::vector<int> n(problem.views.size(), 0);
  for (const auto& bb : as.built) {
    Eigen::VectorXd r;
    if (!EvaluateBlock(bb, layout, as.buffer, &r, nullptr)) {
      const std::string what =
          bb.view < 0    ? std::string("a prior")
          : bb.obs < 0   ? "view '" + problem.views[bb.view].id + "'"
                         : "view '" + problem.views[bb.view].id + "' point " +
                             std::to_string(problem.views[bb.view].point_ids[bb.obs]);
      return Status::Error("the initial state gives a non-finite residual at " + what +
                           " (behind the source? a wrong initial pose?)",
                           ErrorKind::kNonFiniteInitialState);
    }
    chi2_0 += r.squaredNorm();
    ForEachObservation(
        problem, o, bb, r, [&](int, const Eigen::Vector2d&, const Eigen::Vector2d& e) {
          ss[bb.view] += e.squaredNorm();
          n[bb.view] += 1;
        });
  }
  view_rms_px->assign(problem.views.size(), std::nan(""));
  for (size_t v = 0; v < problem.views.size(); ++v) {
    if (n[v] > 0) (*view_rms_px)[v] = std::sqrt(ss[v] / (2.0 * n[v]));
  }
  return 0.5 * chi2_0;
}

// The Schur elimination order for Ceres: points first, then poses, then intrinsics.
std::shared_ptr<ceres::ParameterBlockOrdering> SchurOrdering(const StateLayout& layout,
                                                             const ceres::Problem& cp,
                                                             std::vector<double>* buffer) {
  auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
  bool any_point = false;
  for (const BlockInfo& b : layout.blocks()) {
    const bool point = b.kind == BlockKind::kMarker || b.kind == BlockKind::kPlatePoint;
    any_point |= point && !b.constant && cp.HasParameterBlock(buffer->data() + b.offset);
  }
  for (const BlockInfo& b : layout.blocks()) {
    double* p = buffer->data() + b.offset;
    if (!cp.HasParameterBlock(p) || cp.IsParameterBlockConstant(p)) continue;
    int group = 0;
    switch (b.kind) {
      case BlockKind::kMarker:
      case BlockKind::kPlatePoint:
        group = 0;
        break;
      case BlockKind::kPlatePose:
      case BlockKind::kObjectPose:
      case BlockKind::kRigPose:
        group = any_point ? 1 : 0;
        break;
      case BlockKind::kIntrinsics:
        group = any_point ? 2 : 1;
        break;
    }
    ordering->AddElementToGroup(p, group);
  }
  return ordering;
}

Termination TerminationOf(ceres::TerminationType t) {
  switch (t) {
    case ceres::CONVERGENCE:
      return Termination::kConvergence;
    case ceres::NO_CONVERGENCE:
      return Termination::kNoConvergence;
    case ceres::USER_SUCCESS:
      return Termination::kUserSuccess;
    case ceres::USER_FAILURE:
      return Termination::kUserFailure;
    case ceres::FAILURE:
      break;
  }
  return Termination::kFailure;
}

// Minimises the assembled Ceres problem in place (as->buffer); iterations and termination
// into res.
Status SolveWithCeres(const BaOptions& o, const StateLayout& layout, Start start,
                      ceres::Problem* cp, Assembly* as, BaResult* res) {
  ceres::Solver::Options so;
  so.initial_trust_region_radius = InitialTrustRegionRadius(o, start);
  LinearSolverType(o.linear_solver, &so.linear_solver_type);
  so.max_num_iterations = o.max_iterations;
  so.function_tolerance = o.function_tolerance;
  so.gradient_tolerance = o.gradient_tolerance;
  so.parameter_tolerance = o.parameter_tolerance;
  so.num_threads = o.num_threads;
  so.logging_type = ceres::SILENT;
  if (so.linear_solver_type == ceres::DENSE_SCHUR || so.linear_solver_type == ceres::SPARSE_SCHUR ||
      so.linear_solver_type == ceres::ITERATIVE_SCHUR) {
    so.linear_solver_ordering = SchurOrdering(layout, *cp, &as->buffer);
  }
  ceres::Solver::Summary summary;
  ceres::Solve(so, cp, &summary);
  res->iterations += static_cast<int>(summary.iterations.size()) - 1;
  res->termination = TerminationOf(summary.termination_type);
  if (!summary.IsSolutionUsable() || !std::isfinite(summary.final_cost)) {
    return Status::Error("bundle adjustment failed: " + summary.message);
  }
  return Status::Ok();
}

// What the evaluation at a solution gathers besides BaResult: the views' sums of squared pixel
// residuals, and the worst observation above reject_sigma (the candidate for rejection).
struct SolutionEvaluation {
  std::vector<double> view_ss;
  std::vector<int> view_n;
  int worst_view = -1, worst_obs = -1;
  double worst_sigma = 0;
  BaOutlier worst_out;
  bool any_rejected = false;
};

// A residual block's squared norm s weighted by its loss's rho'(s) (s itself without a loss).
double RobustlyWeighted(const ceres::LossFunction* loss, double s) {
  if (!loss) return s;
  double rho[3];
  loss->Evaluate(s, rho);
  return rho[1] * s;
}

// The residuals at `state`: chi2 and residual counts, the groups' sums, the linearisation, the
// outliers (sorted, largest first) and the worst observation above reject_sigma when rejection
// may still run (`may_reject`).
Status EvaluateSolution(const BaProblem& problem,
                        const BaOptions& o,
                        const StateLayout& layout,
                        const Assembly& as,
                        const std::vector<double>& state,
                        bool may_reject,
                        BaResult* res,
                        GroupResiduals* groups,
                        SolutionEvaluation* ev) {
  auto lin = std::make_shared<Linearization>();
  res->outliers.clear();
  res->chi2 = 0;
  res->robust_chi2 = 0;
  res->num_residuals = 0;
  *groups = GroupResiduals();
  ev->view_ss.assign(problem.views.size(), 0.0);
  ev->view_n.assign(problem.views.size(), 0);
  res->residuals.assign(problem.views.size(), {});
  for (size_t v = 0; v < problem.views.size(); ++v) {
    res->residuals[v].resize(problem.views[v].point_ids.size());
  }
  for (const auto& bb : as.built) {
    Eigen::VectorXd r;
    LinearizedBlock lb;
    if (!EvaluateBlock(bb, layout, state, &r, &lb)) {
      return Status::Error("a residual is not finite at the solution (a point behind the source?)");
    }
    res->chi2 += r.squaredNorm();
    res->robust_chi2 += RobustlyWeighted(bb.loss, r.squaredNorm());
    res->num_residuals += static_cast<int>(r.size()) - bb.zero_rows;
    groups->chi2[static_cast<int>(bb.group)] += r.squaredNorm();
    groups->rows[static_cast<int>(bb.group)] += static_cast<int>(r.size()) - bb.zero_rows;
    if (!lb.blocks.empty()) lin->rows.push_back(std::move(lb));
    if (bb.view < 0) continue;
    const BaView& view = problem.views[bb.view];
    ForEachObservation(
        problem, o, bb, r, [&](int obs, const Eigen::Vector2d& r2, const Eigen::Vector2d& e) {
          const double n_sigma = r2.norm();
          ev->view_ss[bb.view] += e.squaredNorm();
          ev->view_n[bb.view] += 1;
          res->residuals[bb.view][obs] = BaObservationResidual{e[0], e[1], n_sigma};
          BaOutlier out{
              view.id, view.kind == ViewKind::kPlate, view.point_ids[obs], n_sigma, e[0], e[1]};
          if (n_sigma > o.outlier_sigma) res->outliers.push_back(out);
          if (may_reject && o.reject_sigma > 0 && n_sigma > o.reject_sigma &&
              n_sigma > ev->worst_sigma) {
            ev->worst_sigma = n_sigma;
            ev->worst_view = bb.view;
            ev->worst_obs = obs;
            ev->worst_out = out;
            ev->any_rejected = true;
          }
        });
  }
  std::sort(res->outliers.begin(), res->outliers.end(), [](const BaOutlier& a, const BaOutlier& b) {
    return a.residual_sigma > b.residual_sigma;
  });
  res->linearization = lin;
  return Status::Ok();
}

// The final statistics: per view and per kind of view RMS in px, the degrees of freedom,
// sigma0 and the chi-square tail probability.
void SolutionStatistics(const BaProblem& problem, const StateLayout& layout,
                        const SolutionEvaluation& ev, BaResult* res) {
  res->final_cost = 0.5 * res->chi2;
  res->views.clear();
  double ss_plate = 0, ss_object = 0;
  int n_plate = 0, n_object = 0;
  for (size_t v = 0; v < problem.views.size(); ++v) {
    BaViewStats vs;
    vs.id = problem.views[v].id;
    vs.num_observations = ev.view_n[v];
    vs.rms_px = ev.view_n[v] ? std::sqrt(ev.view_ss[v] / (2.0 * ev.view_n[v])) : 0.0;
    res->views.push_back(vs);
    if (problem.views[v].kind == ViewKind::kPlate) {
      ss_plate += ev.view_ss[v], n_plate += ev.view_n[v];
    } else {
      ss_object += ev.view_ss[v], n_object += ev.view_n[v];
    }
  }
  res->rms_plate_px = n_plate ? std::sqrt(ss_plate / (2.0 * n_plate)) : std::nan("");
  res->rms_object_px = n_object ? std::sqrt(ss_object / (2.0 * n_object)) : std::nan("");
  res->num_free = layout.num_free();
  res->dof = res->num_residuals - res->num_free;
  res->sigma0 = res->dof > 0 ? std::sqrt(res->chi2 / res->dof) : std::nan("");
  res->chi2_p_value = ChiSquareUpperTail(res->chi2, res->dof);
}

// Drops the evaluation's worst observation above reject_sigma; an error when a view is left with
// fewer than 4 observations.
Status RejectWorst(const BaProblem& problem, const BaOptions& o, const SolutionEvaluation& ev,
                   std::vector<std::vector<char>>* dropped, BaResult* res) {
  (*dropped)[ev.worst_view][ev.worst_obs] = 1;
  res->rejected.push_back(ev.worst_out);
  for (size_t v = 0; v < problem.views.size(); ++v) {
    const auto left = std::count((*dropped)[v].begin(), (*dropped)[v].end(), 0);
    if (left < 4) {
      return Status::Error("outlier rejection (reject_sigma " + std::to_string(o.reject_sigma) +
                           ") leaves view '" + problem.views[v].id + "' with " +
                           std::to_string(left) + " observations, at least 4 needed");
    }
  }
  return Status::Ok();
}

// One solve at the options' group sigma scales from `state`, with the observations in `dropped`
// left out (the rejection pass may add to them): the estimate, its statistics (chi2 at the
// scaled sigmas), the linearisation, the covariance, and the groups' residual sums.
// The rejection pass drops the worst observation above reject_sigma, then solves again: one gross
// error pulls the residuals of the observations that share its marker, pose or intrinsics up too,
// so dropping all above the threshold at once would throw good observations away with it.
StatusOr<BaResult> SolveOnce(const BaProblem& problem,
                             const BaOptions& o,
                             std::shared_ptr<StateLayout> layout_ptr,
                             Start start,
                             std::vector<double> state,
                             std::vector<std::vector<char>> dropped,
                             GroupResiduals* groups) {
  BaResult res;
  res.layout = std::move(layout_ptr);
  const StateLayout& layout = *res.layout;
  const bool use_lm = o.backend == Backend::kCarmbaLm;
  if (use_lm) CARMBA_RETURN_IF_ERROR(CheckCarmbaLm(problem, o));
  res.backend = o.backend;

  static thread_local std::unique_ptr<ceres::Context> context(ceres::Context::Create());
  constexpr int kMaxRejectionPasses = 100;
  for (int pass = 0; pass <= kMaxRejectionPasses; ++pass) {
    Assembly as;
    as.buffer = state;
    ceres::Problem cp(ProblemOptions(context.get()));
    CARMBA_RETURN_IF_ERROR(Assemble(problem, layout, o, dropped, &as, use_lm ? nullptr : &cp));
    std::vector<double> view_rms_px;
    auto initial_cost = InitialCost(problem, o, layout, as, &view_rms_px);
    if (!initial_cost.ok()) return initial_cost.status();
    if (pass == 0) res.initial_cost = *initial_cost, res.initial_view_rms_px = view_rms_px;
    if (use_lm) {
      CARMBA_RETURN_IF_ERROR(SolveWithCarmbaLm(problem, layout, o, start, &as.buffer, &res));
    } else {
      CARMBA_RETURN_IF_ERROR(SolveWithCeres(o, layout, start, &cp, &as, &res));
    }
    state = as.buffer;
    if (!o.evaluate_solution) break;
    SolutionEvaluation ev;
    CARMBA_RETURN_IF_ERROR(EvaluateSolution(
        problem, o, layout, as, state, pass < kMaxRejectionPasses, &res, groups, &ev));
    if (ev.any_rejected) {
      CARMBA_RETURN_IF_ERROR(RejectWorst(problem, o, ev, &dropped, &res));
      continue;  // solve again without it
    }
    SolutionStatistics(problem, layout, ev, &res);
    break;
  }
  res.state = state;
  res.dropped = dropped;
  if (o.compute_covariance && o.evaluate_solution) {
    auto cov = SchurCovariance::Compute(layout, *res.linearization, o.min_reciprocal_condition);
    if (!cov.ok()) return cov.status();
    res.covariance = *cov;
  }
  return res;
}

// The per_group estimate's limits: at most this many re-solves, until every applied group's
// factor of the rescaled problem is within kFactorTolerance of 1. 1e-3 is an order below a
// factor's own sampling uncertainty (sqrt(2 / redundancy), at least 1e-2 for a group with
// redundancy below 20000) and leaves the sigmas within 5e-4 (relative) of the fixed point. A
// re-solve shrinks a factor's distance from 1 about 250x on the joint problem (object pixels:
// 0.034, 1.3e-4, 4.5e-7), so one re-solve settles a factor within 25 % of 1 where 1e-6 took two.
// The sigma scale is kept within [1 / kMaxSigmaScale, kMaxSigmaScale]
// (noise-free data would otherwise scale the weights to infinity).
constexpr int kMaxVarianceIterations = 50;
constexpr double kFactorTolerance = 1e-3;
constexpr double kMaxSigmaScale = 100;

// Scales each estimable group's sigmas by the square root of its factor in the rescaled problem.
// True (and `scale`, `applied` updated) if a group is newly applied or a factor was further than
// kFactorTolerance from 1: another solve is needed. False leaves them as they were solved with.
bool UpdateGroupScales(const GroupResiduals& groups,
                       const std::array<double, kNumNoiseGroups>& redundancy,
                       std::array<double, kNumNoiseGroups>* scale,
                       std::array<bool, kNumNoiseGroups>* applied) {
  bool changed = false;
  std::array<double, kNumNoiseGroups> next = *scale;
  std::array<bool, kNumNoiseGroups> next_applied = *applied;
  for (int k = 0; k < kNumNoiseGroups; ++k) {
    if (groups.rows[k] == 0 || redundancy[k] < kMinVarianceComponentRedundancy) continue;
    const double f = groups.chi2[k] / redundancy[k];
    next[k] = std::clamp((*scale)[k] * std::sqrt(f), 1.0 / kMaxSigmaScale, kMaxSigmaScale);
    changed |= !next_applied[k] ||
               std::abs(next[k] * next[k] / ((*scale)[k] * (*scale)[k]) - 1) > kFactorTolerance;
    next_applied[k] = true;
  }
  if (changed) *scale = next, *applied = next_applied;
  return changed;
}

}  // namespace

namespace {

// The solve with its noise model: SolveOnce, then the variance components (re-solving while
// per_group's factors move) and the statistics at the stated sigmas. `warm`: a solved state of
// the same layout to start from (null: the problem's initial values).
StatusOr<BaResult> SolveWithNoiseModel(const BaProblem& problem, const BaOptions& options,
                                       const std::vector<double>* warm) {
  const auto t0 = std::chrono::steady_clock::now();
  auto layout = std::make_shared<StateLayout>(problem);
  std::vector<std::vector<char>> dropped(problem.views.size());
  for (size_t v = 0; v < problem.views.size(); ++v)
    dropped[v].assign(problem.views[v].point_ids.size(), 0);
  BaOptions o = options;
  GroupResiduals groups;
  const Start start = warm ? Start::kWarm : Start::kCold;
  auto solved = SolveOnce(problem, o, layout, start, warm ? *warm : InitialState(problem, *layout),
                          dropped, &groups);
  if (!solved.ok()) return solved.status();
  BaResult res = std::move(*solved);
  if (res.covariance) {
    std::array<bool, kNumNoiseGroups> applied{};
    for (int it = 0;; ++it) {
      const auto redundancy =
          GroupRedundancies(*layout, *res.linearization, *res.covariance, groups);
      res.variance_components =
          VarianceComponents(groups, redundancy, o.group_sigma_scale, applied);
      if (options.covariance_scale != CovarianceScale::kPerGroup || it == kMaxVarianceIterations ||
          !UpdateGroupScales(groups, redundancy, &o.group_sigma_scale, &applied)) {
        break;
      }
      auto again = SolveOnce(problem, o, layout, Start::kWarm, res.state, res.dropped, &groups);
      if (!again.ok()) return again.status();
      again->initial_cost = res.initial_cost;
      again->initial_view_rms_px = res.initial_view_rms_px;
      again->iterations += res.iterations;
      again->rejected.insert(again->rejected.begin(), res.rejected.begin(), res.rejected.end());
      res = std::move(*again);
      res.variance_iterations = it + 1;
    }
  }
  // The statistics at the stated sigmas (the test of the stated noise model).
  if (res.linearization) {
    res.chi2 = 0;
    for (int k = 0; k < kNumNoiseGroups; ++k) {
      res.chi2 += o.group_sigma_scale[k] * o.group_sigma_scale[k] * groups.chi2[k];
    }
    res.sigma0 = res.dof > 0 ? std::sqrt(res.chi2 / res.dof) : std::nan("");
    res.chi2_p_value = ChiSquareUpperTail(res.chi2, res.dof);
  }
  res.group_sigma_scale = o.group_sigma_scale;
  res.scale_mode = options.covariance_scale;
  // global: the a-posteriori variance factor, robust_chi2 / dof (chi2 / dof without a loss).
  res.covariance_scale = options.covariance_scale == CovarianceScale::kGlobal && res.dof > 0 &&
                                 std::isfinite(res.robust_chi2)
                             ? res.robust_chi2 / res.dof
                             : 1.0;
  res.time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

}  // namespace

StatusOr<BaResult> SolveBundleAdjustment(const BaProblem& problem, const BaOptions& options) {
  std::string err;
  if (!options.Check(&err)) return Status::Error("solver options: " + err);
  CARMBA_RETURN_IF_ERROR(problem.Check());
  auto res = SolveWithNoiseModel(problem, options, nullptr);
  if (!res.ok() || !options.shadow_correction || !options.evaluate_solution) return res;
  const auto offsets = ShadowOffsets(problem, *res);
  const ShadowCorrectionSummary shadow =
      SummariseShadowOffsets(problem, offsets, std::sqrt(res->covariance_scale));
  if (!shadow.applied) {
    res->shadow = shadow;
    return res;
  }
  const BaResult first = std::move(*res);
  res = SolveWithNoiseModel(WithShadowOffsetsRemoved(problem, offsets), options, &first.state);
  if (!res.ok()) return res;
  // The initial values are the problem's, before the first solve.
  res->initial_cost = first.initial_cost;
  res->initial_view_rms_px = first.initial_view_rms_px;
  const double first_time_s = first.time_s;
  const int first_iterations = first.iterations;
  res->shadow = shadow;
  res->shadow_offsets = offsets;
  res->time_s += first_time_s;
  res->iterations += first_iterations;
  return res;
}

namespace {

std::string OutlierText(const BaOutlier& o) {
  char buf[300];
  std::snprintf(buf, sizeof buf, "view '%s' %s %d: residual %.1f sigma (du %+.3g, dv %+.3g px)",
                o.view.c_str(), o.plate ? "plate point" : "marker", o.id, o.residual_sigma, o.du_px,
                o.dv_px);
  return buf;
}

}  // namespace

std::vector<std::string> SolveWarnings(const BaResult& r) {
  std::vector<std::string> out;
  if (r.dof > 0 && std::isfinite(r.chi2_p_value) &&
      (r.chi2_p_value < kVarianceBandTail || r.chi2_p_value > 1 - kVarianceBandTail)) {
    char buf[300];
    std::snprintf(buf, sizeof buf,
                  "chi-square %.1f on %d dof at the stated sigmas (P = %.2g, sigma0 %.3g): the "
                  "residuals are %s than the stated noise explains (see the variance components)",
                  r.chi2, r.dof, r.chi2_p_value, r.sigma0,
                  r.chi2_p_value < kVarianceBandTail ? "larger" : "smaller");
    out.push_back(buf);
  }
  for (auto& w : VarianceComponentWarnings(r.variance_components, r.scale_mode)) {
    out.push_back(std::move(w));
  }
  auto list = [&](const std::vector<BaOutlier>& v, const std::string& what) {
    for (size_t i = 0; i < v.size() && i < static_cast<size_t>(kMaxListedOutliers); ++i) {
      out.push_back(OutlierText(v[i]) + " " + what);
    }
    if (v.size() > static_cast<size_t>(kMaxListedOutliers)) {
      out.push_back(std::to_string(v.size() - kMaxListedOutliers) + " more observations " + what);
    }
  };
  list(r.rejected, "was rejected as an outlier (outliers.reject_sigma)");
  list(r.outliers, "is beyond the outlier threshold (outliers.list_sigma)");
  return out;
}

StatusOr<Eigen::MatrixXd> CeresBlockCovariance(const BaProblem& problem,
                                               const BaOptions& o,
                                               const BaResult& result,
                                               const std::vector<int>& blocks,
                                               CovarianceAlgorithm algorithm) {
  const StateLayout& layout = *result.layout;
  Assembly as;
  as.buffer = result.state;
  ceres::Problem cp(ProblemOptions(nullptr));
  BaOptions weighted = o;  // the weights of the final solve (per_group's scales)
  weighted.group_sigma_scale = result.group_sigma_scale;
  CARMBA_RETURN_IF_ERROR(Assemble(problem, layout, weighted, result.dropped, &as, &cp));
  ceres::Covariance::Options co;
  switch (algorithm) {
    case CovarianceAlgorithm::kDenseSvd:
      co.algorithm_type = ceres::DENSE_SVD;
      break;
    case CovarianceAlgorithm::kSparseQr:
      co.algorithm_type = ceres::SPARSE_QR;
      break;
    case CovarianceAlgorithm::kEigenSparseQr:
      co.algorithm_type = ceres::SPARSE_QR;
      co.sparse_linear_algebra_library_type = ceres::EIGEN_SPARSE;
      break;
    case CovarianceAlgorithm::kSchur:
      return Status::Error("CeresBlockCovariance: schur is the engine's own covariance");
  }
  co.null_space_rank = 0;
  co.min_reciprocal_condition_number = o.min_reciprocal_condition;
  ceres::Covariance cov(co);
  std::vector<const double*> ptrs;
  for (int b : blocks) ptrs.push_back(as.buffer.data() + layout.block(b).offset);
  std::vector<std::pair<const double*, const double*>> pairs;
  for (size_t i = 0; i < ptrs.size(); ++i) {
    for (size_t j = i; j < ptrs.size(); ++j) pairs.emplace_back(ptrs[i], ptrs[j]);
  }
  if (!cov.Compute(pairs, &cp)) {
    return Status::Error(std::string("ceres::Covariance (") +
                             NameOf(kCovarianceAlgorithmNames, algorithm) + "): rank-deficient",
                         ErrorKind::kNotDetermined);
  }
  int n = 0;
  for (int b : blocks) n += layout.block(b).size;
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> C(n, n);
  cov.GetCovarianceMatrix(ptrs, C.data());
  return Eigen::MatrixXd(C * result.covariance_scale);
}

}  // namespace ba
}  // namespace carmba
