// Each view's intrinsics in a solved bundle adjustment, for every intrinsics model: a shared or
// per-group block holds them directly; a smooth group (ba/smooth_intrinsics.h) maps its
// coefficients c to the view's intrinsics A(angles) c. Uniformly: intrinsics_v = M_v x_g with
// M_v the identity (9 x 9) or A (9 x (4K+5)), and their covariance M_v C_g M_v^T (C_g the group
// block's covariance from the engine, held parameters zero).
#pragma once

#include <Eigen/Dense>
#include <array>

#include "ba/bundle_adjuster.h"
#include "ba/problem.h"

namespace carmba {
namespace ba {

constexpr double kDegToRadFlex = 0.017453292519943295;

// M_v: 9 x group block size.
Eigen::MatrixXd ViewIntrinsicsMap(const BaProblem& problem, int view);
// M_v at arbitrary angles for group g (identity for a non-smooth group).
Eigen::MatrixXd GroupIntrinsicsMapAt(const IntrinsicsGroup& group,
                                     double primary_deg,
                                     double secondary_deg);

struct ViewIntrinsics {
  std::array<double, kNumIntrinsics> value{};
  Eigen::MatrixXd covariance;  // 9 x 9 (scaled as BaResult::Covariance)
};

// The intrinsics of group g at the given angles (a view between calibrated angles, or a plot).
ViewIntrinsics GroupIntrinsicsAt(const BaProblem& problem,
                                 const BaResult& result,
                                 int group,
                                 double primary_deg,
                                 double secondary_deg);
// The intrinsics of a view of the problem (at its angles).
ViewIntrinsics IntrinsicsOfView(const BaProblem& problem, const BaResult& result, int view);
// Their values alone (no covariance): what a residual, a plot or an exported view geometry needs.
std::array<double, kNumIntrinsics> IntrinsicsValueOfView(const BaProblem& problem,
                                                         const BaResult& result,
                                                         int view);

}  // namespace ba
}  // namespace carmba
