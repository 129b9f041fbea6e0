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
              RigidTransform* target_from_source) {
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

StatusOr<Labelling> LabelMarkers(const std::vector<Eigen::Vector3d>& found,
                                 const std::vector<ModelPoint>& model,
                                 double tolerance_mm) {
  const int n = static_cast<int>(found.size()), m = static_cast<int>(model.size());
  if (!(tolerance_mm > 0)) return Status::Error("labelling tolerance must be > 0 mm");
  if (n < 3 || n > m) {
    return Status::Error("labelling needs 3 .. " + std::to_string(m) +
                         " found markers (the model's count), got " + std::to_string(n));
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
      RigidTransform T;
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
