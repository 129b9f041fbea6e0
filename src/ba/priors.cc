#include "ba/priors.h"

#include <cmath>

namespace carmba {
namespace ba {

IntrinsicsPriorError::IntrinsicsPriorError(const double* mean,
                                           std::vector<int> indices,
                                           const Eigen::MatrixXd& sqrt_information)
    : mean_(mean, mean + kNumIntrinsics), indices_(std::move(indices)), S_(sqrt_information) {
  set_num_residuals(static_cast<int>(indices_.size()));
  mutable_parameter_block_sizes()->push_back(kNumIntrinsics);
}

bool IntrinsicsPriorError::Evaluate(double const* const* parameters,
                                    double* residuals,
                                    double** jacobians) const {
  const int n = static_cast<int>(indices_.size());
  Eigen::VectorXd d(n);
  for (int c = 0; c < n; ++c) d[c] = parameters[0][indices_[c]] - mean_[indices_[c]];
  Eigen::Map<Eigen::VectorXd> r(residuals, n);
  r = S_ * d;
  if (!r.allFinite()) return false;
  if (jacobians && jacobians[0]) {
    // dr/dx: S on the prior's columns, zero elsewhere (row-major n x 9).
    Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, kNumIntrinsics, Eigen::RowMajor>> J(
        jacobians[0], n, kNumIntrinsics);
    J.setZero();
    for (int c = 0; c < n; ++c) J.col(indices_[c]) = S_.col(c);
  }
  return true;
}

bool SqrtInformationN(const Eigen::MatrixXd& covariance, Eigen::MatrixXd* S) {
  if (covariance.rows() != covariance.cols() || !covariance.allFinite() ||
      (covariance - covariance.transpose()).norm() > 1e-9 * (1.0 + covariance.norm())) {
    return false;
  }
  Eigen::LLT<Eigen::MatrixXd> llt_c(covariance);
  if (llt_c.info() != Eigen::Success) return false;
  const Eigen::MatrixXd information =
      llt_c.solve(Eigen::MatrixXd::Identity(covariance.rows(), covariance.cols()));
  Eigen::LLT<Eigen::MatrixXd> llt(0.5 * (information + information.transpose()));
  if (llt.info() != Eigen::Success) return false;
  *S = llt.matrixL().transpose();
  return S->allFinite();
}

}  // namespace ba
}  // namespace carmba
