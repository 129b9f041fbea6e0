#include "problem/pose_covariance.h"

#include <cmath>
#include <string>

namespace carmba {
namespace {

using Mat26 = Eigen::Matrix<double, 2, 6, Eigen::RowMajor>;
using Mat23 = Eigen::Matrix<double, 2, 3, Eigen::RowMajor>;

// Ceres's robust-loss correction of a block's Jacobian (ceres/internal/corrector.cc): with
// s = |r|^2 and rho = (rho(s), rho'(s), rho''(s)),
//   J <- sqrt(rho') (I - alpha r r^T / s) J,   alpha = 1 - sqrt(1 + 2 s rho'' / rho'),
// where alpha = 0 if s = 0 or rho'' <= 0.
template <typename JacobianType>
void CorrectForLoss(const ceres::LossFunction& loss, const Eigen::Vector2d& r, JacobianType* J) {
  const double s = r.squaredNorm();
  double rho[3];
  loss.Evaluate(s, rho);
  const double sqrt_rho1 = std::sqrt(rho[1]);
  if (s == 0.0 || rho[2] <= 0.0) {
    *J *= sqrt_rho1;
    return;
  }
  const double alpha = 1.0 - std::sqrt(1.0 + 2.0 * s * rho[2] / rho[1]);
  const Eigen::Matrix2d P = Eigen::Matrix2d::Identity() - (alpha / s) * r * r.transpose();
  *J = sqrt_rho1 * (P * *J);
}

}  // namespace

StatusOr<Eigen::MatrixXd> PoseCovarianceBySchur(const PoseCovarianceInput& in) {
  const int V = static_cast<int>(in.poses.size());
  const int M = static_cast<int>(in.markers.size());
  if (static_cast<int>(in.marker_information.size()) != M) {
    return Status::Error("covariance: one CT information matrix per marker expected");
  }
  std::vector<Eigen::Matrix<double, 6, 6>> A(V, Eigen::Matrix<double, 6, 6>::Zero());
  std::vector<Eigen::Matrix3d> D(in.marker_information);
  // B blocks (view v, marker k), stored densely: V x M is small (views x markers of one object).
  std::vector<Eigen::Matrix<double, 6, 3>> B(static_cast<size_t>(V) * M);
  std::vector<char> has_B(static_cast<size_t>(V) * M, 0);

  for (const PoseCovarianceBlock& b : in.blocks) {
    if (b.view < 0 || b.view >= V || b.marker < 0 || b.marker >= M || b.cost == nullptr) {
      return Status::Error("covariance: a residual block refers to an unknown view or marker");
    }
    const double* params[3] = {in.poses[b.view], in.markers[b.marker], in.intrinsics};
    Eigen::Vector2d r;
    Mat26 Jp;
    Mat23 Jm;
    double* jac[3] = {Jp.data(), Jm.data(), nullptr};
    if (!b.cost->Evaluate(params, r.data(), jac) || !r.allFinite() || !Jp.allFinite() ||
        !Jm.allFinite()) {
      return Status::Error("covariance: a reprojection residual cannot be evaluated at the "
                           "solution (marker behind the source?)");
    }
    if (b.loss != nullptr) {
      // The correction acts on the rows, so it applies to each column block on its own.
      CorrectForLoss(*b.loss, r, &Jp);
      CorrectForLoss(*b.loss, r, &Jm);
    }
    A[b.view].noalias() += Jp.transpose() * Jp;
    D[b.marker].noalias() += Jm.transpose() * Jm;
    const size_t idx = static_cast<size_t>(b.view) * M + b.marker;
    if (!has_B[idx]) B[idx].setZero(), has_B[idx] = 1;
    B[idx].noalias() += Jp.transpose() * Jm;
  }

  // Reduced system S = A - B D^-1 B^T over the views.
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(6 * V, 6 * V);
  for (int v = 0; v < V; ++v) S.block<6, 6>(6 * v, 6 * v) = A[v];
  std::vector<int> seen_by;
  for (int k = 0; k < M; ++k) {
    Eigen::LLT<Eigen::Matrix3d> llt(D[k]);
    if (llt.info() != Eigen::Success || !D[k].allFinite()) {
      return Status::Error("covariance: marker " + std::to_string(k) +
                           " has a singular information matrix");
    }
    const Eigen::Matrix3d D_inv = D[k].inverse();  // positive definite (checked above), 3x3
    seen_by.clear();
    for (int v = 0; v < V; ++v) {
      if (has_B[static_cast<size_t>(v) * M + k]) seen_by.push_back(v);
    }
    for (int v : seen_by) {
      const Eigen::Matrix<double, 3, 6> DinvBt = D_inv * B[static_cast<size_t>(v) * M + k].transpose();
      for (int w : seen_by) {
        S.block<6, 6>(6 * w, 6 * v).noalias() -= B[static_cast<size_t>(w) * M + k] * DinvBt;
      }
    }
  }
  S = 0.5 * (S + S.transpose()).eval();

  // Jacobi scaling, then a Cholesky factorisation with its reciprocal condition estimate gives
  // both the rank test and the inverse.
  const Eigen::VectorXd d = S.diagonal();
  if (!S.allFinite() || (d.array() <= 0).any()) {
    return Status::Error("covariance: a pose is not constrained by its observations");
  }
  const Eigen::VectorXd inv_sqrt_d = d.cwiseSqrt().cwiseInverse();
  const Eigen::MatrixXd Sc = inv_sqrt_d.asDiagonal() * S * inv_sqrt_d.asDiagonal();
  Eigen::LLT<Eigen::MatrixXd> llt(Sc);
  const double rcond = llt.info() == Eigen::Success ? llt.rcond() : 0.0;
  if (!(rcond > in.min_reciprocal_condition_number)) {
    return Status::Error("covariance: rank-deficient information (reciprocal condition " +
                         std::to_string(rcond) + ")");
  }
  const Eigen::MatrixXd Sc_inv = llt.solve(Eigen::MatrixXd::Identity(6 * V, 6 * V));
  Eigen::MatrixXd cov = inv_sqrt_d.asDiagonal() * Sc_inv * inv_sqrt_d.asDiagonal();
  return Eigen::MatrixXd(0.5 * (cov + cov.transpose()));
}

}  // namespace carmba
