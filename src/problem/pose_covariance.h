// Joint covariance of the pose problem's poses, computed from the residuals' own Jacobians at the
// solution with the markers eliminated by the Schur complement (the "schur" covariance algorithm).
//
// With whitened residuals the Gauss-Newton information is H = J^T J. Ordering the parameters as
// poses p (6 per view) and markers m (3 each):
//     H = [ A   B ]     A: block-diagonal, 6x6 per view (a reprojection touches one pose)
//         [ B^T D ]     D: block-diagonal, 3x3 per marker (reprojections + the CT prior S^T S)
//     Cov(p) = (A - B D^-1 B^T)^-1                 (the poses' block of H^-1)
// which is what ceres::Covariance returns for the pose blocks (tests/core/pose_solver_test.cc
// checks the two against each other), at the cost of one Jacobian evaluation and a 6V x 6V
// inverse instead of a sparse QR of the whole Jacobian.
//
// With a robust loss each reprojection block's Jacobian is corrected as Ceres corrects it
// (Triggs et al., "Bundle adjustment: a modern synthesis", sec. 4.3; ceres/internal/corrector.cc),
// so the result equals ceres::Covariance with the loss applied.
//
// Gauge and rank: the CT priors fix the object frame, so D is positive definite. The reduced
// matrix is Jacobi-scaled and Cholesky-factored; a failed factorisation or a reciprocal condition
// estimate (LLT::rcond, 1-norm) below `min_reciprocal_condition_number` (Ceres's own default is
// 1e-14) is reported as rank-deficient.
#pragma once

#include <ceres/cost_function.h>
#include <ceres/loss_function.h>

#include <Eigen/Dense>
#include <vector>

#include "util/status.h"

namespace carmba {

struct PoseCovarianceBlock {
  const ceres::CostFunction* cost = nullptr;  // parameter blocks: pose (6), marker (3), intrinsics
  const ceres::LossFunction* loss = nullptr;  // nullptr: squared loss
  int view = 0;
  int marker = 0;
};

struct PoseCovarianceInput {
  std::vector<PoseCovarianceBlock> blocks;
  std::vector<const double*> poses;                  // V pointers to 6 doubles
  std::vector<const double*> markers;                // M pointers to 3 doubles
  std::vector<Eigen::Matrix3d> marker_information;   // M CT prior informations (S^T S), mm^-2
  const double* intrinsics = nullptr;                // held constant
  double min_reciprocal_condition_number = 1e-14;
};

// Returns the 6V x 6V covariance of [rvec (rad), t (mm)] per view, views in order.
StatusOr<Eigen::MatrixXd> PoseCovarianceBySchur(const PoseCovarianceInput& in);

}  // namespace carmba
