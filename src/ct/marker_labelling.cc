#include "ct/marker_labelling.h"

#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>

#include "util/csv.h"
#include "util/plausible.h"

namespace carmba {

StatusOr<std::vector<ModelPoint>> ReadModelCsv(const std::string& path,
                                               const std::vector<std::string>& columns) {
  auto table = ReadCsv(path);
  if (!table.ok()) return table.status();
  std::vector<std::string> cols = columns;
  if (cols.empty()) {
    const std::vector<std::vector<std::string>> candidates = {
        {"x_mm", "y_mm", "z_mm"}, {"x", "y", "z"}, {"x_o", "y_o", "z_o"}, {"x_ct", "y_ct", "z_ct"}};
    for (const auto& c : candidates) {
      if (table->Column(c[0]).ok() && table->Column(c[1]).ok() && table->Column(c[2]).ok()) {
        cols = c;
        break;
      }
    }
    if (cols.empty()) {
      return Status::Error(path + ": no coordinate columns: expected x_mm,y_mm,z_mm or x,y,z or "
                                  "x_o,y_o,z_o or x_ct,y_ct,z_ct in the header");
    }
  }
  if (cols.size() != 3) return Status::Error(path + ": expected 3 coordinate column names");
  const std::string id_col = table->Column("id").ok() ? "id" : "marker";
  std::vector<ModelPoint> model;
  for (int r = 0; r < static_cast<int>(table->rows.size()); ++r) {
    ModelPoint m;
    auto id = table->Integer(r, id_col);
    if (!id.ok()) return id.status();
    m.id = *id;
    for (int a = 0; a < 3; ++a) {
      auto x = table->NumberIn(r, cols[a], plausible::kCoordinateMm);
      if (!x.ok()) return x.status();
      m.p_in_object[a] = *x;
    }
    for (const auto& o : model) {
      if (o.id == m.id) {
        return Status::Error(path + ":" + std::to_string(table->line_numbers[r]) +
                             ": duplicate marker id " + std::to_string(m.id));
      }
    }
    model.push_back(m);
  }
  if (model.size() < 3) {
    return Status::Error(path + ": " + std::to_string(model.size()) +
                         " model points, expected at least 3");
  }
  return model;
}

bool FitRigid(const std::vector<Eigen::Vector3d>& source,
              const std::vector<Eigen::Vector3d>& target,
              Rigid3* target_from_source) {
  const size_t n = source.size();
  if (n < 3 || target.size() != n) return false;
  Eigen::Vector3d ms = Eigen::Vector3d::Zero(), mt = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < n; ++i) {
    ms += source[i];
    mt += target[i];
  }
  ms /= n;
  mt /= n;
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero(), Sss = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < n; ++i) {
    H += (source[i] - ms) * (target[i] - mt).transpose();
    Sss += (source[i] - ms) * (source[i] - ms).transpose();
  }
  Eigen::JacobiSVD<Eigen::Matrix3d> spread(Sss);
  const Eigen::Vector3d sv = spread.singularValues();
  if (!(sv(1) > 1e-9 * std::max(1.0, sv(0)))) return false;  // collinear
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Matrix3d U = svd.matrixU(), V = svd.matrixV();
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (V * U.transpose()).determinant() < 0 ? -1 : 1;
  target_from_source->R = V * D * U.transpose();
  target_from_source->t = mt - target_from_source->R * ms;
  return true;
}

