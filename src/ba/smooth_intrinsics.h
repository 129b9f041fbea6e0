// Orientation-dependent ("smooth") intrinsics of a C-arm that flexes under its own weight
// (issue 14; shared/notes/joint-ba.md "C-arm flex"): fx, fy, cx, cy of a view are low-order
// functions of the view's C-arm angles, distortion is shared. The coefficients are the
// parameters of the bundle adjustment; a view's intrinsics and their covariance follow from them.
//
// BASIS (a = primary angle, LAO +; b = secondary angle, cranial +; radians):
//   phi(a, b) = [1, cos a, sin a, ..., cos(P a), sin(P a), b, b^2, ..., b^S]     (K = 1 + 2P + S)
// a Fourier series of order P in the primary angle (the C-arm's orbit is periodic) plus a
// polynomial of degree S in the secondary angle, no cross terms. Defaults P = 1, S = 1: K = 4.
//
// PARAMETER BLOCK of a smooth intrinsics group (size 4K + 5):
//   [fx_0 .. fx_{K-1}, fy_0 .., cx_0 .., cy_0 .., k1, k2, p1, p2, k3]
// and the view's OPENCV5 intrinsics are linear in it:
//   intrinsics(a, b) = A(a, b) c,  A (9 x (4K+5)): rows fx..cy are phi^T on their coefficient
//   columns, rows k1..k3 pick the distortion.  So J_uv_c = J_uv_intrinsics A (exact), and the
//   covariance of a view's intrinsics is A C_c A^T.
// Coefficient names (covariance output): "fx 1", "fx cos(p)", "fx sin(p)", "cx sec", "cx sec^2",
// ... ("p": primary, "sec": secondary).
//
// SmoothReprojectionError is the reprojection residual (ba/reprojection_error.h) of a view of a
// smooth group: parameter blocks pose (6), point (3), coefficients (4K+5). Analytic (the 2x9
// Jacobian of ReprojectionError times A) with an autodiff twin.
#pragma once

#include <ceres/cost_function.h>
#include <ceres/dynamic_autodiff_cost_function.h>

#include <Eigen/Dense>
#include <array>
#include <string>
#include <vector>

#include "camera/camera_model.h"

namespace carmba {
namespace ba {

struct SmoothBasis {
  int primary_order = 1;     // P: Fourier order in the primary angle (>= 0)
  int secondary_degree = 1;  // S: polynomial degree in the secondary angle (>= 0)

  int NumTerms() const { return 1 + 2 * primary_order + secondary_degree; }  // K
  int BlockSize() const { return 4 * NumTerms() + 5; }
  // phi(a, b), angles in radians.
  Eigen::VectorXd Evaluate(double primary_rad, double secondary_rad) const;
  // "1", "cos(p)", "sin(p)", "cos(2p)", ..., "sec", "sec^2", ...
  std::string TermName(int k) const;
  // Name of parameter i of the block: "fx cos(p)", ..., "k1".
  std::string ParameterName(int i) const;
  // The intrinsic (kFx .. kK3) parameter i of the block belongs to.
  int IntrinsicOf(int i) const;
  // A(a, b): 9 x BlockSize().
  Eigen::MatrixXd Map(double primary_rad, double secondary_rad) const;
  // The block whose intrinsics are `intrinsics` at every angle (constant terms, distortion).
  std::vector<double> ConstantCoefficients(
      const std::array<double, kNumIntrinsics>& intrinsics) const;
};

// The view's intrinsics A c.
std::array<double, kNumIntrinsics> SmoothIntrinsicsAt(const Eigen::MatrixXd& A, const double* c);

class SmoothReprojectionError final : public ceres::CostFunction {
 public:
  // A: the view's map (SmoothBasis::Map at its angles).
  SmoothReprojectionError(double u_px, double v_px, double sigma_px, const Eigen::MatrixXd& A);

  bool Evaluate(double const* const* parameters,
                double* residuals,
                double** jacobians) const override;

 private:
  double u_, v_, sigma_;
  Eigen::Matrix<double, kNumIntrinsics, Eigen::Dynamic, Eigen::RowMajor> A_;
};

// The autodiff twin: intrinsics = A c on Jets, then ProjectPoint.
struct SmoothReprojectionErrorAutoDiff {
  SmoothReprojectionErrorAutoDiff(double u_px,
                                  double v_px,
                                  double sigma_px,
                                  const Eigen::MatrixXd& a)
      : u(u_px), v(v_px), inv_sigma(1.0 / sigma_px), A(a) {}

  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    T intr[kNumIntrinsics];
    for (int r = 0; r < kNumIntrinsics; ++r) {
      intr[r] = T(0.0);
      for (Eigen::Index c = 0; c < A.cols(); ++c) {
        if (A(r, c) != 0.0) intr[r] += T(A(r, c)) * parameters[2][c];
      }
    }
    T uv[2];
    if (!ProjectPoint(intr, parameters[0], parameters[1], uv)) return false;
    residuals[0] = (uv[0] - T(u)) * T(inv_sigma);
    residuals[1] = (uv[1] - T(v)) * T(inv_sigma);
    return true;
  }

  static ceres::CostFunction* Create(double u_px,
                                     double v_px,
                                     double sigma_px,
                                     const Eigen::MatrixXd& A) {
    auto* f = new ceres::DynamicAutoDiffCostFunction<SmoothReprojectionErrorAutoDiff, 8>(
        new SmoothReprojectionErrorAutoDiff(u_px, v_px, sigma_px, A));
    f->AddParameterBlock(6);
    f->AddParameterBlock(3);
    f->AddParameterBlock(static_cast<int>(A.cols()));
    f->SetNumResiduals(2);
    return f;
  }

  double u, v, inv_sigma;
  Eigen::MatrixXd A;
};

}  // namespace ba
}  // namespace carmba
