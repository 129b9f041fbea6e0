// The relative C-arm pose between two object views of a solved bundle adjustment, with its 6x6
// covariance (issue 11).
//
// With poses cam_a_from_object = (R_a, t_a) and cam_b_from_object = (R_b, t_b) (geometry/pose.h),
//   cam_b_from_cam_a = cam_b_from_object * inverse(cam_a_from_object):
//     R = R_b R_a^T,   t = t_b - R t_a,
// as a Pose6 [rvec of R (rad), t (mm)]. t is the source of view a seen from view b's camera, so
// |t| is the distance between the two source positions (the C-arm's "baseline").
//
// Covariance: first order through the 6x12 Jacobian of (rvec, t) with respect to both poses
// (ceres::Jet, exact), applied to the engine's joint 12x12 covariance of the two pose blocks
// (ba/covariance.h: marginal over everything else, so the intrinsics' and the markers' shares and
// the two poses' cross-covariance are in it):  C_rel = J C_ab J^T. With a considered
// calibration (a pose problem's held intrinsics with camera.json's covariance) C_ab includes its
// consider term, and its part J C_ab,cal J^T is also given on its own.
// The rotation part is also given as small rotations about view b's camera axes (deg; the rvec
// covariance mapped by the SO(3) left Jacobian, as the pose reports do).
#pragma once

#include <ceres/jet.h>
#include <ceres/rotation.h>

#include <Eigen/Dense>
#include <string>
#include <utility>
#include <vector>

#include "ba/bundle_adjuster.h"
#include "geometry/pose.h"

namespace carmba {
namespace analysis {

// rel = cam_b_from_cam_a of pose_a = cam_a_from_object and pose_b = cam_b_from_object (6 each).
template <typename T>
void RelativePose(const T* pose_a, const T* pose_b, T* rel) {
  T Ra[9], Rb[9], R[9];
  ceres::AngleAxisToRotationMatrix(pose_a, ceres::RowMajorAdapter3x3(Ra));
  ceres::AngleAxisToRotationMatrix(pose_b, ceres::RowMajorAdapter3x3(Rb));
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {  // R = Rb Ra^T
      R[3 * i + j] = Rb[3 * i] * Ra[3 * j] + Rb[3 * i + 1] * Ra[3 * j + 1] +
                     Rb[3 * i + 2] * Ra[3 * j + 2];
    }
  }
  ceres::RotationMatrixToAngleAxis(ceres::RowMajorAdapter3x3(static_cast<const T*>(R)), rel);
  for (int i = 0; i < 3; ++i) {
    rel[3 + i] = pose_b[3 + i] - (R[3 * i] * pose_a[3] + R[3 * i + 1] * pose_a[4] +
                                  R[3 * i + 2] * pose_a[5]);
  }
}

// The relative pose and its 6x12 Jacobian (columns: pose_a's six, then pose_b's), row-major.
Pose6 RelativePoseWithJacobian(const Pose6& pose_a,
                               const Pose6& pose_b,
                               Eigen::Matrix<double, 6, 12>* J);

struct RelativePoseEstimate {
  int view_a = 0, view_b = 0;         // problem view indices
  Pose6 cam_b_from_cam_a = Pose6::Zero();
  Matrix6 covariance = Matrix6::Zero();   // of [rvec (rad), t (mm)]
  double angle_deg = 0, sigma_angle_deg = 0;  // rotation angle |rvec| and its sigma
  Eigen::Vector3d sigma_rotation_deg = Eigen::Vector3d::Zero();  // about view b's camera axes
  Eigen::Vector3d sigma_translation_mm = Eigen::Vector3d::Zero();
  double baseline_mm = 0;             // |t|: distance between the two sources
  // The considered calibration's part of `covariance` (zero without one) and of the angle's
  // variance (its sigma, deg).
  Matrix6 covariance_calibration = Matrix6::Zero();
  double sigma_angle_calibration_deg = 0;
};

// The relative pose of object views `view_a`, `view_b` (problem indices) of a solved result with
// a covariance (scaled by its covariance_scale).
RelativePoseEstimate EstimateRelativePose(const ba::BaResult& result, int view_a, int view_b);
// The same from the two poses and their joint 12x12 covariance (a's block first), e.g. blocks of
// a joint covariance of all poses computed once.
RelativePoseEstimate EstimateRelativePose(const Pose6& pose_a,
                                          const Pose6& pose_b,
                                          const Eigen::Matrix<double, 12, 12>& covariance_ab);
// The same with the calibration's part of covariance_ab (included in it) given on its own.
RelativePoseEstimate EstimateRelativePose(const Pose6& pose_a,
                                          const Pose6& pose_b,
                                          const Eigen::Matrix<double, 12, 12>& covariance_ab,
                                          const Eigen::Matrix<double, 12, 12>& calibration_ab);

// The relative poses of `pairs` (problem view indices), with the covariance of all the views
// involved computed once.
std::vector<RelativePoseEstimate> EstimateRelativePoses(
    const ba::BaResult& result, const std::vector<std::pair<int, int>>& pairs);

// The pairs a report shows: every pair of object views when there are at most `max_all` of them,
// else `validation` (view index pairs) alone.
std::vector<std::pair<int, int>> RelativePosePairs(
    const ba::BaProblem& problem,
    const std::vector<std::pair<int, int>>& validation,
    int max_all = 10);

// Errors of an estimate against true poses cam_a_from_object, cam_b_from_object:
//   e = estimate - truth (rvec difference, mm), NEES = e^T C^-1 e (6 dof), the rotation error
//   as a small rotation (deg, log(R_est R_true^T)) and the rotation part's Mahalanobis distance
//   sqrt(e_r^T C_rr^-1 e_r) (3 dof: "within 3 sigma" means below 3).
struct RelativePoseError {
  Pose6 error = Pose6::Zero();
  double nees = 0;
  double rotation_error_deg = 0;
  double rotation_mahalanobis = 0;
  double angle_error_sigma = 0;  // (angle - true angle) / sigma_angle
};
RelativePoseError CompareRelativePose(const RelativePoseEstimate& estimate,
                                      const Pose6& true_cam_a_from_object,
                                      const Pose6& true_cam_b_from_object);

}  // namespace analysis
}  // namespace carmba