namespace {

std::string P3(const Eigen::Vector3d& v) {
  char b[96];
  std::snprintf(b, sizeof(b), "(%.2f, %.2f, %.2f)", v.x(), v.y(), v.z());
  return b;
}

// More candidates than model points: hypothesise and verify. A depth-first search assigns to
// model point j a candidate i whose distances to the candidates of the model points before j
// all match the model's within the tolerance; each complete assignment (every model point
// matched) is verified by the RMS of the proper rigid fit. Unused candidates get -1.
StatusOr<Labelling> SelectAndLabel(const std::vector<Eigen::Vector3d>& found,
                                   const std::vector<ModelPoint>& model,
                                   double tolerance_mm) {
  const int n = static_cast<int>(found.size()), m = static_cast<int>(model.size());
  std::vector<int> cand(m, -1);  // per model point, its candidate
  std::vector<bool> used(n, false);
  int deepest = 0, complete = 0;
  constexpr int kMaxAssignments = 100000;
  struct Hypothesis {
    double rms;
    std::vector<int> cand;
    Rigid3 T;
  };
  std::vector<Hypothesis> best;  // the two best, by RMS
  std::function<void(int)> search = [&](int j) {
    if (complete >= kMaxAssignments) return;
    deepest = std::max(deepest, j);
    if (j == m) {
      ++complete;
      std::vector<Eigen::Vector3d> src, dst;
      for (int a = 0; a < m; ++a) {
        src.push_back(found[cand[a]]);
        dst.push_back(model[a].p_in_object);
      }
      Rigid3 T;
      if (!FitRigid(src, dst, &T)) return;
      double ss = 0;
      for (int a = 0; a < m; ++a) ss += (T * src[a] - dst[a]).squaredNorm();
      best.push_back({std::sqrt(ss / m), cand, T});
      std::sort(best.begin(), best.end(),
                [](const Hypothesis& a, const Hypothesis& b) { return a.rms < b.rms; });
      if (best.size() > 2) best.resize(2);
      return;
    }
    for (int i = 0; i < n; ++i) {
      if (used[i]) continue;
      bool ok = true;
      for (int a = 0; a < j && ok; ++a) {
        const double d = (found[i] - found[cand[a]]).norm();
        const double D = (model[j].p_in_object - model[a].p_in_object).norm();
        ok = std::abs(d - D) <= tolerance_mm;
      }
      if (!ok) continue;
      used[i] = true;
      cand[j] = i;
      search(j + 1);
      used[i] = false;
      cand[j] = -1;
    }
  };
  search(0);
  char b[400];
  if (best.empty() || best[0].rms > tolerance_mm) {
    std::snprintf(b, sizeof(b),
                  "no subset of the %d candidates matches the %d model points: %s (at most %d "
                  "model points matched within %.2f mm); candidates at",
                  n, m,
                  best.empty() ? "no assignment keeps every pairwise distance"
                               : "the distances match only a mirror image (no proper rigid fit)",
                  deepest, tolerance_mm);
    std::string msg = b;
    for (int i = 0; i < n && i < 30; ++i) msg += " " + P3(found[i]);
    if (n > 30) msg += " ...";
    return Status::Error(msg);
  }
  const Hypothesis& h = best[0];
  if (best.size() > 1 && best[1].rms <= std::max(2 * h.rms, tolerance_mm / 4)) {
    std::snprintf(b, sizeof(b),
                  "ambiguous selection of %d of the %d candidates for the model: two assignments "
                  "fit with RMS %.3f and %.3f mm; best uses",
                  m, n, h.rms, best[1].rms);
    std::string msg = b;
    for (int a = 0; a < m; ++a) {
      msg += " " + std::to_string(model[a].id) + ":" + P3(found[h.cand[a]]);
    }
    msg += "; next uses";
    for (int a = 0; a < m; ++a) {
      msg += " " + std::to_string(model[a].id) + ":" + P3(found[best[1].cand[a]]);
    }
    return Status::Error(msg);
  }
  Labelling lab;
  lab.model_index.assign(n, -1);
  lab.residual_mm.assign(n, 0.0);
  lab.object_from_ct = h.T;
  lab.rms_mm = h.rms;
  lab.assignments = complete;
  lab.second_best_rms_mm = best.size() > 1 ? best[1].rms : -1;
  for (int a = 0; a < m; ++a) {
    const int i = h.cand[a];
    lab.model_index[i] = a;
    lab.residual_mm[i] = (h.T * found[i] - model[a].p_in_object).norm();
    lab.max_mm = std::max(lab.max_mm, lab.residual_mm[i]);
  }
  lab.selected = m;
  return lab;
}

}  // namespace

