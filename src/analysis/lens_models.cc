#include "analysis/lens_models.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

namespace carmba {
namespace analysis {
namespace {

// Which of k1 k2 p1 p2 k3 the model frees.
std::array<bool, 5> DistortionFree(DistortionModel m) {
  switch (m) {
    case DistortionModel::kRadial2:
      return {true, true, false, false, false};
    case DistortionModel::kRadial2Tangential:
      return {true, true, true, true, false};
    case DistortionModel::kRadial3:
      return {true, true, false, false, true};
    case DistortionModel::kFull:
      return {true, true, true, true, true};
  }
  return {};
}

// The plate views of `p` alone (no object views, no markers): a calibration.
ba::BaProblem PlateViews(const ba::BaProblem& p) {
  ba::BaProblem out = p;
  out.views.clear();
  out.markers.clear();
  for (const auto& v : p.views) {
    if (v.kind == ba::ViewKind::kPlate) out.views.push_back(v);
  }
  return out;
}

// The full fit's scores and principal point.
StatusOr<ba::BaResult> FitFull(const ba::BaProblem& plates,
                               const ba::BaOptions& o,
                               DistortionScore* sc) {
  auto r = ba::SolveBundleAdjustment(plates, o);
  if (!r.ok()) return r.status();
  sc->num_free = r->num_free;
  sc->num_residuals = r->num_residuals;
  sc->chi2 = r->chi2;
  sc->aic = sc->chi2 + 2.0 * sc->num_free;
  sc->bic = sc->chi2 + sc->num_free * std::log(static_cast<double>(sc->num_residuals));
  const std::array<double, kNumIntrinsics> x = r->GroupIntrinsics(0);
  for (int i = 0; i < kNumIntrinsics; ++i) sc->intrinsics[i] = x[i];
  sc->plate_poses.resize(plates.views.size());
  for (size_t v = 0; v < plates.views.size(); ++v) {
    const Pose6 pose = r->ViewPose(static_cast<int>(v));
    for (int i = 0; i < 6; ++i) sc->plate_poses[v][i] = pose[i];
  }
  sc->principal_point = Eigen::Vector2d(sc->intrinsics[kCx], sc->intrinsics[kCy]);
  sc->principal_point_covariance = r->GroupIntrinsicsCovariance(0).block<2, 2>(kCx, kCx);
  return r;
}

// The plate views' linearised rows at a fit, by view, with the view's pose taken out: for J over
// the pose (Jp) and the free intrinsics (Ji) and whitened residuals r, the projector
// P = I - Jp (Jp^T Jp)^-1 Jp^T applied to Ji and r (P itself, rows x rows, is never formed).
struct ViewRows {
  Eigen::MatrixXd PJi;
  Eigen::VectorXd Pr;
};

// Whether `row` belongs to a plate view (its index in `view`), and its blocks over the pose and the
// intrinsics (null when absent).
struct RowBlocks {
  int view = -1;
  const Eigen::MatrixXd* Jp = nullptr;
  const Eigen::MatrixXd* Ji = nullptr;
};

RowBlocks BlocksOf(const ba::LinearizedBlock& row, int intrinsics_block,
                   const std::map<int, int>& view_of_block) {
  RowBlocks out;
  for (size_t k = 0; k < row.blocks.size(); ++k) {
    if (row.blocks[k] == intrinsics_block) out.Ji = &row.J[k];
    auto it = view_of_block.find(row.blocks[k]);
    if (it != view_of_block.end()) out.view = it->second, out.Jp = &row.J[k];
  }
  return out;
}

std::vector<ViewRows> RowsByView(const ba::BaProblem& plates, const ba::BaResult& r) {
  const ba::StateLayout& L = *r.layout;
  const int gb = L.group_block(0);
  const int nv = static_cast<int>(plates.views.size());
  std::map<int, int> view_of_block;
  for (int v = 0; v < nv; ++v) view_of_block[L.view_block(v)] = v;
  Eigen::Index k = 0;
  std::vector<Eigen::Index> rows(nv, 0);
  for (const ba::LinearizedBlock& row : r.linearization->rows) {
    const RowBlocks b = BlocksOf(row, gb, view_of_block);
    if (b.view < 0) continue;
    rows[b.view] += row.r.size();
    if (b.Ji) k = b.Ji->cols();
  }
  std::vector<Eigen::MatrixXd> Jp(nv), Ji(nv);
  std::vector<Eigen::VectorXd> res(nv);
  for (int v = 0; v < nv; ++v) {
    Jp[v].setZero(rows[v], 6), Ji[v].setZero(rows[v], k), res[v].setZero(rows[v]);
    rows[v] = 0;
  }
  for (const ba::LinearizedBlock& row : r.linearization->rows) {
    const RowBlocks b = BlocksOf(row, gb, view_of_block);
    if (b.view < 0) continue;
    const Eigen::Index n0 = rows[b.view], nr = row.r.size();
    Jp[b.view].middleRows(n0, nr) = *b.Jp;
    if (b.Ji) Ji[b.view].middleRows(n0, nr) = *b.Ji;
    res[b.view].segment(n0, nr) = row.r;
    rows[b.view] += nr;
  }
  std::vector<ViewRows> out(nv);
  for (int v = 0; v < nv; ++v) {
    const auto M = (Jp[v].transpose() * Jp[v]).ldlt();
    out[v].PJi = Ji[v] - Jp[v] * M.solve(Jp[v].transpose() * Ji[v]);
    out[v].Pr = res[v] - Jp[v] * M.solve(Jp[v].transpose() * res[v]);
  }
  return out;
}

// Held-out scores of `folds` folds from the fit's linearisation (one Gauss-Newton step, exact
// for a linear model): without fold F the intrinsics move by
//   d = S_-F^-1 sum_{v in F} g_v,   S_v = Ji^T P Ji,  g_v = Ji^T P r,  S_-F = sum_{v not in F} S_v
// (the poses eliminated; at the optimum sum_v g_v = 0), and fold F's views, their poses refitted
// with the intrinsics held there, leave the residuals P (r + Ji d) (P is idempotent and symmetric,
// so S_v = (P Ji)^T (P Ji) and g_v = (P Ji)^T (P r)).
void HeldOutScores(const std::vector<ViewRows>& rows, double sigma_px, int folds,
                   DistortionScore* sc) {
  const Eigen::Index k = rows.empty() ? 0 : rows[0].PJi.cols();
  std::vector<Eigen::MatrixXd> S(rows.size());
  std::vector<Eigen::VectorXd> g(rows.size());
  Eigen::MatrixXd S_all = Eigen::MatrixXd::Zero(k, k);
  for (size_t v = 0; v < rows.size(); ++v) {
    S[v] = rows[v].PJi.transpose() * rows[v].PJi;
    g[v] = rows[v].PJi.transpose() * rows[v].Pr;
    S_all += S[v];
  }
  double chi2 = 0;
  long n = 0;
  for (int f = 0; f < folds; ++f) {
    Eigen::MatrixXd S_f = S_all;
    Eigen::VectorXd g_f = Eigen::VectorXd::Zero(k);
    for (size_t v = f; v < rows.size(); v += folds) S_f -= S[v], g_f += g[v];
    const Eigen::VectorXd d = S_f.ldlt().solve(g_f);
    for (size_t v = f; v < rows.size(); v += folds) {
      chi2 += (rows[v].Pr + rows[v].PJi * d).squaredNorm();
      n += rows[v].Pr.size();
    }
  }
  sc->held_out_chi2_per_residual = chi2 / static_cast<double>(n);
  sc->held_out_rms_px = std::sqrt(chi2 / static_cast<double>(n)) * sigma_px;
}

Status ScoreModel(const ba::BaProblem& plates,
                  const ba::BaOptions& o,
                  int folds,
                  DistortionScore* sc) {
  auto r = FitFull(plates, o, sc);
  if (!r.ok()) return r.status();
  HeldOutScores(RowsByView(plates, *r), plates.views[0].sigma_px, folds, sc);
  return Status::Ok();
}

// a's free distortion terms are a subset of b's.
bool Nested(DistortionModel a, DistortionModel b) {
  const auto fa = DistortionFree(a), fb = DistortionFree(b);
  for (int i = 0; i < 5; ++i) {
    if (fa[i] && !fb[i]) return false;
  }
  return true;
}

// The fitted score with the most free parameters whose model is nested in m (null if none).
const DistortionScore* LargestNestedFit(const std::vector<DistortionScore>& fitted,
                                        DistortionModel m) {
  const DistortionScore* out = nullptr;
  for (const auto& sc : fitted) {
    if (sc.ok && Nested(sc.model, m) && (!out || sc.num_free > out->num_free)) out = &sc;
  }
  return out;
}

// |pp - s.pp| in sigmas of s (Mahalanobis, s's principal-point covariance).
double PrincipalPointSigmas(const DistortionScore& s, const Eigen::Vector2d& pp) {
  const Eigen::Vector2d d = pp - s.principal_point;
  return std::sqrt(d.dot(s.principal_point_covariance.ldlt().solve(d)));
}

// The chi-squares and covariances of every score at the pixel sigma of the full model's fit
// (the scores were computed at the stated sigma, whatever it was).
void RescaleToEstimatedSigma(double stated_sigma_px, DistortionSelection* sel) {
  const DistortionScore* full = nullptr;
  for (const auto& sc : sel->scores) {
    if (sc.ok && sc.model == DistortionModel::kFull) full = &sc;
  }
  if (!full || full->num_residuals <= full->num_free) return;
  const double s2 = full->chi2 / (full->num_residuals - full->num_free);
  if (!(s2 > 0)) return;
  sel->sigma_estimated = true;
  sel->sigma_px = std::sqrt(s2) * stated_sigma_px;
  for (auto& sc : sel->scores) {
    if (!sc.ok) continue;
    sc.chi2 /= s2;
    sc.aic = sc.chi2 + 2.0 * sc.num_free;
    sc.bic = sc.chi2 + sc.num_free * std::log(static_cast<double>(sc.num_residuals));
    sc.held_out_chi2_per_residual /= s2;
    sc.principal_point_covariance *= s2;
  }
}

}  // namespace

const char* DistortionModelName(DistortionModel m) {
  switch (m) {
    case DistortionModel::kRadial2:
      return "k1 k2";
    case DistortionModel::kRadial2Tangential:
      return "k1 k2 p1 p2";
    case DistortionModel::kRadial3:
      return "k1 k2 k3";
    case DistortionModel::kFull:
      return "k1 k2 p1 p2 k3";
  }
  return "?";
}

bool DistortionModelOf(const std::array<bool, kNumIntrinsics>& free, DistortionModel* out) {
  for (DistortionModel m : kDistortionModels) {
    const auto d = DistortionFree(m);
    bool same = true;
    for (int i = 0; i < 5; ++i) same &= d[i] == free[kK1 + i];
    if (same) {
      *out = m;
      return true;
    }
  }
  return false;
}

void ApplyDistortionModel(DistortionModel m, ba::BaProblem* problem) {
  const auto d = DistortionFree(m);
  for (ba::IntrinsicsGroup& g : problem->groups) {
    for (int i = 0; i < 5; ++i) {
      g.free[kK1 + i] = d[i];
      if (!d[i]) g.initial[kK1 + i] = 0;
    }
  }
}

void StartFromFit(const DistortionScore& fit, ba::BaProblem* problem) {
  for (ba::IntrinsicsGroup& g : problem->groups) g.initial = fit.intrinsics;
  size_t k = 0;
  for (ba::BaView& v : problem->views) {
    if (v.kind == ba::ViewKind::kPlate && k < fit.plate_poses.size()) {
      v.initial = fit.plate_poses[k++];
    }
  }
}

const DistortionScore* DistortionSelection::Score(DistortionModel m) const {
  for (const auto& s : scores) {
    if (s.model == m) return &s;
  }
  return nullptr;
}

StatusOr<DistortionSelection> SelectDistortionModel(const ba::BaProblem& problem,
                                                    const ba::BaOptions& options,
                                                    int folds,
                                                    bool estimate_sigma) {
  if (problem.groups.size() != 1 || problem.groups[0].smooth) {
    return Status::Error("the distortion model is selected for one shared intrinsics group (have " +
                         std::to_string(problem.groups.size()) +
                         (problem.groups.size() == 1 ? ", smooth" : "") + ")");
  }
  const ba::BaProblem plates = PlateViews(problem);
  const int num_plates = static_cast<int>(plates.views.size());
  if (num_plates < 2) {
    return Status::Error("the distortion model is selected on plate views: " +
                         std::to_string(num_plates) + " (at least 2 needed)");
  }
  ba::BaOptions o = options;
  o.covariance_scale = ba::CovarianceScale::kApriori;  // the chi-squares at the stated sigmas
  o.reject_sigma = 0;
  // Converged as calibrate converges its own fits (calib/calibrate.cc): the last iterations of
  // these ill-conditioned fits (k3 against k1, k2 in a narrow field of view: there the cost falls
  // about 10x per iteration) gain < 1e-10 of the cost, < 1e-7 of a chi-square of 1000 and the
  // parameters within 1e-3 sigma, far below what the comparison resolves (AIC differences of 1).
  o.function_tolerance = std::max(o.function_tolerance, 1e-10);
  // carmba's own LM serves these plate-only calibrations when they have its structure (several
  // times faster than Ceres there, the same optimum; ba/bundle_adjuster.h).
  bool lm = o.loss == ba::Loss::kTrivial && !plates.plate.free && !plates.groups[0].has_prior;
  for (const auto& v : plates.views) {
    lm &= v.sigma_px == plates.views[0].sigma_px && v.obs_sigma_px.empty() &&
          v.obs_covariance_px2.empty();
  }
  if (lm) o.backend = ba::Backend::kCarmbaLm;
  DistortionSelection sel;
  sel.folds = std::min(folds, num_plates);
  const DistortionScore* best = nullptr;
  for (DistortionModel m : kDistortionModels) {
    DistortionScore sc;
    sc.model = m;
    ba::BaProblem p = plates;
    // Started at the optimum of the largest model already fitted that it contains (its own
    // further terms at zero), with the first steps of a start near the optimum.
    ba::BaOptions om = o;
    if (const DistortionScore* from = LargestNestedFit(sel.scores, m)) {
      StartFromFit(*from, &p);
      om.initial_trust_region_radius = ba::kNearOptimumTrustRegionRadius;
    }
    ApplyDistortionModel(m, &p);
    const Status s = ScoreModel(p, om, sel.folds, &sc);
    sc.ok = s.ok();
    if (!s.ok()) sc.error = s.message();
    sel.scores.push_back(sc);
  }
  if (estimate_sigma) RescaleToEstimatedSigma(plates.views[0].sigma_px, &sel);
  const DistortionScore* best_held_out = nullptr;
  for (const auto& sc : sel.scores) {
    if (!sc.ok) continue;
    if (!best || sc.aic < best->aic) best = &sc;
    if (!best_held_out ||
        sc.held_out_chi2_per_residual < best_held_out->held_out_chi2_per_residual) {
      best_held_out = &sc;
    }
  }
  if (!best) return Status::Error("no distortion model could be fitted: " + sel.scores[0].error);
  // A model with more terms that moves the principal point by more than
  // kPrincipalPointWarnSigma of the AIC-best's sigma: the principal point depends on a choice the
  // data cannot make (AIC never rejects a larger model by more than 2 per term), and the smaller
  // model's sigma does not carry it. The larger model is recommended.
  std::string moved;
  for (bool again = true; again;) {
    again = false;
    for (const auto& sc : sel.scores) {
      if (!sc.ok || sc.num_free <= best->num_free || !Nested(best->model, sc.model)) continue;
      const double m = PrincipalPointSigmas(*best, sc.principal_point);
      if (!(m > kPrincipalPointWarnSigma)) continue;
      char b[600];
      std::snprintf(b, sizeof b,
                    "%s has the lowest AIC (%.1f), but %s (AIC %+.1f, which the data cannot "
                    "reject) moves the principal point by %.1f of its sigmas: the principal point "
                    "depends on a choice the data cannot make, so %s is recommended (its sigmas "
                    "carry the trade-off); ",
                    DistortionModelName(best->model), best->aic, DistortionModelName(sc.model),
                    sc.aic - best->aic, m, DistortionModelName(sc.model));
      moved += b;
      best = &sc;
      again = true;
      break;
    }
  }
  sel.recommended = best->model;
  char buf[1000];
  std::snprintf(
      buf,
      sizeof buf,
      "%s%s (AIC %.1f; chi-square %.1f with %d free parameters); the held-out views (%d "
      "folds) %s",
      moved.empty() ? "" : "the recommendation is ",
      DistortionModelName(best->model),
      best->aic,
      best->chi2,
      best->num_free,
      sel.folds,
      best_held_out == best
          ? "are predicted best by it too"
          : (std::string("are predicted best by ") + DistortionModelName(best_held_out->model) +
             " (held-out chi-square per residual " +
             std::to_string(best_held_out->held_out_chi2_per_residual) + " against " +
             std::to_string(best->held_out_chi2_per_residual) + ")")
                .c_str());
  sel.why = moved.empty() ? std::string(buf) + ": the lowest AIC" : moved + buf;
  return sel;
}

std::string DistortionWarning(const DistortionSelection& selection,
                              DistortionModel solved,
                              const Eigen::Vector2d& pp) {
  if (solved == selection.recommended) return "";
  const DistortionScore* rec = selection.Score(selection.recommended);
  const DistortionScore* own = selection.Score(solved);
  if (!rec || !rec->ok || !own || !own->ok) return "";
  // In the solved model's sigmas: does its reported uncertainty cover the model choice?
  const double m = PrincipalPointSigmas(*own, rec->principal_point);
  if (!(m > kPrincipalPointWarnSigma)) return "";
  char buf[2500];
  std::snprintf(buf, sizeof buf,
                "distortion model %s: its principal point (%.2f, %.2f) px lies %.1f of its sigmas "
                "from the recommended model %s's (%.2f, %.2f) px, so its sigmas do not carry the "
                "model choice (%s); set `distortion: auto` or free those terms",
                DistortionModelName(solved), pp[0], pp[1], m,
                DistortionModelName(selection.recommended), rec->principal_point[0],
                rec->principal_point[1], selection.why.c_str());
  return buf;
}

}  // namespace analysis
}  // namespace carmba
