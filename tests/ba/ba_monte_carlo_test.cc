// Seeded Monte Carlo of the joint bundle adjustment (src/ba/) on the synthetic joint problem
// (20 plate views of a 5x5 plate, 7 object views of the thesis's 9-marker object, free plate
// points with a manufacturing prior, an intrinsics prior: all five noise sources):
//   * the error budget: each source switched on alone, its empirical variance of every derived
//     quantity against the budget's share (within 15 %), and all sources together against the
//     total (within 10 %);
//   * NEES: with all sources on, mean e^T C^-1 e / dim over the trials in [0.8, 1.25] for
//     (fx, fy, cx, cy) and for each object pose, with each trial's own covariance.
// Sampling: with N trials the relative standard error of a variance is sqrt(2 / N); N = 1500
// makes 15 % about 4 standard errors, so the ~300 comparisons do not fail by chance.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "ba/bundle_adjuster.h"
#include "ba/quantities.h"
#include "figures.h"
#include "geometry/rotation.h"
#include "synthetic/synthetic_joint.h"

namespace carmba {
namespace ba {
namespace {

constexpr int kTrials = 1500;
constexpr double kShareTol = 0.15;   // the figure for each source
constexpr double kTotalTol = 0.10;   // the figure for all sources together
constexpr int kNeesTrials = 300;

SyntheticJointSpec Spec() {
  SyntheticJointSpec s;
  s.plate_free = true;
  s.sigma_plate_mm = 0.01;
  s.intrinsics_prior = true;
  return s;
}

// The errors of the derived quantities (DerivedQuantities order) of a solution against the
// truth, to first order the quantities' deviations: intrinsics and translations as differences,
// rotations as the small rotation log(R_est R_true^T) in the camera frame, the centre projection
// as project(estimate, p0) - project(truth, p0) with p0 the linearisation's point, pair angles as
// differences.
Eigen::VectorXd Errors(const SyntheticJoint& sj,
                       const BaResult& r,
                       const QuantitySet& truth_q,
                       const Eigen::Vector3d& p0) {
  const BaProblem& p = sj.problem;
  const StateLayout& L = *r.layout;
  Eigen::VectorXd e(truth_q.quantities.size());
  int q = 0;
  const double* x = r.block(L.group_block(0));
  for (int i : L.block(L.group_block(0)).free) e[q++] = x[i] - sj.true_intrinsics[i];
  double uv_est[2], uv_true[2];
  ProjectCamPoint(x, p0.data(), uv_est);
  ProjectCamPoint(sj.true_intrinsics.data(), p0.data(), uv_true);
  e[q++] = uv_est[0] - uv_true[0];
  e[q++] = uv_est[1] - uv_true[1];
  for (size_t v = 0; v < p.views.size(); ++v) {
    if (p.views[v].kind != ViewKind::kObject) continue;
    const double* pose = r.block(L.view_block(static_cast<int>(v)));
    const Eigen::Matrix3d dR = RotationOf(Eigen::Vector3d(pose[0], pose[1], pose[2])) *
                               RotationOf(sj.true_poses[v].head<3>()).transpose();
    const Eigen::Vector3d w = RvecFromRotation(dR) * kRadToDeg;
    for (int a = 0; a < 3; ++a) e[q++] = w[a];
    for (int a = 0; a < 3; ++a) e[q++] = pose[3 + a] - sj.true_poses[v][3 + a];
  }
  for (const auto& [ia, ib] : sj.pairs) {
    const double* a = r.block(L.view_block(ia));
    const double* b = r.block(L.view_block(ib));
    e[q] = RelativeRotationAngle(a, b) * kRadToDeg - truth_q.quantities[q].value;
    ++q;
    e[q] = ViewDirectionAngle(a, b) * kRadToDeg - truth_q.quantities[q].value;
    ++q;
  }
  EXPECT_EQ(q, e.size());
  return e;
}

struct Reference {
  SyntheticJoint sj;
  BaResult at_truth;
  QuantitySet q;
  std::vector<BudgetRow> budget;
  Eigen::Vector3d p0;
};

Reference AtTruth() {
  NoiseSwitches none{false, false, false, false, false, false};
  Reference ref{MakeSyntheticJoint(Spec(), none, 0), BaResult(), QuantitySet(), {}, {}};
  auto r = SolveBundleAdjustment(ref.sj.problem, BaOptions());
  EXPECT_TRUE(r.ok()) << r.status().message();
  ref.at_truth = *r;
  ref.q = DerivedQuantities(ref.sj.problem, ref.at_truth, ref.sj.pairs);
  ref.budget = ComputeErrorBudget(ref.sj.problem, ref.at_truth, ref.sj.pairs);
  // The centre projection's point, as DerivedQuantities builds it.
  const auto& g = ref.sj.problem.groups[0];
  const double uc[2] = {0.5 * (g.width - 1), 0.5 * (g.height - 1)};
  double xy[2];
  UnprojectToNormalized(ref.at_truth.block(ref.at_truth.layout->group_block(0)), uc, xy);
  double d = 0;
  int n = 0;
  for (size_t v = 0; v < ref.sj.problem.views.size(); ++v) {
    if (ref.sj.problem.views[v].kind != ViewKind::kObject) continue;
    d += ref.at_truth.block(ref.at_truth.layout->view_block(static_cast<int>(v)))[5];
    ++n;
  }
  d /= n;
  ref.p0 = Eigen::Vector3d(xy[0] * d, xy[1] * d, d);
  return ref;
}

Eigen::VectorXd EmpiricalVariance(const Reference& ref, const NoiseSwitches& noise, uint64_t seed0,
                                  int trials) {
  // Only the solved states are used: no residual statistics, linearisation or covariance (the
  // same states: this problem has no sphere radii for a shadow correction and no rejection).
  BaOptions o;
  o.compute_covariance = false;
  o.evaluate_solution = false;
  o.initial_trust_region_radius = kNearOptimumTrustRegionRadius;  // starts at the truth
  const Eigen::Index nq = static_cast<Eigen::Index>(ref.q.quantities.size());
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(nq), sum2 = Eigen::VectorXd::Zero(nq);
  for (int t = 0; t < trials; ++t) {
    const SyntheticJoint sj = MakeSyntheticJoint(Spec(), noise, seed0 + t);
    auto r = SolveBundleAdjustment(sj.problem, o);
    EXPECT_TRUE(r.ok()) << r.status().message();
    if (!r.ok()) return Eigen::VectorXd::Zero(nq);
    const Eigen::VectorXd e = Errors(sj, *r, ref.q, ref.p0);
    sum += e;
    sum2 += e.cwiseProduct(e);
  }
  const Eigen::VectorXd mean = sum / trials;
  return (sum2 / trials - mean.cwiseProduct(mean)) * trials / (trials - 1.0);
}

TEST(BaMonteCarlo, ErrorBudgetMatchesEachSourceAlone) {
  const Reference ref = AtTruth();
  const int nq = static_cast<int>(ref.q.quantities.size());
  ASSERT_EQ(nq, static_cast<int>(ref.budget.size()));
  double worst = 0;
  std::string worst_what;
  for (int s = 0; s < kNumResidualSources; ++s) {  // no considered calibration here
    const Source src = static_cast<Source>(s);
    const Eigen::VectorXd var =
        EmpiricalVariance(ref, NoiseSwitches::Only(src), 100000 * (s + 1), kTrials);
    for (int q = 0; q < nq; ++q) {
      const double predicted = ref.budget[q].source_sigma[s] * ref.budget[q].source_sigma[s];
      const double ratio = var[q] / predicted;
      if (std::abs(ratio - 1) > worst) {
        worst = std::abs(ratio - 1);
        worst_what = ref.q.quantities[q].name + " / " + SourceName(src);
      }
      EXPECT_NEAR(ratio, 1.0, kShareTol)
          << ref.q.quantities[q].name << " from " << SourceName(src) << ": Monte Carlo variance "
          << var[q] << ", budget " << predicted << " (share " << ref.budget[q].share[s] << ")";
    }
  }
  std::printf("error budget vs Monte Carlo (%d trials per source): worst |ratio - 1| = %.3f (%s)\n",
              kTrials, worst, worst_what.c_str());
  // All sources together against the total.
  const Eigen::VectorXd var = EmpiricalVariance(ref, NoiseSwitches(), 900000, kTrials);
  double worst_total = 0;
  for (int q = 0; q < nq; ++q) {
    const double predicted = ref.budget[q].sigma * ref.budget[q].sigma;
    worst_total = std::max(worst_total, std::abs(var[q] / predicted - 1));
    EXPECT_NEAR(var[q] / predicted, 1.0, kTotalTol)
        << ref.q.quantities[q].name << ": Monte Carlo variance " << var[q] << ", budget total "
        << predicted;
  }
  std::printf("all sources (%d trials): worst |ratio - 1| = %.3f over %d quantities\n", kTrials,
              worst_total, nq);
  testing::RecordFigure("budget.trials", "%d", kTrials);
  testing::RecordFigure("budget.quantities", "%d", nq);
  testing::RecordFigure(
      "budget.each", "%.1f %% of the budget's share (worst: %s)", 100 * worst, worst_what.c_str());
  testing::RecordFigure("budget.total", "%.1f %%", 100 * worst_total);
}

TEST(BaMonteCarlo, NeesOfIntrinsicsAndPoses) {
  const SyntheticJointSpec spec = Spec();
  double nees_intr = 0;
  std::vector<double> nees_pose;
  int n = 0;
  for (int t = 0; t < kNeesTrials; ++t) {
    const SyntheticJoint sj = MakeSyntheticJoint(spec, NoiseSwitches(), 5000 + t);
    BaOptions o;
    o.initial_trust_region_radius = kNearOptimumTrustRegionRadius;  // starts at the truth
    auto r = SolveBundleAdjustment(sj.problem, o);
    ASSERT_TRUE(r.ok()) << r.status().message();
    const StateLayout& L = *r->layout;
    const Eigen::MatrixXd Ci = r->Covariance({L.group_block(0)}).topLeftCorner(4, 4);
    Eigen::Vector4d e;
    for (int i = 0; i < 4; ++i) e[i] = r->block(L.group_block(0))[i] - sj.true_intrinsics[i];
    nees_intr += e.dot(Ci.ldlt().solve(e)) / 4;
    int k = 0;
    for (size_t v = 0; v < sj.problem.views.size(); ++v) {
      if (sj.problem.views[v].kind != ViewKind::kObject) continue;
      const int b = L.view_block(static_cast<int>(v));
      const Eigen::MatrixXd Cp = r->Covariance({b});
      Eigen::Matrix<double, 6, 1> ep;
      for (int i = 0; i < 6; ++i) ep[i] = r->block(b)[i] - sj.true_poses[v][i];
      if (nees_pose.size() <= static_cast<size_t>(k)) nees_pose.push_back(0);
      nees_pose[k++] += ep.dot(Cp.ldlt().solve(ep)) / 6;
    }
    ++n;
  }
  nees_intr /= n;
  std::printf(
      "mean NEES / dim over %d trials: intrinsics (fx, fy, cx, cy) %.3f; poses", n, nees_intr);
  EXPECT_GE(nees_intr, 0.8);
  EXPECT_LE(nees_intr, 1.25);
  for (double& x : nees_pose) {
    x /= n;
    std::printf(" %.3f", x);
    EXPECT_GE(x, 0.8);
    EXPECT_LE(x, 1.25);
  }
  std::printf("\n");
  testing::RecordFigure("budget.nees_trials", "%d", n);
  testing::RecordFigure("budget.nees_intrinsics", "%.2f", nees_intr);
  testing::RecordFigure("budget.nees_poses",
                        "%.2f-%.2f for the %zu object poses",
                        *std::min_element(nees_pose.begin(), nees_pose.end()),
                        *std::max_element(nees_pose.begin(), nees_pose.end()),
                        nees_pose.size());
}

}  // namespace
}  // namespace ba
}  // namespace carmba