StatusOr<Labelling> LabelMarkers(const std::vector<Eigen::Vector3d>& found,
                                 const std::vector<ModelPoint>& model,
                                 double tolerance_mm) {
  const int n = static_cast<int>(found.size()), m = static_cast<int>(model.size());
  if (!(tolerance_mm > 0)) return Status::Error("labelling tolerance must be > 0 mm");
  if (n > m && m >= 3) return SelectAndLabel(found, model, tolerance_mm);
  if (n < 3) {
    return Status::Error("labelling needs at least 3 found markers, got " + std::to_string(n));
  }
  std::vector<int> assign(n, -1);
  std::vector<bool> used(m, false);
  int deepest = 0, complete = 0;
  constexpr int kMaxAssignments = 10000;
  double best_rms = 1e30, second_rms = 1e30;
  Labelling best;
  std::function<void(int)> search = [&](int i) {
    if (complete >= kMaxAssignments) return;
    deepest = std::max(deepest, i);
    if (i == n) {
      ++complete;
      std::vector<Eigen::Vector3d> src, dst;
      for (int a = 0; a < n; ++a) {
        src.push_back(found[a]);
        dst.push_back(model[assign[a]].p_in_object);
      }
      Rigid3 T;
      if (!FitRigid(src, dst, &T)) return;
      double ss = 0;
      for (int a = 0; a < n; ++a) ss += (T * src[a] - dst[a]).squaredNorm();
      const double rms = std::sqrt(ss / n);
      if (rms < best_rms) {
        second_rms = best_rms;
        best_rms = rms;
        best.model_index = assign;
        best.object_from_ct = T;
      } else if (rms < second_rms) {
        second_rms = rms;
      }
      return;
    }
    for (int j = 0; j < m; ++j) {
      if (used[j]) continue;
      bool ok = true;
      for (int a = 0; a < i && ok; ++a) {
        const double d = (found[i] - found[a]).norm();
        const double D = (model[j].p_in_object - model[assign[a]].p_in_object).norm();
        ok = std::abs(d - D) <= tolerance_mm;
      }
      if (!ok) continue;
      used[j] = true;
      assign[i] = j;
      search(i + 1);
      used[j] = false;
      assign[i] = -1;
    }
  };
  search(0);
  char b[400];
  if (best.model_index.empty()) {
    std::snprintf(b, sizeof(b),
                  "no labelling of the %d found markers with the %d model points keeps every "
                  "pairwise distance within %.2f mm (at most %d markers matched): wrong model, "
                  "model columns or markers",
                  n, m, tolerance_mm, deepest);
    return Status::Error(b);
  }
  if (best_rms > tolerance_mm) {
    std::snprintf(b, sizeof(b),
                  "the markers match the model's pairwise distances but no proper rigid motion "
                  "fits them (RMS %.3f mm > %.2f mm): a mirror image of the model?",
                  best_rms, tolerance_mm);
    return Status::Error(b);
  }
  best.assignments = complete;
  best.second_best_rms_mm = second_rms < 1e29 ? second_rms : -1;
  if (best.second_best_rms_mm >= 0 &&
      best.second_best_rms_mm <= std::max(2 * best_rms, tolerance_mm / 4)) {
    std::snprintf(b, sizeof(b),
                  "ambiguous labelling: two assignments to the model fit with RMS %.3f and %.3f "
                  "mm (the model is too symmetric to tell its markers apart)",
                  best_rms, best.second_best_rms_mm);
    return Status::Error(b);
  }
  best.residual_mm.resize(n);
  best.rms_mm = best_rms;
  for (int a = 0; a < n; ++a) {
    best.residual_mm[a] =
        (best.object_from_ct * found[a] - model[best.model_index[a]].p_in_object).norm();
    best.max_mm = std::max(best.max_mm, best.residual_mm[a]);
  }
  return best;
}

}  // namespace carmba
