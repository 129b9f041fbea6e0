// Prior residuals of the bundle-adjustment engine (ba/problem.h), analytic with autodiff twins.
//
// Point priors (CT prior on a marker, manufacturing prior on a plate point) are PointPriorRows
// (ba/reprojection_error.h): r = A (p - p_measured), A 2x3 rows of the square-root information.
// PointPriorRowsAutoDiff is its twin.
//
// Intrinsics prior: an earlier calibration's estimate m of the intrinsics with indices I (a
// subset of [fx .. k3]) and covariance C (|I| x |I|):
//   r = S (x_I - m_I),  S^T S = C^-1  (S upper triangular: S = L^T with L L^T = C^-1)
//   dr/dx = S on the columns I, 0 elsewhere.
#pragma once

#include <ceres/autodiff_cost_function.h>
#include <ceres/dynamic_autodiff_cost_function.h>
#include <ceres/cost_function.h>

#include <Eigen/Dense>
#include <vector>

#include "camera/camera_model.h"

namespace carmba {
namespace ba {

class IntrinsicsPriorError final : public ceres::CostFunction {
 public:
  // `mean` holds all 9 intrinsics (only those in `indices` are used); `sqrt_information` is
  // |indices| x |indices|.
  IntrinsicsPriorError(const double* mean,
                       std::vector<int> indices,
                       const Eigen::MatrixXd& sqrt_information);

  bool Evaluate(double const* const* parameters,
                double* residuals,
                double** jacobians) const override;

 private:
  std::vector<double> mean_;
  std::vector<int> indices_;
  Eigen::MatrixXd S_;
};

// The autodiff twin (a ceres::DynamicAutoDiffCostFunction of one 9-parameter block).
struct IntrinsicsPriorAutoDiff {
  IntrinsicsPriorAutoDiff(const double* mean, std::vector<int> idx, const Eigen::MatrixXd& S)
      : mean_I(), indices(std::move(idx)), sqrt_information(S) {
    for (int i : indices) mean_I.push_back(mean[i]);
  }
  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    const int n = static_cast<int>(indices.size());
    for (int r = 0; r < n; ++r) {
      T acc(0.0);
      for (int c = 0; c < n; ++c) {
        acc += T(sqrt_information(r, c)) * (parameters[0][indices[c]] - T(mean_I[c]));
      }
      residuals[r] = acc;
    }
    return true;
  }
  static ceres::CostFunction* Create(const double* mean,
                                     const std::vector<int>& indices,
                                     const Eigen::MatrixXd& S) {
    auto* f = new ceres::DynamicAutoDiffCostFunction<IntrinsicsPriorAutoDiff, 9>(
        new IntrinsicsPriorAutoDiff(mean, indices, S));
    f->AddParameterBlock(kNumIntrinsics);
    f->SetNumResiduals(static_cast<int>(indices.size()));
    return f;
  }
  std::vector<double> mean_I;
  std::vector<int> indices;
  Eigen::MatrixXd sqrt_information;
};

struct PointPriorRowsAutoDiff {
  PointPriorRowsAutoDiff(const Eigen::Vector3d& p, const Eigen::Matrix<double, 2, 3>& a)
      : p_measured(p), A(a) {}
  template <typename T>
  bool operator()(const T* p, T* residuals) const {
    for (int r = 0; r < 2; ++r) {
      residuals[r] = T(A(r, 0)) * (p[0] - T(p_measured[0])) +
                     T(A(r, 1)) * (p[1] - T(p_measured[1])) +
                     T(A(r, 2)) * (p[2] - T(p_measured[2]));
    }
    return true;
  }
  static ceres::CostFunction* Create(const Eigen::Vector3d& p,
                                     const Eigen::Matrix<double, 2, 3>& a) {
    return new ceres::AutoDiffCostFunction<PointPriorRowsAutoDiff, 2, 3>(
        new PointPriorRowsAutoDiff(p, a));
  }
  Eigen::Vector3d p_measured;
  Eigen::Matrix<double, 2, 3> A;
};

// The upper-triangular square-root information S (S^T S = C^-1) of an n x n covariance, or false
// if it is not symmetric positive definite.
bool SqrtInformationN(const Eigen::MatrixXd& covariance, Eigen::MatrixXd* S);

}  // namespace ba
}  // namespace carmba
