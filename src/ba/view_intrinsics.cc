#include "ba/view_intrinsics.h"

namespace carmba {
namespace ba {

Eigen::MatrixXd GroupIntrinsicsMapAt(const IntrinsicsGroup& g,
                                     double primary_deg,
                                     double secondary_deg) {
  if (!g.smooth) return Eigen::MatrixXd::Identity(kNumIntrinsics, kNumIntrinsics);
  return g.basis.Map(primary_deg * kDegToRadFlex, secondary_deg * kDegToRadFlex);
}

Eigen::MatrixXd ViewIntrinsicsMap(const BaProblem& problem, int view) {
  const BaView& v = problem.views[view];
  return GroupIntrinsicsMapAt(problem.groups[v.group], v.primary_deg, v.secondary_deg);
}

ViewIntrinsics GroupIntrinsicsAt(const BaProblem& problem,
                                 const BaResult& result,
                                 int group,
                                 double primary_deg,
                                 double secondary_deg) {
  const Eigen::MatrixXd M = GroupIntrinsicsMapAt(problem.groups[group], primary_deg, secondary_deg);
  const int b = result.layout->group_block(group);
  ViewIntrinsics out;
  const Eigen::VectorXd x = M * Eigen::Map<const Eigen::VectorXd>(result.block(b), M.cols());
  for (int i = 0; i < kNumIntrinsics; ++i) out.value[i] = x[i];
  if (result.covariance) {
    out.covariance = M * result.Covariance({b}) * M.transpose();
  } else {
    out.covariance = Eigen::MatrixXd::Zero(kNumIntrinsics, kNumIntrinsics);
  }
  return out;
}

std::array<double, kNumIntrinsics> IntrinsicsValueOfView(const BaProblem& problem,
                                                         const BaResult& result,
                                                         int view) {
  const Eigen::MatrixXd M = ViewIntrinsicsMap(problem, view);
  const int b = result.layout->group_block(problem.views[view].group);
  const Eigen::VectorXd x = M * Eigen::Map<const Eigen::VectorXd>(result.block(b), M.cols());
  std::array<double, kNumIntrinsics> out;
  for (int i = 0; i < kNumIntrinsics; ++i) out[i] = x[i];
  return out;
}

ViewIntrinsics IntrinsicsOfView(const BaProblem& problem, const BaResult& result, int view) {
  const BaView& v = problem.views[view];
  return GroupIntrinsicsAt(problem, result, v.group, v.primary_deg, v.secondary_deg);
}

}  // namespace ba
}  // namespace carmba
