#include "ba/lens_models.h"

#include <cmath>
#include <cstdio>

namespace carmba {
namespace ba {
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

// The plate views of `p` (all, or those whose index among the plate views is / is not in `fold`
// of `folds`), no markers.
BaProblem PlateViews(const BaProblem& p, int fold, int folds, bool in_fold) {
  BaProblem out = p;
  out.views.clear();
  out.markers.clear();
  int k = 0;
  for (const auto& v : p.views) {
    if (v.kind != ViewKind::kPlate) continue;
    if (fold < 0 || ((k % folds) == fold) == in_fold) out.views.push_back(v);
    ++k;
  }
  return out;
}

// The full fit's scores and principal point; `poses` gets each plate view's solved pose.
Status FitFull(const BaProblem& plates, const BaOptions& o, DistortionScore* sc,
               std::vector<Pose6>* poses) {
  auto r = SolveBundleAdjustment(plates, o);
  if (!r.ok()) return r.status();
  sc->num_free = r->num_free;
  sc->num_residuals = r->num_residuals;
  sc->chi2 = r->chi2;
  sc->aic = sc->chi2 + 2.0 * sc->num_free;
  sc->bic = sc->chi2 + sc->num_free * std::log(static_cast<double>(sc->num_residuals));
  const int gb = r->layout->group_block(0);
  for (int i = 0; i < kNumIntrinsics; ++i) sc->intrinsics[i] = r->block(gb)[i];
  sc->principal_point = Eigen::Vector2d(sc->intrinsics[kCx], sc->intrinsics[kCy]);
  sc->principal_point_covariance = r->Covariance({gb}).block<2, 2>(kCx, kCx);
  poses->clear();
  for (size_t v = 0; v < plates.views.size(); ++v) {
    Pose6 x;
    for (int i = 0; i < 6; ++i) x[i] = r->block(r->layout->view_block(static_cast<int>(v)))[i];
    poses->push_back(x);
  }
  return Status::Ok();
}

// Held-out chi2 and squared pixel residuals of fold `f`: trained without it, its views' poses
// refitted with the intrinsics held at the training fit.
Status HeldOut(const BaProblem& plates, const std::vector<Pose6>& poses, const BaOptions& o, int f,
               int folds, double* chi2, long* residuals, double* ss_px, long* coords) {
  const BaProblem train = PlateViews(plates, f, folds, false);
  BaOptions ot = o;
  ot.compute_covariance = false;
  auto rt = SolveBundleAdjustment(train, ot);
  if (!rt.ok()) return Status::Error("without fold " + std::to_string(f + 1) + ": " + rt.status().message());
  BaProblem test = PlateViews(plates, f, folds, true);
  IntrinsicsGroup& g = test.groups[0];
  for (int i = 0; i < kNumIntrinsics; ++i) g.initial[i] = rt->block(rt->layout->group_block(0))[i];
  g.free.fill(false);
  g.fy_over_fx = 0;
  for (size_t v = 0, k = 0; v < plates.views.size(); ++v) {
    if (static_cast<int>(v % folds) == f) test.views[k++].initial = poses[v];
  }
  auto rp = SolveBundleAdjustment(test, ot);
  if (!rp.ok()) return Status::Error("predicting fold " + std::to_string(f + 1) + ": " + rp.status().message());
  *chi2 += rp->chi2;
  *residuals += rp->num_residuals;
  for (const auto& vs : rp->views) {
    *ss_px += vs.rms_px * vs.rms_px * 2.0 * vs.num_observations;
    *coords += 2L * vs.num_observations;
  }
  return Status::Ok();
}

Status ScoreModel(const BaProblem& plates, const BaOptions& o, int folds, DistortionScore* sc) {
  std::vector<Pose6> poses;
  CARMBA_RETURN_IF_ERROR(FitFull(plates, o, sc, &poses));
  double chi2 = 0, ss = 0;
  long n = 0, coords = 0;
  for (int f = 0; f < folds; ++f) {
    CARMBA_RETURN_IF_ERROR(HeldOut(plates, poses, o, f, folds, &chi2, &n, &ss, &coords));
  }
  sc->held_out_chi2_per_residual = chi2 / static_cast<double>(n);
  sc->held_out_rms_px = std::sqrt(ss / static_cast<double>(coords));
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

void ApplyDistortionModel(DistortionModel m, BaProblem* problem) {
  const auto d = DistortionFree(m);
  for (IntrinsicsGroup& g : problem->groups) {
    for (int i = 0; i < 5; ++i) {
      g.free[kK1 + i] = d[i];
      if (!d[i]) g.initial[kK1 + i] = 0;
    }
  }
}

const DistortionScore* DistortionSelection::Score(DistortionModel m) const {
  for (const auto& s : scores) {
    if (s.model == m) return &s;
  }
  return nullptr;
}

StatusOr<DistortionSelection> SelectDistortionModel(const BaProblem& problem,
                                                    const BaOptions& options,
                                                    int folds,
                                                    bool estimate_sigma) {
  if (problem.groups.size() != 1 || problem.groups[0].smooth) {
    return Status::Error("the distortion model is selected for one shared intrinsics group (have " +
                         std::to_string(problem.groups.size()) +
                         (problem.groups.size() == 1 ? ", smooth" : "") + ")");
  }
  const BaProblem plates = PlateViews(problem, -1, 1, true);
  const int num_plates = static_cast<int>(plates.views.size());
  if (num_plates < 2) {
    return Status::Error("the distortion model is selected on plate views: " +
                         std::to_string(num_plates) + " (at least 2 needed)");
  }
  BaOptions o = options;
  o.covariance_scale = CovarianceScale::kApriori;  // the chi-squares at the stated sigmas
  o.reject_sigma = 0;
  // carmba's own LM serves these plate-only calibrations when they have its structure (several
  // times faster than Ceres there, the same optimum; ba/bundle_adjuster.h).
  bool lm = o.loss == "trivial" && !plates.plate.free && !plates.groups[0].has_prior;
  for (const auto& v : plates.views) {
    lm &= v.sigma_px == plates.views[0].sigma_px && v.obs_sigma_px.empty() && v.obs_covariance_px2.empty();
  }
  if (lm) o.backend = "carmba_lm";
  DistortionSelection sel;
  sel.folds = std::min(folds, num_plates);
  const DistortionScore* best = nullptr;
  for (DistortionModel m : kDistortionModels) {
    DistortionScore sc;
    sc.model = m;
    BaProblem p = plates;
    ApplyDistortionModel(m, &p);
    const Status s = ScoreModel(p, o, sel.folds, &sc);
    sc.ok = s.ok();
    if (!s.ok()) sc.error = s.message();
    sel.scores.push_back(sc);
  }
  if (estimate_sigma) RescaleToEstimatedSigma(plates.views[0].sigma_px, &sel);
  const DistortionScore* best_held_out = nullptr;
  for (const auto& sc : sel.scores) {
    if (!sc.ok) continue;
    if (!best || sc.aic < best->aic) best = &sc;
    if (!best_held_out || sc.held_out_chi2_per_residual < best_held_out->held_out_chi2_per_residual) {
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
  std::snprintf(buf, sizeof buf,
                "%s%s (AIC %.1f; chi-square %.1f with %d free parameters); the held-out views (%d "
                "folds) %s",
                moved.empty() ? "" : "the recommendation is ", DistortionModelName(best->model),
                best->aic, best->chi2, best->num_free, sel.folds,
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

}  // namespace ba
}  // namespace carmba
