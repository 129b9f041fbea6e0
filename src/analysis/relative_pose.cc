#include "analysis/relative_pose.h"

#include <cmath>
#include <map>

#include "camera/camera_model.h"
#include "geometry/rotation.h"

namespace carmba {
namespace analysis {

Pose6 RelativePoseWithJacobian(const Pose6& pose_a,
                               const Pose6& pose_b,
                               Eigen::Matrix<double, 6, 12>* J) {
  using Jet = ceres::Jet<double, 12>;
  Jet pa[6], pb[6], rel[6];
  for (int i = 0; i < 6; ++i) {
    pa[i] = Jet(pose_a[i], i);
    pb[i] = Jet(pose_b[i], 6 + i);
  }
  RelativePose(pa, pb, rel);
  Pose6 out;
  for (int i = 0; i < 6; ++i) {
    out[i] = rel[i].a;
    if (J) J->row(i) = rel[i].v.transpose();
  }
  return out;
}

RelativePoseEstimate EstimateRelativePose(const ba::BaResult& result, int view_a, int view_b) {
  return EstimateRelativePoses(result, {{view_a, view_b}}).front();
}

RelativePoseEstimate EstimateRelativePose(const Pose6& pa,
                                          const Pose6& pb,
                                          const Eigen::Matrix<double, 12, 12>& C) {
  RelativePoseEstimate e;
  Eigen::Matrix<double, 6, 12> J;
  e.cam_b_from_cam_a = RelativePoseWithJacobian(pa, pb, &J);
  e.covariance = J * C * J.transpose();
  e.covariance = 0.5 * (e.covariance + e.covariance.transpose()).eval();
  Eigen::Matrix<double, 12, 1> g;
  e.angle_deg = PairMetricWithGradient(pa.data(), pb.data(),
                                       [](auto* a, auto* b) { return RelativeRotationAngle(a, b); },
                                       g.data()) *
                kRadToDeg;
  e.sigma_angle_deg = std::sqrt(std::max(0.0, g.dot(C * g))) * kRadToDeg;
  Eigen::Matrix3d Jl;
  SO3LeftJacobian(e.cam_b_from_cam_a.data(), Jl.data());
  Jl.transposeInPlace();  // row-major into column-major storage
  const Eigen::Matrix3d local = Jl * e.covariance.topLeftCorner<3, 3>() * Jl.transpose();
  e.sigma_rotation_deg = local.diagonal().cwiseMax(0.0).cwiseSqrt() * kRadToDeg;
  e.sigma_translation_mm =
      e.covariance.bottomRightCorner<3, 3>().diagonal().cwiseMax(0.0).cwiseSqrt();
  e.baseline_mm = e.cam_b_from_cam_a.tail<3>().norm();
  return e;
}

RelativePoseEstimate EstimateRelativePose(const Pose6& pa,
                                          const Pose6& pb,
                                          const Eigen::Matrix<double, 12, 12>& C,
                                          const Eigen::Matrix<double, 12, 12>& C_cal) {
  RelativePoseEstimate e = EstimateRelativePose(pa, pb, C);
  Eigen::Matrix<double, 6, 12> J;
  RelativePoseWithJacobian(pa, pb, &J);
  e.covariance_calibration = J * C_cal * J.transpose();
  e.covariance_calibration =
      0.5 * (e.covariance_calibration + e.covariance_calibration.transpose()).eval();
  Eigen::Matrix<double, 12, 1> g;
  PairMetricWithGradient(pa.data(), pb.data(),
                         [](auto* a, auto* b) { return RelativeRotationAngle(a, b); }, g.data());
  e.sigma_angle_calibration_deg = std::sqrt(std::max(0.0, g.dot(C_cal * g))) * kRadToDeg;
  return e;
}

std::vector<RelativePoseEstimate> EstimateRelativePoses(
    const ba::BaResult& result, const std::vector<std::pair<int, int>>& pairs) {
  std::map<int, int> slot;  // view -> position in the joint covariance
  std::vector<int> views;
  for (const auto& [a, b] : pairs) {
    for (int v : {a, b}) {
      if (slot.emplace(v, static_cast<int>(views.size())).second) views.push_back(v);
    }
  }
  std::vector<RelativePoseEstimate> out;
  if (pairs.empty()) return out;
  // The two parts of BaResult::Covariance, the calibration's computed once.
  const std::vector<int> blocks = result.ViewBlocks(views);
  const Eigen::MatrixXd C_cal = result.CalibrationCovariance(blocks);
  const Eigen::MatrixXd C = result.ObservationCovariance(blocks) + C_cal;  // scaled
  for (const auto& [a, b] : pairs) {
    Eigen::Matrix<double, 12, 12> Cab, Cab_cal;
    const int s[2] = {slot.at(a), slot.at(b)};
    for (int i = 0; i < 2; ++i) {
      for (int k = 0; k < 2; ++k) {
        Cab.block<6, 6>(6 * i, 6 * k) = C.block<6, 6>(6 * s[i], 6 * s[k]);
        Cab_cal.block<6, 6>(6 * i, 6 * k) = C_cal.block<6, 6>(6 * s[i], 6 * s[k]);
      }
    }
    RelativePoseEstimate e =
        EstimateRelativePose(result.ViewPose(a), result.ViewPose(b), Cab, Cab_cal);
    e.view_a = a;
    e.view_b = b;
    out.push_back(e);
  }
  return out;
}

std::vector<std::pair<int, int>> RelativePosePairs(
    const ba::BaProblem& problem, const std::vector<std::pair<int, int>>& validation, int max_all) {
  std::vector<int> object;
  for (size_t v = 0; v < problem.views.size(); ++v) {
    if (problem.views[v].kind == ba::ViewKind::kObject) object.push_back(static_cast<int>(v));
  }
  if (static_cast<int>(object.size()) > max_all) return validation;
  std::vector<std::pair<int, int>> pairs;
  for (size_t i = 0; i < object.size(); ++i) {
    for (size_t j = i + 1; j < object.size(); ++j) pairs.emplace_back(object[i], object[j]);
  }
  return pairs;
}

RelativePoseError CompareRelativePose(const RelativePoseEstimate& est,
                                      const Pose6& true_a,
                                      const Pose6& true_b) {
  RelativePoseError out;
  Pose6 truth;
  RelativePose(true_a.data(), true_b.data(), truth.data());
  out.error = est.cam_b_from_cam_a - truth;
  auto ldlt = est.covariance.ldlt();
  out.nees = out.error.dot(ldlt.solve(out.error));
  const Eigen::Vector3d er = out.error.head<3>();
  out.rotation_mahalanobis =
      std::sqrt(std::max(0.0, er.dot(est.covariance.topLeftCorner<3, 3>().ldlt().solve(er))));
  const Eigen::Matrix3d Re = RotationOf(est.cam_b_from_cam_a.head<3>());
  const Eigen::Matrix3d Rt = RotationOf(truth.head<3>());
  out.rotation_error_deg = AngleBetweenRotations(Re, Rt) * kRadToDeg;
  const double true_angle = RelativeRotationAngle(true_a.data(), true_b.data()) * kRadToDeg;
  out.angle_error_sigma =
      est.sigma_angle_deg > 0 ? (est.angle_deg - true_angle) / est.sigma_angle_deg : 0.0;
  return out;
}

}  // namespace analysis
}  // namespace carmba
