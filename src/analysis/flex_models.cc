#include "analysis/flex_models.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>

#include "ba/view_intrinsics.h"
#include "camera/carm_geometry.h"

namespace carmba {
namespace analysis {
namespace {

bool SameAngles(double a1, double b1, double a2, double b2) {
  return std::lround(a1 * 100) == std::lround(a2 * 100) &&
         std::lround(b1 * 100) == std::lround(b2 * 100);
}

int NearestOrientation(const std::vector<std::pair<double, double>>& o, double a, double b) {
  int best = 0;
  double best_d = std::numeric_limits<double>::infinity();
  for (size_t k = 0; k < o.size(); ++k) {
    const double d = std::hypot(o[k].first - a, o[k].second - b);
    if (d < best_d) best_d = d, best = static_cast<int>(k);
  }
  return best;
}

// The plate views of `p` whose orientation is (or is not) `o`.
ba::BaProblem PlateSubset(const ba::BaProblem& p, const std::pair<double, double>& o, bool keep_o) {
  ba::BaProblem out = p;
  out.views.clear();
  out.markers.clear();
  for (const auto& v : p.views) {
    if (v.kind != ba::ViewKind::kPlate) continue;
    if (SameAngles(v.primary_deg, v.secondary_deg, o.first, o.second) == keep_o)
      out.views.push_back(v);
  }
  return out;
}

// fx, fy, cx, cy of `vi` and their covariance.
void Head4(const ba::ViewIntrinsics& vi, Eigen::Vector4d* x, Eigen::Matrix4d* C) {
  for (int i = 0; i < 4; ++i) (*x)[i] = vi.value[i];
  *C = vi.covariance.topLeftCorner<4, 4>();
}

}  // namespace

const char* IntrinsicsModelName(IntrinsicsModel m) {
  switch (m) {
    case IntrinsicsModel::kShared: return "shared";
    case IntrinsicsModel::kPerGroup: return "per_group";
    case IntrinsicsModel::kSmooth: return "smooth";
  }
  return "?";
}

std::vector<std::pair<double, double>> PlateOrientations(const ba::BaProblem& problem) {
  std::vector<std::pair<double, double>> out;
  for (const auto& v : problem.views) {
    if (v.kind != ba::ViewKind::kPlate || !v.has_angles) continue;
    bool seen = false;
    for (const auto& o : out) seen |= SameAngles(o.first, o.second, v.primary_deg, v.secondary_deg);
    if (!seen) out.emplace_back(v.primary_deg, v.secondary_deg);
  }
  return out;
}

Status ApplyIntrinsicsModel(IntrinsicsModel model, const ba::SmoothBasis& basis, ba::BaProblem* p) {
  if (p->groups.empty()) return Status::Error("no intrinsics group to start from");
  ba::IntrinsicsGroup tmpl = p->groups[0];
  tmpl.smooth = false;
  tmpl.initial_coefficients.clear();
  if (model != IntrinsicsModel::kShared) {
    for (const auto& v : p->views) {
      if (!v.has_angles) {
        return Status::Error("view '" + v.id + "' has no C-arm angles; intrinsics model " +
                             IntrinsicsModelName(model) +
                             " needs them (DICOM positioner angles, or angles: views.csv)");
      }
    }
  }
  p->groups.clear();
  if (model == IntrinsicsModel::kShared) {
    tmpl.name = "shared";
    p->groups.push_back(tmpl);
    for (auto& v : p->views) v.group = 0;
  } else if (model == IntrinsicsModel::kSmooth) {
    tmpl.name = "smooth";
    tmpl.smooth = true;
    tmpl.basis = basis;
    p->groups.push_back(tmpl);
    for (auto& v : p->views) v.group = 0;
  } else {
    const auto orientations = PlateOrientations(*p);
    if (orientations.empty()) return Status::Error("per_group: no plate views with angles");
    for (const auto& o : orientations) {
      ba::IntrinsicsGroup g = tmpl;
      g.name = OrientationName(o.first, o.second);
      p->groups.push_back(g);
    }
    for (auto& v : p->views)
      v.group = NearestOrientation(orientations, v.primary_deg, v.secondary_deg);
  }
  return p->Check();
}

StatusOr<ModelSelection> SelectIntrinsicsModel(const ba::BaProblem& problem,
                                               const ba::SmoothBasis& basis,
                                               const ba::BaOptions& options,
                                               const std::vector<IntrinsicsModel>& models) {
  const auto orientations = PlateOrientations(problem);
  if (orientations.size() < 2) {
    return Status::Error("model selection needs plate views at >= 2 orientations (have " +
                         std::to_string(orientations.size()) + ")");
  }
  ba::BaOptions o = options;
  o.reject_sigma = 0;
  // Each orientation group's own calibration (its plate views alone, shared model).
  std::vector<Eigen::Vector4d> own_x(orientations.size());
  std::vector<Eigen::Matrix4d> own_C(orientations.size());
  for (size_t k = 0; k < orientations.size(); ++k) {
    ba::BaProblem sub = PlateSubset(problem, orientations[k], true);
    CARMBA_RETURN_IF_ERROR(ApplyIntrinsicsModel(IntrinsicsModel::kShared, basis, &sub));
    auto r = ba::SolveBundleAdjustment(sub, o);
    if (!r.ok()) {
      return Status::Error("orientation " +
                           OrientationName(orientations[k].first, orientations[k].second) +
                           " alone: " + r.status().message());
    }
    Head4(ba::IntrinsicsOfView(sub, *r, 0), &own_x[k], &own_C[k]);
  }
  ModelSelection sel;
  for (IntrinsicsModel m : models) {
    ModelScore sc;
    sc.model = m;
    ba::BaProblem full = PlateSubset(problem, {1e9, 1e9}, false);  // all plate views
    Status s = ApplyIntrinsicsModel(m, basis, &full);
    StatusOr<ba::BaResult> r =
        s.ok() ? ba::SolveBundleAdjustment(full, o) : StatusOr<ba::BaResult>(s);
    if (!r.ok()) {
      sc.error = r.status().message();
      sel.scores.push_back(sc);
      continue;
    }
    sc.num_free = r->num_free;
    sc.num_residuals = r->num_residuals;
    sc.chi2 = r->chi2;
    sc.aic = sc.chi2 + 2.0 * sc.num_free;
    sc.bic = sc.chi2 + sc.num_free * std::log(static_cast<double>(sc.num_residuals));
    double ss = 0, d2 = 0;
    long n = 0;
    sc.ok = true;
    for (size_t k = 0; k < orientations.size() && sc.ok; ++k) {
      const auto& ok_ = orientations[k];
      HeldOutGroup h;
      h.orientation = OrientationName(ok_.first, ok_.second);
      ba::BaProblem train = PlateSubset(problem, ok_, false);
      Status st = ApplyIntrinsicsModel(m, basis, &train);
      StatusOr<ba::BaResult> rt =
          st.ok() ? ba::SolveBundleAdjustment(train, o) : StatusOr<ba::BaResult>(st);
      if (!rt.ok()) {
        sc.ok = false;
        sc.error = "without " + h.orientation + ": " + rt.status().message();
        break;
      }
      // The prediction at o's angles.
      int g = 0;
      if (m == IntrinsicsModel::kPerGroup) {
        g = NearestOrientation(PlateOrientations(train), ok_.first, ok_.second);
      }
      const ba::ViewIntrinsics pred = ba::GroupIntrinsicsAt(train, *rt, g, ok_.first, ok_.second);
      Eigen::Vector4d xp;
      Eigen::Matrix4d Cp;
      Head4(pred, &xp, &Cp);
      const Eigen::Vector4d dx = xp - own_x[k];
      h.d2 = dx.dot((Cp + own_C[k]).ldlt().solve(dx));
      // The held-out views with the predicted intrinsics held, poses free.
      ba::BaProblem test = PlateSubset(problem, ok_, true);
      CARMBA_RETURN_IF_ERROR(ApplyIntrinsicsModel(IntrinsicsModel::kShared, basis, &test));
      test.groups[0].initial = pred.value;
      test.groups[0].free.fill(false);
      ba::BaOptions ot = o;
      ot.compute_covariance = false;
      auto rp = ba::SolveBundleAdjustment(test, ot);
      if (!rp.ok()) {
        sc.ok = false;
        sc.error = "predicting " + h.orientation + ": " + rp.status().message();
        break;
      }
      double ss_k = 0;
      long n_k = 0;
      for (size_t v = 0; v < test.views.size(); ++v) {
        ss_k += rp->views[v].rms_px * rp->views[v].rms_px * 2.0 * rp->views[v].num_observations;
        n_k += 2L * rp->views[v].num_observations;
      }
      h.rms_px = std::sqrt(ss_k / static_cast<double>(n_k));
      h.chi2_per_residual = rp->chi2 / static_cast<double>(rp->num_residuals);
      ss += ss_k;
      n += n_k;
      d2 += h.d2;
      sc.held_out.push_back(h);
    }
    if (sc.ok) {
      sc.held_out_rms_px = std::sqrt(ss / static_cast<double>(n));
      sc.held_out_d2_mean = d2 / static_cast<double>(orientations.size());
    }
    sel.scores.push_back(sc);
  }
  // Recommendation: the simplest model whose held-out predictions agree with the groups' own
  // calibrations within the noise; else the one that predicts best.
  const double G = static_cast<double>(orientations.size());
  const double threshold = 4.0 + 2.0 * std::sqrt(8.0 / G);
  const ModelScore* best = nullptr;
  const ModelScore* simplest_ok = nullptr;
  for (const auto& sc : sel.scores) {
    if (!sc.ok) continue;
    if (!best || sc.held_out_d2_mean < best->held_out_d2_mean) best = &sc;
    if (sc.held_out_d2_mean <= threshold && (!simplest_ok || sc.num_free < simplest_ok->num_free)) {
      simplest_ok = &sc;
    }
  }
  if (!best) return Status::Error("model selection: no model could be fitted and cross-validated");
  std::ostringstream why;
  char buf[256];
  if (simplest_ok) {
    sel.recommended = simplest_ok->model;
    std::snprintf(buf, sizeof buf,
                  "%s is the simplest model (%d free parameters) whose held-out predictions agree "
                  "with each orientation group's own calibration within the noise: mean "
                  "Mahalanobis d2 %.2f over %d groups (expected 4 for a correct model; threshold "
                  "%.2f = 4 + 2 sd)",
                  IntrinsicsModelName(simplest_ok->model), simplest_ok->num_free,
                  simplest_ok->held_out_d2_mean, static_cast<int>(G), threshold);
  } else {
    sel.recommended = best->model;
    std::snprintf(buf, sizeof buf,
                  "no model predicts the held-out groups within the noise (threshold %.2f); %s "
                  "predicts best: mean Mahalanobis d2 %.2f",
                  threshold, IntrinsicsModelName(best->model), best->held_out_d2_mean);
  }
  why << buf;
  for (const auto& sc : sel.scores) {
    if (!sc.ok || sc.model == sel.recommended) continue;
    std::snprintf(buf, sizeof buf, "; %s: d2 %.2f (%d parameters)", IntrinsicsModelName(sc.model),
                  sc.held_out_d2_mean, sc.num_free);
    why << buf;
  }
  sel.why = why.str();
  return sel;
}

}  // namespace analysis
}  // namespace carmba
