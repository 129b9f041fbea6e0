#include "ba/quantities.h"

#include <cmath>

#include "ba/view_intrinsics.h"
#include "camera/camera.h"
#include "geometry/rotation.h"

namespace carmba {
namespace ba {

void AddGradientRow(const StateLayout& L, int b, const double* g, int row, Eigen::MatrixXd* G) {
  const BlockInfo& bi = L.block(b);
  if (bi.constant) return;
  for (int c = 0; c < static_cast<int>(bi.free.size()); ++c) {
    double v = 0;
    for (int i = 0; i < bi.size; ++i) v += g[i] * bi.basis(i, c);
    (*G)(row, bi.free_offset + c) += v;
  }
}

void AddConsiderGradientRow(const StateLayout& L,
                            int b,
                            const double* g,
                            int row,
                            Eigen::MatrixXd* Gc) {
  const BlockInfo& bi = L.block(b);
  for (size_t c = 0; c < bi.consider.size(); ++c) {
    (*Gc)(row, bi.consider_offset + static_cast<int>(c)) += g[bi.consider[c]];
  }
}

QuantitySet DerivedQuantities(const BaProblem& problem,
                              const BaResult& result,
                              const std::vector<std::pair<int, int>>& pairs) {
  const StateLayout& L = *result.layout;
  std::vector<Quantity> qs;
  std::vector<std::vector<std::pair<int, std::vector<double>>>> grads;  // per quantity: (block, g)
  auto add = [&](std::string name, std::string unit, double value, const QuantityKey& key, int b,
                 std::vector<double> g) {
    qs.push_back({std::move(name), std::move(unit), value, key});
    grads.push_back({{b, std::move(g)}});
  };

  // Distance for the centre projection: the mean object (else plate) distance.
  double d_sum = 0;
  int d_n = 0;
  for (ViewKind kind : {ViewKind::kObject, ViewKind::kPlate}) {
    for (size_t v = 0; v < problem.views.size() && d_n == 0; ++v) {
      if (problem.views[v].kind != kind) continue;
      for (size_t w = v; w < problem.views.size(); ++w) {
        if (problem.views[w].kind != kind) continue;
        d_sum += result.block(L.view_block(static_cast<int>(w)))[5];
        ++d_n;
      }
    }
  }
  const double distance = d_n ? d_sum / d_n : 1000.0;
  for (size_t g = 0; g < problem.groups.size(); ++g) {
    const int b = L.group_block(static_cast<int>(g));
    const BlockInfo& bi = L.block(b);
    const double* x = result.block(b);
    if (problem.groups[g].smooth) {
      // Angle-dependent intrinsics: each view's fx, fy, cx, cy (rows of A(angles)).
      for (size_t v = 0; v < problem.views.size(); ++v) {
        if (problem.views[v].group != static_cast<int>(g)) continue;
        const Eigen::MatrixXd A = ViewIntrinsicsMap(problem, static_cast<int>(v));
        const Eigen::VectorXd xv = A * Eigen::Map<const Eigen::VectorXd>(x, A.cols());
        for (int i = kFx; i <= kCy; ++i) {
          if (!problem.groups[g].free[i]) continue;
          std::vector<double> grad(A.cols());
          for (Eigen::Index c = 0; c < A.cols(); ++c) grad[c] = A(i, c);
          add("view " + problem.views[v].id + " " + kIntrinsicNames[i], "px", xv[i],
              {QuantityKind::kIntrinsic, static_cast<int>(g), static_cast<int>(v), -1, i}, b, grad);
        }
      }
      for (int i = kK1; i < kNumIntrinsics; ++i) {
        if (!problem.groups[g].free[i]) continue;
        const int k = bi.size - kNumIntrinsics + i;  // distortion sits last in the block
        std::vector<double> grad(bi.size, 0.0);
        grad[k] = 1.0;
        add(L.ParameterName(b, k),
            "",
            x[k],
            {QuantityKind::kIntrinsic, static_cast<int>(g), -1, -1, i},
            b,
            grad);
      }
      continue;
    }
    for (int i : bi.Moving()) {
      std::vector<double> grad(kNumIntrinsics, 0.0);
      grad[i] = 1.0;
      add(L.ParameterName(b, i), i < 4 ? "px" : "", x[i],
          {QuantityKind::kIntrinsic, static_cast<int>(g), -1, -1, i}, b, grad);
    }
    // Centre projection.
    const IntrinsicsGroup& grp = problem.groups[g];
    const double uc[2] = {grp.width > 0 ? 0.5 * (grp.width - 1) : x[kCx],
                          grp.height > 0 ? 0.5 * (grp.height - 1) : x[kCy]};
    double xy[2];
    if (UnprojectToNormalized(x, uc, xy)) {
      const double p[3] = {xy[0] * distance, xy[1] * distance, distance};
      double uv[2], J[2 * kNumIntrinsics];
      ProjectCamPointWithJac(x, p, uv, J, nullptr);
      const std::string prefix = bi.label.empty() ? "" : bi.label + " ";
      add(prefix + "centre projection u",
          "px",
          uv[0],
          {QuantityKind::kCentreProjection, static_cast<int>(g), -1, -1, 0},
          b,
          std::vector<double>(J, J + 9));
      add(prefix + "centre projection v", "px", uv[1],
          {QuantityKind::kCentreProjection, static_cast<int>(g), -1, -1, 1}, b,
          std::vector<double>(J + 9, J + 18));
    }
  }
  for (size_t v = 0; v < problem.views.size(); ++v) {
    if (problem.views[v].kind != ViewKind::kObject) continue;
    const int b = L.view_block(static_cast<int>(v));
    const double* pose = result.block(b);
    Eigen::Matrix3d Jl;
    SO3LeftJacobian(pose, Jl.data());
    Jl.transposeInPlace();  // row-major into column-major storage
    static const char* const kAxis[3] = {"x", "y", "z"};
    for (int a = 0; a < 3; ++a) {
      std::vector<double> grad(6, 0.0);
      for (int c = 0; c < 3; ++c) grad[c] = Jl(a, c) * kRadToDeg;
      add("view " + problem.views[v].id + " rot " + kAxis[a], "deg", 0.0,
          QuantityKey::ViewRotation(static_cast<int>(v), a), b, grad);
    }
    for (int a = 0; a < 3; ++a) {
      std::vector<double> grad(6, 0.0);
      grad[3 + a] = 1.0;
      add("view " + problem.views[v].id + " t" + kAxis[a], "mm", pose[3 + a],
          QuantityKey::ViewTranslation(static_cast<int>(v), a), b, grad);
    }
  }
  for (const auto& [ia, ib] : pairs) {
    const int ba = L.view_block(ia), bb = L.view_block(ib);
    const std::string name = "pair " + problem.views[ia].id + "/" + problem.views[ib].id;
    double g[12];
    auto add_pair = [&](const std::string& what, const QuantityKey& key, double value_rad) {
      for (double& x : g) x *= kRadToDeg;
      qs.push_back({name + " " + what, "deg", value_rad * kRadToDeg, key});
      grads.push_back(
          {{ba, std::vector<double>(g, g + 6)}, {bb, std::vector<double>(g + 6, g + 12)}});
    };
    add_pair("relative rotation",
             QuantityKey::PairRelativeRotation(ia, ib),
             PairMetricWithGradient(
                 result.block(ba),
                 result.block(bb),
                 [](auto* a, auto* b) { return RelativeRotationAngle(a, b); },
                 g));
    add_pair("view directions", QuantityKey::PairViewDirections(ia, ib),
             PairMetricWithGradient(result.block(ba), result.block(bb),
                                    [](auto* a, auto* b) { return ViewDirectionAngle(a, b); }, g));
  }
  QuantitySet out;
  out.quantities = qs;
  out.G = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(qs.size()), L.num_free());
  for (size_t q = 0; q < qs.size(); ++q) {
    for (const auto& [b, g] : grads[q]) AddGradientRow(L, b, g.data(), static_cast<int>(q), &out.G);
  }
  out.Gc = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(qs.size()), L.num_consider());
  for (size_t q = 0; q < qs.size(); ++q) {
    for (const auto& [b, g] : grads[q]) {
      if (static_cast<int>(g.size()) == L.block(b).size) {
        AddConsiderGradientRow(L, b, g.data(), static_cast<int>(q), &out.Gc);
      }
    }
  }
  return out;
}

