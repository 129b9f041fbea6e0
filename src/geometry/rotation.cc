#include "geometry/rotation.h"

#include <Eigen/Dense>

namespace carmba {

double ViewDirectionAngleOfMatrices(const Eigen::Matrix3d& Ra, const Eigen::Matrix3d& Rb) {
  const Eigen::Vector3d va = (Ra.inverse() * Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d vb = (Rb.inverse() * Eigen::Vector3d::UnitZ()).normalized();
  return std::atan2(va.cross(vb).norm(), va.dot(vb));
}

Eigen::Vector3d RvecFromRotation(const Eigen::Matrix3d& R) {
  Eigen::Vector3d r;
  ceres::RotationMatrixToAngleAxis(ceres::ColumnMajorAdapter3x3(R.data()), r.data());
  return r;
}

Eigen::Matrix3d NearestRotation(const Eigen::Matrix3d& M) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixU() * D * svd.matrixV().transpose();
}

double OrthonormalityError(const Eigen::Matrix3d& M) {
  return (M.transpose() * M - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
}

double AngleBetweenRotations(const Eigen::Matrix3d& Ra, const Eigen::Matrix3d& Rb) {
  const Eigen::Vector3d ra = RvecFromRotation(Ra), rb = RvecFromRotation(Rb);
  const double pa[6] = {ra[0], ra[1], ra[2], 0, 0, 0};
  const double pb[6] = {rb[0], rb[1], rb[2], 0, 0, 0};
  return RelativeRotationAngle(pa, pb);
}

void SO3LeftJacobian(const double* r, double* J) {
  const double t2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
  const double t = std::sqrt(t2);
  double A, B;  // J = I + A [r]x + B [r]x^2
  if (t < 1e-4) {
    // Taylor: A = 1/2 - t^2/24, B = 1/6 - t^2/120 (error < 1e-17 at t = 1e-4)
    A = 0.5 - t2 / 24.0;
    B = 1.0 / 6.0 - t2 / 120.0;
  } else {
    A = (1.0 - std::cos(t)) / t2;
    B = (t - std::sin(t)) / (t2 * t);
  }
  // [r]x = [0 -rz ry; rz 0 -rx; -ry rx 0];  [r]x^2 = r r^T - t2 I
  const double K[9] = {0, -r[2], r[1], r[2], 0, -r[0], -r[1], r[0], 0};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      const double K2 = r[i] * r[j] - (i == j ? t2 : 0.0);
      J[3 * i + j] = (i == j ? 1.0 : 0.0) + A * K[3 * i + j] + B * K2;
    }
  }
}

void RotatePointWithJac(const double* rvec, const double* p, double* Rp, double* J_Rp_r) {
  ceres::AngleAxisRotatePoint(rvec, p, Rp);
  if (!J_Rp_r) return;
  double Jl[9];
  SO3LeftJacobian(rvec, Jl);
  // -[q]x with q = R p:  [0 qz -qy; -qz 0 qx; qy -qx 0]
  const double M[9] = {0, Rp[2], -Rp[1], -Rp[2], 0, Rp[0], Rp[1], -Rp[0], 0};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      J_Rp_r[3 * i + j] = M[3 * i] * Jl[j] + M[3 * i + 1] * Jl[3 + j] + M[3 * i + 2] * Jl[6 + j];
    }
  }
}

Eigen::Matrix3d SO3LeftJacobian(const double* rvec) {
  Eigen::Matrix<double, 3, 3, Eigen::RowMajor> J;
  SO3LeftJacobian(rvec, J.data());
  return J;
}

}  // namespace carmba
