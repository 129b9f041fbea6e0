#include "ba/smooth_intrinsics.h"

#include <cmath>

#include "ba/reprojection_error.h"
#include "camera/camera.h"

namespace carmba {
namespace ba {

Eigen::VectorXd SmoothBasis::Evaluate(double a, double b) const {
  Eigen::VectorXd phi(NumTerms());
  int k = 0;
  phi[k++] = 1.0;
  for (int n = 1; n <= primary_order; ++n) {
    phi[k++] = std::cos(n * a);
    phi[k++] = std::sin(n * a);
  }
  double bp = 1.0;
  for (int n = 1; n <= secondary_degree; ++n) {
    bp *= b;
    phi[k++] = bp;
  }
  return phi;
}

std::string SmoothBasis::TermName(int k) const {
  if (k == 0) return "1";
  if (k <= 2 * primary_order) {
    const int n = (k + 1) / 2;
    const std::string arg = n == 1 ? "p" : std::to_string(n) + "p";
    return (k % 2 ? "cos(" : "sin(") + arg + ")";
  }
  const int n = k - 2 * primary_order;
  return n == 1 ? "sec" : "sec^" + std::to_string(n);
}

int SmoothBasis::IntrinsicOf(int i) const {
  const int K = NumTerms();
  return i < 4 * K ? i / K : kK1 + (i - 4 * K);
}

std::string SmoothBasis::ParameterName(int i) const {
  const int K = NumTerms();
  if (i >= 4 * K) return kIntrinsicNames[IntrinsicOf(i)];
  return std::string(kIntrinsicNames[i / K]) + " " + TermName(i % K);
}

Eigen::MatrixXd SmoothBasis::Map(double a, double b) const {
  const int K = NumTerms();
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(kNumIntrinsics, BlockSize());
  const Eigen::VectorXd phi = Evaluate(a, b);
  for (int r = 0; r < 4; ++r) A.block(r, r * K, 1, K) = phi.transpose();
  for (int r = 0; r < 5; ++r) A(kK1 + r, 4 * K + r) = 1.0;
  return A;
}

std::vector<double> SmoothBasis::ConstantCoefficients(
    const std::array<double, kNumIntrinsics>& x) const {
  const int K = NumTerms();
  std::vector<double> c(BlockSize(), 0.0);
  for (int r = 0; r < 4; ++r) c[r * K] = x[r];
  for (int r = 0; r < 5; ++r) c[4 * K + r] = x[kK1 + r];
  return c;
}

std::array<double, kNumIntrinsics> SmoothIntrinsicsAt(const Eigen::MatrixXd& A, const double* c) {
  const Eigen::VectorXd x = A * Eigen::Map<const Eigen::VectorXd>(c, A.cols());
  std::array<double, kNumIntrinsics> out;
  for (int i = 0; i < kNumIntrinsics; ++i) out[i] = x[i];
  return out;
}

SmoothReprojectionError::SmoothReprojectionError(double u_px,
                                                 double v_px,
                                                 double sigma_px,
                                                 const Eigen::MatrixXd& A)
    : u_(u_px), v_(v_px), sigma_(sigma_px), A_(A) {
  set_num_residuals(2);
  mutable_parameter_block_sizes()->push_back(6);
  mutable_parameter_block_sizes()->push_back(3);
  mutable_parameter_block_sizes()->push_back(static_cast<int>(A.cols()));
}

// r = (project(A c, pose, p) - uv) / sigma:  dr/dpose, dr/dp as ReprojectionError's;
// dr/dc = (d r / d intrinsics) A   (the intrinsics are linear in c).
bool SmoothReprojectionError::Evaluate(double const* const* parameters,
                                       double* residuals,
                                       double** jacobians) const {
  const Eigen::Index n = A_.cols();
  const std::array<double, kNumIntrinsics> intr = SmoothIntrinsicsAt(A_, parameters[2]);
  const double* params[3] = {parameters[0], parameters[1], intr.data()};
  Eigen::Matrix<double, 2, kNumIntrinsics, Eigen::RowMajor> J_intr;
  double* jac[3] = {jacobians ? jacobians[0] : nullptr, jacobians ? jacobians[1] : nullptr,
                    jacobians && jacobians[2] ? J_intr.data() : nullptr};
  const ReprojectionError base(u_, v_, sigma_);
  if (!base.Evaluate(params, residuals, jacobians ? jac : nullptr)) return false;
  if (jacobians && jacobians[2]) {
    Eigen::Map<Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor>>(jacobians[2], 2, n) =
        J_intr * A_;
  }
  return true;
}

}  // namespace ba
}  // namespace carmba