std::vector<BudgetRow> ComputeErrorBudget(const BaProblem& problem,
                                          const BaResult& result,
                                          const std::vector<std::pair<int, int>>& pairs) {
  const QuantitySet qs = DerivedQuantities(problem, result, pairs);
  const ErrorBudget eb =
      result.covariance->Budget(qs.G, *result.linearization, result.covariance_scale, qs.Gc);
  std::vector<BudgetRow> rows;
  for (size_t q = 0; q < qs.quantities.size(); ++q) {
    BudgetRow r;
    r.quantity = qs.quantities[q];
    const double total = eb.total[q];
    r.sigma = std::sqrt(std::max(0.0, total));
    for (int s = 0; s < kNumSources; ++s) {
      const double var = eb.by_source(q, s);
      r.source_sigma[s] = std::sqrt(std::max(0.0, var));
      r.share[s] = total > 0 ? var / total : 0.0;
    }
    rows.push_back(r);
  }
  return rows;
}

const BudgetRow* FindBudgetRow(const std::vector<BudgetRow>& budget, const QuantityKey& key) {
  for (const BudgetRow& row : budget) {
    if (row.quantity.key == key) return &row;
  }
  return nullptr;
}

std::vector<Source> ActiveSources(const std::vector<BudgetRow>& budget) {
  std::vector<Source> out;
  for (int k = 0; k < kNumSources; ++k) {
    bool any = false;
    for (const auto& r : budget) any |= r.share[k] > 0;
    if (any) out.push_back(static_cast<Source>(k));
  }
  return out;
}

}  // namespace ba
}  // namespace carmba
