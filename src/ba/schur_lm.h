// carmba's own Levenberg-Marquardt for calibration-structured problems (one intrinsics block, many
// plate poses, points held), a back end of the bundle-adjustment engine (ba/bundle_adjuster.h,
// `backend: carmba_lm`) and of `carmba calibrate`, with the kernels it is built from. Tested to
// reach the same optimum as Ceres (tests/calib/solver_test.cc, tests/ba/ba_engine_test.cc).
//
// Per iteration the normal equations are built view by view (LineariseView) and the poses are
// eliminated by the Schur complement, the same algebra as Ceres's DENSE_SCHUR without its
// per-block overhead:
//   (Hpp_i + lambda D_i) dp_i = -(gp_i + Hpc_i A dc)  for every view i,
//   (A^T Hcc A + lambda D_c - A^T sum_i Hpc_i^T (Hpp_i + lambda D_i)^-1 Hpc_i A) dc
//       = -(A^T gc - A^T sum_i Hpc_i^T (Hpp_i + lambda D_i)^-1 gp_i),
// with Marquardt's damping D = diag(H). The reduction is done in the 9 intrinsics (fixed sizes)
// and projected on the free parameters (intrinsics = x0 + A delta) once per step. A step is kept
// if the cost drops (then lambda / 3); a rejected step (lambda x 4) costs one cost evaluation and
// one reduction, the Jacobians are reused. Residuals in pixels (unwhitened): one pixel sigma for
// all views.
#pragma once

#include <Eigen/Core>
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "ba/solver_kinds.h"
#include "camera/camera_model.h"
#include "geometry/pose.h"
#include "geometry/rotation.h"
#include "util/status.h"

namespace ceres {
class LossFunction;
}  // namespace ceres

namespace carmba {
namespace ba {

using Mat6 = Eigen::Matrix<double, 6, 6>;
using Vec6 = Eigen::Matrix<double, 6, 1>;
using Mat9 = Eigen::Matrix<double, kNumIntrinsics, kNumIntrinsics>;
using Vec9 = Eigen::Matrix<double, kNumIntrinsics, 1>;
using Mat69 = Eigen::Matrix<double, 6, kNumIntrinsics>;

// The robust loss `loss` at the scale `scale_whitened` of the whitened residual; null for the
// trivial loss. For the Ceres problem and carmba's LM alike.
std::unique_ptr<ceres::LossFunction> MakeLossFunction(Loss loss, double scale_whitened);

// Inverse of a symmetric positive definite 6x6 matrix by Cholesky; false if a pivot is not
// positive.
bool InvertSpd6(const Mat6& A, Mat6* inv);

// The Gauss-Newton blocks of one view at (intrinsics, pose), in pixels (unwhitened), with
// e_j = project - observed:
//   Hpp = sum J_pose^T J_pose (6x6),  Hpc = sum J_pose^T J_intr (6x9),  gp = sum J_pose^T e;
// the view's share of the intrinsics blocks is added to Hcc and gc.
struct ViewSystem {
  Mat6 Hpp;
  Mat69 Hpc;
  Vec6 gp;
};
bool LineariseView(const std::vector<Eigen::Vector3d>& plate,
                   const std::vector<Eigen::Vector2d>& uv,
                   const double* intr,
                   const double* pose,
                   ViewSystem* out,
                   Mat9* Hcc,
                   Vec9* gc);

// Sum of squared residuals (px^2) of one view added to *cost; false if a point is behind the
// source.
bool ViewCost(const std::vector<Eigen::Vector3d>& plate,
              const std::vector<Eigen::Vector2d>& uv,
              const double* intr,
              const double* pose,
              double* cost);

struct LmReport {
  int iterations = 0;
  Termination termination = Termination::kNoConvergence;
};

// Minimises sum over views and points of |project(x, pose_v, plate_v[j]) - uv_v[j]|^2 over
// x = x0 + A delta and the poses, from the given values. `initial_lambda`: the damping of the first
// step (relative to the diagonal; 1 / Ceres's initial trust-region radius). Errors: a point behind
// the source at the start, a singular system.
Status SchurLevenbergMarquardt(const std::vector<std::vector<Eigen::Vector3d>>& plate,
                               const std::vector<std::vector<Eigen::Vector2d>>& uv,
                               const Eigen::MatrixXd& A,
                               int max_iterations,
                               double function_tolerance,
                               double initial_lambda,
                               std::array<double, kNumIntrinsics>* x,
                               std::vector<Pose6>* poses,
                               LmReport* report);

}  // namespace ba
}  // namespace carmba
