#include "geometry/rotation.h"

#include <Eigen/Dense>

namespace carmba {

double ViewDirectionAngleOfMatrices(const Eigen::Matrix3d& Ra, const Eigen::Matrix3d& Rb) {
  const Eigen::Vector3d va = (Ra.inverse() * Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d vb = (Rb.inverse() * Eigen::Vector3d::UnitZ()).normalized();
  return std::atan2(va.cross(vb).norm(), va.dot(vb));
}

Eigen::Matrix3d RotationFromRvec(const Eigen::Vector3d& rvec) {
  Eigen::Matrix3d R;
  ceres::AngleAxisToRotationMatrix(rvec.data(), ceres::ColumnMajorAdapter3x3(R.data()));
  return R;
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

}  // namespace carmba
