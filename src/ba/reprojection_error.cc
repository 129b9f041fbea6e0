#include "ba/reprojection_error.h"

#include <Eigen/Dense>
#include <cmath>

#include "geometry/rotation.h"

namespace carmba {

bool ReprojectionError::Evaluate(double const* const* parameters,
                                 double* residuals,
                                 double** jacobians) const {
  double* J_pose = jacobians ? jacobians[0] : nullptr;
  double* J_point = jacobians ? jacobians[1] : nullptr;
  double* J_intr = jacobians ? jacobians[2] : nullptr;
  double uv[2];
  if (!ProjectPointWithJac(parameters[2], parameters[0], parameters[1], uv, J_intr, J_pose,
                           J_point)) {
    return false;
  }
  // r = L^-1 e, L^-1 = [[a, 0], [b, c]]; each Jacobian (row-major 2 x n) likewise.
  const double e0 = uv[0] - u_, e1 = uv[1] - v_;
  residuals[0] = w_.a * e0;
  residuals[1] = w_.b * e0 + w_.c * e1;
  if (!std::isfinite(residuals[0]) || !std::isfinite(residuals[1])) return false;
  auto whiten = [this](double* J, int n) {
    for (int i = 0; i < n; ++i) {
      const double d0 = J[i], d1 = J[n + i];
      J[i] = w_.a * d0;
      J[n + i] = w_.b * d0 + w_.c * d1;
    }
  };
  if (J_pose) whiten(J_pose, 6);
  if (J_point) whiten(J_point, 3);
  if (J_intr) whiten(J_intr, kNumIntrinsics);
  return true;
}

RigReprojectionError::RigReprojectionError(double u_px, double v_px, const PixelWhitening& w,
                                           const double* cam_from_rig)
    : u_(u_px), v_(v_px), w_(w) {
  ceres::AngleAxisToRotationMatrix(cam_from_rig, ceres::ColumnMajorAdapter3x3(Rc_.data()));
  tc_ = Eigen::Vector3d(cam_from_rig[3], cam_from_rig[4], cam_from_rig[5]);
}

bool RigReprojectionError::Evaluate(double const* const* parameters,
                                    double* residuals,
                                    double** jacobians) const {
  const double* rig_pose = parameters[0];
  const double* point = parameters[1];
  double* J_pose = jacobians ? jacobians[0] : nullptr;
  double* J_point = jacobians ? jacobians[1] : nullptr;
  double* J_intr = jacobians ? jacobians[2] : nullptr;
  Eigen::Vector3d Rp;
  Eigen::Matrix<double, 3, 3, Eigen::RowMajor> J_Rp_r;
  RotatePointWithJac(rig_pose, point, Rp.data(), J_pose ? J_Rp_r.data() : nullptr);
  const Eigen::Vector3d p_cam =
      Rc_ * (Rp + Eigen::Vector3d(rig_pose[3], rig_pose[4], rig_pose[5])) + tc_;
  double uv[2];
  Eigen::Matrix<double, 2, 3, Eigen::RowMajor> J_cam;
  if (!ProjectCamPointWithJac(parameters[2], p_cam.data(), uv, J_intr,
                              (J_pose || J_point) ? J_cam.data() : nullptr)) {
    return false;
  }
  Eigen::Matrix2d L_inv;
  L_inv << w_.a, 0, w_.b, w_.c;
  const Eigen::Vector2d r = L_inv * Eigen::Vector2d(uv[0] - u_, uv[1] - v_);
  residuals[0] = r[0];
  residuals[1] = r[1];
  if (!r.allFinite()) return false;
  const Eigen::Matrix<double, 2, 3> J_rig = L_inv * J_cam * Rc_;  // whitened d r / d p_in_rig
  if (J_pose) {
    Eigen::Map<Eigen::Matrix<double, 2, 6, Eigen::RowMajor>> J(J_pose);
    J.leftCols<3>() = J_rig * J_Rp_r;
    J.rightCols<3>() = J_rig;
  }
  if (J_point) {
    Eigen::Matrix3d R;
    ceres::AngleAxisToRotationMatrix(rig_pose, ceres::ColumnMajorAdapter3x3(R.data()));
    Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> J(J_point);
    J = J_rig * R;
  }
  if (J_intr) {
    Eigen::Map<Eigen::Matrix<double, 2, kNumIntrinsics, Eigen::RowMajor>> J(J_intr);
    J = (L_inv * J).eval();
  }
  return true;
}

bool PixelWhitening::FromCovariance(const Eigen::Matrix2d& C, PixelWhitening* w) {
  if (!C.allFinite() ||
      std::abs(C(0, 1) - C(1, 0)) > 1e-12 * (std::abs(C(0, 0)) + std::abs(C(1, 1))) ||
      !(C(0, 0) > 0)) {
    return false;
  }
  const double l00 = std::sqrt(C(0, 0));
  const double l10 = C(1, 0) / l00;
  const double d = C(1, 1) - l10 * l10;
  if (!(d > 0)) return false;
  const double l11 = std::sqrt(d);
  *w = {1.0 / l00, -l10 / (l00 * l11), 1.0 / l11};
  return std::isfinite(w->a) && std::isfinite(w->b) && std::isfinite(w->c);
}

PlateViewReprojection::PlateViewReprojection(std::vector<Eigen::Vector3d> p_in_plate,
                                             std::vector<Eigen::Vector2d> uv_px,
                                             double sigma_px)
    : p_(std::move(p_in_plate)), uv_(std::move(uv_px)), inv_sigma_(1.0 / sigma_px) {
  set_num_residuals(2 * static_cast<int>(p_.size()));
  mutable_parameter_block_sizes()->push_back(6);
  mutable_parameter_block_sizes()->push_back(kNumIntrinsics);
}

bool PlateViewReprojection::Evaluate(double const* const* parameters,
                                     double* residuals,
                                     double** jacobians) const {
  const double* pose = parameters[0];
  const double* intrinsics = parameters[1];
  double* J_pose = jacobians ? jacobians[0] : nullptr;
  double* J_intr = jacobians ? jacobians[1] : nullptr;
  for (size_t i = 0; i < p_.size(); ++i) {
    double uv[2];
    double* Jp = J_pose ? J_pose + 12 * i : nullptr;
    double* Ji = J_intr ? J_intr + 2 * kNumIntrinsics * i : nullptr;
    if (!ProjectPointWithJac(intrinsics, pose, p_[i].data(), uv, Ji, Jp, nullptr)) return false;
    residuals[2 * i] = (uv[0] - uv_[i].x()) * inv_sigma_;
    residuals[2 * i + 1] = (uv[1] - uv_[i].y()) * inv_sigma_;
    if (!std::isfinite(residuals[2 * i]) || !std::isfinite(residuals[2 * i + 1])) return false;
    if (Jp) for (int k = 0; k < 12; ++k) Jp[k] *= inv_sigma_;
    if (Ji) for (int k = 0; k < 2 * kNumIntrinsics; ++k) Ji[k] *= inv_sigma_;
  }
  return true;
}

bool SqrtInformation(const Eigen::Matrix3d& covariance, Eigen::Matrix3d* S) {
  if (!covariance.allFinite() || (covariance - covariance.transpose()).norm() >
                                     1e-9 * (1.0 + covariance.norm())) {
    return false;
  }
  Eigen::LLT<Eigen::Matrix3d> llt(covariance.inverse());
  if (!covariance.inverse().allFinite() || llt.info() != Eigen::Success) return false;
  // information = L L^T  =>  S = L^T satisfies S^T S = information.
  *S = llt.matrixL().transpose();
  return S->allFinite();
}

bool PointPriorRows::Evaluate(double const* const* parameters,
                              double* residuals,
                              double** jacobians) const {
  const Eigen::Map<const Eigen::Vector3d> p(parameters[0]);
  Eigen::Map<Eigen::Vector2d> r(residuals);
  r = A_ * (p - p_measured_);
  if (!r.allFinite()) return false;
  if (jacobians && jacobians[0]) {
    Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> J(jacobians[0]);
    J = A_;
  }
  return true;
}

std::pair<PointPriorRows*, PointPriorRows*> PointPriorRows::Split(
    const Eigen::Vector3d& p_measured, const Eigen::Matrix3d& sqrt_information) {
  Eigen::Matrix<double, 2, 3> top = sqrt_information.topRows<2>();
  Eigen::Matrix<double, 2, 3> last = Eigen::Matrix<double, 2, 3>::Zero();
  last.row(0) = sqrt_information.row(2);
  return {new PointPriorRows(p_measured, top), new PointPriorRows(p_measured, last)};
}

}  // namespace carmba
