#include "ba/schur_lm.h"

#include <ceres/loss_function.h>
#include <ceres/rotation.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "geometry/rotation.h"

namespace carmba {
namespace ba {

std::unique_ptr<ceres::LossFunction> MakeLossFunction(Loss loss, double scale_whitened) {
  switch (loss) {
    case Loss::kTrivial:
      return nullptr;
    case Loss::kHuber:
      return std::make_unique<ceres::HuberLoss>(scale_whitened);
    case Loss::kCauchy:
      return std::make_unique<ceres::CauchyLoss>(scale_whitened);
    case Loss::kSoftL1:
      return std::make_unique<ceres::SoftLOneLoss>(scale_whitened);
  }
  return nullptr;
}

// Inverse of a symmetric positive definite 6x6 matrix by Cholesky, A = L L^T, A^-1 = L^-T L^-1;
// false if a pivot is not positive (as Eigen::LLT reports). Plain loops over fixed sizes: Eigen's
// LLT::solve goes through its blocked triangular solver, costly at this size.
bool InvertSpd6(const Mat6& A, Mat6* inv) {
  double L[6][6] = {}, M[6][6] = {};
  for (int j = 0; j < 6; ++j) {
    double d = A(j, j);
    for (int p = 0; p < j; ++p) d -= L[j][p] * L[j][p];
    if (!(d > 0)) return false;
    L[j][j] = std::sqrt(d);
    const double inv_ljj = 1.0 / L[j][j];
    for (int i = j + 1; i < 6; ++i) {
      double s = A(i, j);
      for (int p = 0; p < j; ++p) s -= L[i][p] * L[j][p];
      L[i][j] = s * inv_ljj;
    }
  }
  // M = L^-1 (lower triangular).
  for (int j = 0; j < 6; ++j) {
    M[j][j] = 1.0 / L[j][j];
    for (int i = j + 1; i < 6; ++i) {
      double s = 0;
      for (int p = j; p < i; ++p) s -= L[i][p] * M[p][j];
      M[i][j] = s / L[i][i];
    }
  }
  for (int i = 0; i < 6; ++i) {
    for (int j = i; j < 6; ++j) {
      double s = 0;
      for (int p = j; p < 6; ++p) s += M[p][i] * M[p][j];
      (*inv)(i, j) = (*inv)(j, i) = s;
    }
  }
  return true;
}

// Per point, the pose columns are taken for a small rotation w of the camera frame,
//   d(R p)/dw = -[R p]x,  so row a of J_uv_p_in_cam gives the row (R p) x a,
// and mapped to the rotation vector once per view, J_uv_rvec = J_uv_w J_l(rvec) (the chain rule
// of ProjectPointWithJac). All sizes are fixed: no heap allocation.
bool LineariseView(const std::vector<Eigen::Vector3d>& plate,
                   const std::vector<Eigen::Vector2d>& uv,
                   const double* intr,
                   const double* pose,
                   ViewSystem* out,
                   Mat9* Hcc,
                   Vec9* gc) {
  const Eigen::Matrix3d R = RotationOf(pose);
  const Eigen::Vector3d t(pose[3], pose[4], pose[5]);
  // Accumulated for [w, t] and the intrinsics.
  Mat6 Hpp = Mat6::Zero();
  Mat69 Hpc = Mat69::Zero();
  Mat9 Hcc_view = Mat9::Zero();
  Vec6 gp = Vec6::Zero();
  Vec9 gc_view = Vec9::Zero();
  for (size_t j = 0; j < plate.size(); ++j) {
    const Eigen::Vector3d Rp = R * plate[j];
    const Eigen::Vector3d pc = Rp + t;
    double q[2], Ji[2 * kNumIntrinsics], Jpc[6];
    if (!ProjectCamPointWithJac(intr, pc.data(), q, Ji, Jpc)) return false;
    Eigen::Matrix<double, 2, 6, Eigen::RowMajor> Jp;
    for (int r = 0; r < 2; ++r) {
      const double* a = Jpc + 3 * r;
      Jp(r, 0) = Rp.y() * a[2] - Rp.z() * a[1];
      Jp(r, 1) = Rp.z() * a[0] - Rp.x() * a[2];
      Jp(r, 2) = Rp.x() * a[1] - Rp.y() * a[0];
      Jp(r, 3) = a[0], Jp(r, 4) = a[1], Jp(r, 5) = a[2];
    }
    const Eigen::Map<const Eigen::Matrix<double, 2, kNumIntrinsics, Eigen::RowMajor>> Jc(Ji);
    Eigen::Vector2d e(q[0] - uv[j].x(), q[1] - uv[j].y());
    // Blocks by lazy (coefficient-wise, fixed-size) products: Eigen's default product sends
    // these sizes to its general GEMM.
    Hpp.noalias() += Jp.transpose().lazyProduct(Jp);
    Hpc.noalias() += Jp.transpose().lazyProduct(Jc);
    Hcc_view.noalias() += Jc.transpose().lazyProduct(Jc);
    gp.noalias() += Jp.transpose().lazyProduct(e);
    gc_view.noalias() += Jc.transpose().lazyProduct(e);
  }
  // [w, t] -> [rvec, t]: the rotation rows and columns times J_l.
  const Eigen::Matrix3d Jl = SO3LeftJacobian(pose);
  out->Hpp.topLeftCorner<3, 3>().noalias() = Jl.transpose() * Hpp.topLeftCorner<3, 3>() * Jl;
  out->Hpp.topRightCorner<3, 3>().noalias() = Jl.transpose() * Hpp.topRightCorner<3, 3>();
  out->Hpp.bottomLeftCorner<3, 3>() = out->Hpp.topRightCorner<3, 3>().transpose();
  out->Hpp.bottomRightCorner<3, 3>() = Hpp.bottomRightCorner<3, 3>();
  out->Hpc.topRows<3>().noalias() = Jl.transpose().lazyProduct(Hpc.topRows<3>());
  out->Hpc.bottomRows<3>() = Hpc.bottomRows<3>();
  out->gp.head<3>().noalias() = Jl.transpose() * gp.head<3>();
  out->gp.tail<3>() = gp.tail<3>();
  *Hcc += Hcc_view;
  *gc += gc_view;
  return true;
}

// Sum of squared residuals (px^2) of one view; false if a point is behind the source.
bool ViewCost(const std::vector<Eigen::Vector3d>& plate,
              const std::vector<Eigen::Vector2d>& uv,
              const double* intr,
              const double* pose,
              double* cost) {
  const Eigen::Matrix3d R = RotationOf(pose);
  const Eigen::Vector3d t(pose[3], pose[4], pose[5]);
  double c = 0;
  for (size_t j = 0; j < plate.size(); ++j) {
    const Eigen::Vector3d pc = R * plate[j] + t;
    double q[2];
    if (!ProjectCamPoint(intr, pc.data(), q)) return false;
    const double du = q[0] - uv[j].x(), dv = q[1] - uv[j].y();
    c += du * du + dv * dv;
  }
  *cost += c;
  return true;
}

Status SchurLevenbergMarquardt(const std::vector<std::vector<Eigen::Vector3d>>& plate,
                               const std::vector<std::vector<Eigen::Vector2d>>& uv,
                               const Eigen::MatrixXd& A,
                               int max_iterations,
                               double function_tolerance,
                               double initial_lambda,
                               std::array<double, kNumIntrinsics>* x,
                               std::vector<Pose6>* poses,
                               LmReport* report) {
  const int nv = static_cast<int>(plate.size());
  const int k = static_cast<int>(A.cols());
  const Eigen::MatrixXd At = A.transpose();
  std::vector<ViewSystem> sys(nv);
  std::vector<Mat69> Y(nv);  // (Hpp_i + lambda D_i)^-1 Hpc_i
  std::vector<Vec6> y(nv);   // (Hpp_i + lambda D_i)^-1 gp_i
  std::vector<Pose6> p_new(nv);
  Eigen::MatrixXd Hcc(k, k), S(k, k);
  Eigen::VectorXd gc(k), b(k), dc = Eigen::VectorXd::Zero(k);
  auto total_cost = [&](const std::array<double, kNumIntrinsics>& xi,
                        const std::vector<Pose6>& pi,
                        double* c) {
    *c = 0;
    for (int v = 0; v < nv; ++v) {
      if (!ViewCost(plate[v], uv[v], xi.data(), pi[v].data(), c)) return false;
    }
    return true;
  };
  double cost = 0;
  if (!total_cost(*x, *poses, &cost)) {
    return Status::Error("initialisation puts grid points behind the source (bad detections?)");
  }
  double lambda = initial_lambda;
  report->termination = Termination::kNoConvergence;
  for (int it = 0; it < max_iterations; ++it) {
    report->iterations = it + 1;
    // Linearise.
    Mat9 Hcc9 = Mat9::Zero();
    Vec9 gc9 = Vec9::Zero();
    for (int v = 0; v < nv; ++v) {
      if (!LineariseView(plate[v], uv[v], x->data(), (*poses)[v].data(), &sys[v], &Hcc9, &gc9)) {
        return Status::Error("a grid point moved behind the source during the adjustment");
      }
    }
    Hcc.noalias() = At * Hcc9 * A;
    gc.noalias() = At * gc9;
    // Damped steps until the cost drops (re-using the linearisation).
    bool accepted = false;
    for (int tries = 0; tries < 20 && !accepted; ++tries) {
      Mat9 reduction = Mat9::Zero();
      Vec9 reduction_g = Vec9::Zero();
      bool singular = false;
      for (int v = 0; v < nv; ++v) {
        Mat6 D = sys[v].Hpp, D_inv;
        D.diagonal() *= (1.0 + lambda);
        if (!InvertSpd6(D, &D_inv)) {
          singular = true;
          break;
        }
        Y[v].noalias() = D_inv.lazyProduct(sys[v].Hpc);
        y[v].noalias() = D_inv.lazyProduct(sys[v].gp);
        reduction.noalias() += sys[v].Hpc.transpose().lazyProduct(Y[v]);
        reduction_g.noalias() += sys[v].Hpc.transpose().lazyProduct(y[v]);
      }
      if (!singular && k > 0) {
        S = Hcc;
        S.diagonal() *= (1.0 + lambda);
        S.noalias() -= At * reduction * A;
        b = gc;
        b.noalias() -= At * reduction_g;
        Eigen::LDLT<Eigen::MatrixXd> ldlt(S);
        if (ldlt.info() != Eigen::Success) {
          singular = true;
        } else {
          dc = -ldlt.solve(b);
          if (!dc.allFinite()) singular = true;
        }
      }
      if (singular) {
        lambda *= 10;
        continue;
      }
      std::array<double, kNumIntrinsics> x_new = *x;
      const Vec9 dx = A * dc;
      for (int i = 0; i < kNumIntrinsics; ++i) x_new[i] += dx(i);
      for (int v = 0; v < nv; ++v) {
        const Vec6 dp = -(y[v] + Y[v] * dx);
        for (int i = 0; i < 6; ++i) p_new[v][i] = (*poses)[v][i] + dp(i);
      }
      double cost_new = 0;
      const bool ok_new = total_cost(x_new, p_new, &cost_new);
      if (ok_new && cost_new < cost) {
        const double rel = (cost - cost_new) / cost;
        *x = x_new;
        poses->swap(p_new);
        cost = cost_new;
        lambda = std::max(lambda / 3.0, 1e-12);
        accepted = true;
        if (rel < function_tolerance) {
          report->termination = Termination::kConvergence;
          return Status::Ok();
        }
      } else {
        lambda *= 4;
      }
    }
    if (!accepted) {
      // No damped step lowers the cost: at the minimum to machine precision.
      report->termination = Termination::kConvergence;
      return Status::Ok();
    }
  }
  return Status::Ok();
}
}  // namespace ba
}  // namespace carmba
