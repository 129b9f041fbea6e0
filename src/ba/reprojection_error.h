// Residuals of carmba's bundle adjustments.
//
// ReprojectionError: one observed pixel of one point in one view.
//   parameter blocks: pose   cam_from_object [rx, ry, rz (rad), tx, ty, tz (mm)]   (6)
//                     point  p_in_object [x, y, z] (mm)                              (3)
//                     intrinsics [fx, fy, cx, cy, k1, k2, p1, p2, k3]                 (9)
//   residual (2): L^-1 (project(intrinsics, pose, point) - uv_observed),  Sigma = L L^T
// with Sigma the observation's 2x2 pixel covariance (px^2; a detected blob's, detect/
// marker_blobs.h) and L its lower Cholesky factor; isotropic sigma_px is the special case
// L = sigma_px I. Then |r|^2 = e^T Sigma^-1 e. Whitening makes ceres::Covariance come out in
// physical units (ceres/covariance.h leaves that to the user). Evaluate() returns false for
// non-finite input or a point behind the source, so Ceres rejects the step instead of using a
// meaningless residual.
//
// The Jacobians are the analytic ones of camera/camera_model.h (ProjectPointWithJac),
// premultiplied by L^-1 (dr/dx = L^-1 dq/dx: the whitening is constant). ReprojectionErrorAutoDiff
// is the autodiff twin, used by the `autodiff` configuration and by the tests to check the analytic
// derivatives.
//
// CT prior: a 3-D point tied to a measured position (a CT fiducial) with covariance C:
//   residual (3): S (p - p_measured),  with S^T S = C^-1  (S = L^T, the square-root information)
//   so that |r|^2 = (p - p_measured)^T C^-1 (p - p_measured).  Jacobian: S (constant).
// It is handed to Ceres as two PointPriorRows blocks of 2 rows each (see below).
#pragma once

#include <ceres/autodiff_cost_function.h>
#include <ceres/rotation.h>
#include <ceres/sized_cost_function.h>

#include <Eigen/Core>
#include <utility>
#include <vector>

#include "camera/camera_model.h"

namespace carmba {

// The whitening L^-1 of a 2x2 pixel covariance Sigma = L L^T: lower triangular
// [[a, 0], [b, c]] (a = 1/l00, b = -l10/(l00 l11), c = 1/l11). Isotropic: a = c = 1/sigma, b = 0.
struct PixelWhitening {
  double a = 1, b = 0, c = 1;
  static PixelWhitening Isotropic(double sigma_px) { return {1.0 / sigma_px, 0.0, 1.0 / sigma_px}; }
  // False if Sigma is not symmetric positive definite.
  static bool FromCovariance(const Eigen::Matrix2d& covariance_px2, PixelWhitening* w);
  // L e (px) of a whitened residual r: the pixel residual back.
  Eigen::Vector2d Unwhiten(const Eigen::Vector2d& r) const {
    const double x = r[0] / a;
    return {x, (r[1] - b * x) / c};
  }
};

class ReprojectionError final : public ceres::SizedCostFunction<2, 6, 3, 9> {
 public:
  ReprojectionError(double u_px, double v_px, double sigma_px)
      : u_(u_px), v_(v_px), w_(PixelWhitening::Isotropic(sigma_px)) {}
  ReprojectionError(double u_px, double v_px, const PixelWhitening& w)
      : u_(u_px), v_(v_px), w_(w) {}

  bool Evaluate(double const* const* parameters,
                double* residuals,
                double** jacobians) const override;

  static ceres::CostFunction* Create(double u_px, double v_px, double sigma_px) {
    return new ReprojectionError(u_px, v_px, sigma_px);
  }
  static ceres::CostFunction* Create(double u_px, double v_px, const PixelWhitening& w) {
    return new ReprojectionError(u_px, v_px, w);
  }

 private:
  double u_, v_;
  PixelWhitening w_;
};

struct ReprojectionErrorAutoDiff {
  ReprojectionErrorAutoDiff(double u_px, double v_px, const PixelWhitening& whitening)
      : u(u_px), v(v_px), w(whitening) {}

  template <typename T>
  bool operator()(const T* pose, const T* point, const T* intrinsics, T* residuals) const {
    T uv[2];
    if (!ProjectPoint(intrinsics, pose, point, uv)) return false;
    const T e0 = uv[0] - T(u), e1 = uv[1] - T(v);
    residuals[0] = T(w.a) * e0;
    residuals[1] = T(w.b) * e0 + T(w.c) * e1;
    return true;
  }

  static ceres::CostFunction* Create(double u_px, double v_px, double sigma_px) {
    return Create(u_px, v_px, PixelWhitening::Isotropic(sigma_px));
  }
  static ceres::CostFunction* Create(double u_px, double v_px, const PixelWhitening& w) {
    return new ceres::AutoDiffCostFunction<ReprojectionErrorAutoDiff, 2, 6, 3, 9>(
        new ReprojectionErrorAutoDiff(u_px, v_px, w));
  }

  double u, v;
  PixelWhitening w;
};

// RigReprojectionError: ReprojectionError for a view of a rig (ba/problem.h): the pose block is
// the rig's rig_from_object, and the view's held cam_from_rig = (Rc, tc) is a constant:
//   p_in_cam = Rc (R(r) p + t) + tc.
// Analytic Jacobians by the chain rule through ProjectCamPointWithJac and RotatePointWithJac
// (camera/camera_model.h); RigReprojectionErrorAutoDiff is its autodiff twin.
class RigReprojectionError final : public ceres::SizedCostFunction<2, 6, 3, 9> {
 public:
  RigReprojectionError(double u_px,
                       double v_px,
                       const PixelWhitening& w,
                       const double* cam_from_rig);

  bool Evaluate(double const* const* parameters,
                double* residuals,
                double** jacobians) const override;

 private:
  double u_, v_;
  PixelWhitening w_;
  Eigen::Matrix3d Rc_;
  Eigen::Vector3d tc_;
};

struct RigReprojectionErrorAutoDiff {
  RigReprojectionErrorAutoDiff(double u_px, double v_px, const PixelWhitening& whitening,
                               const double* cam_from_rig)
      : u(u_px), v(v_px), w(whitening) {
    for (int i = 0; i < 6; ++i) cam_from_rig_[i] = cam_from_rig[i];
  }

  template <typename T>
  bool operator()(const T* rig_pose, const T* point, const T* intrinsics, T* residuals) const {
    T p_rig[3], p_cam[3];
    ceres::AngleAxisRotatePoint(rig_pose, point, p_rig);
    for (int k = 0; k < 3; ++k) p_rig[k] += rig_pose[3 + k];
    const T rc[3] = {T(cam_from_rig_[0]), T(cam_from_rig_[1]), T(cam_from_rig_[2])};
    ceres::AngleAxisRotatePoint(rc, p_rig, p_cam);
    for (int k = 0; k < 3; ++k) p_cam[k] += T(cam_from_rig_[3 + k]);
    T uv[2];
    if (!ProjectCamPoint(intrinsics, p_cam, uv)) return false;
    const T e0 = uv[0] - T(u), e1 = uv[1] - T(v);
    residuals[0] = T(w.a) * e0;
    residuals[1] = T(w.b) * e0 + T(w.c) * e1;
    return true;
  }

  static ceres::CostFunction* Create(double u_px, double v_px, const PixelWhitening& w,
                                     const double* cam_from_rig) {
    return new ceres::AutoDiffCostFunction<RigReprojectionErrorAutoDiff, 2, 6, 3, 9>(
        new RigReprojectionErrorAutoDiff(u_px, v_px, w, cam_from_rig));
  }

  double u, v;
  PixelWhitening w;
  double cam_from_rig_[6];
};

// PlateViewReprojection: all observed points of one plate view with the plate held (its points
// are constants), in one residual block: 2n residuals (ReprojectionError's, point by point),
// parameter blocks pose (6) and intrinsics (9). Without a robust loss this is the same problem as
// n ReprojectionError blocks, and one block per view is several times cheaper to build, evaluate
// and linearise (the engine uses it for held plates without a robust loss; a loss must act per
// point, so then each point is its own block).
class PlateViewReprojection final : public ceres::CostFunction {
 public:
  PlateViewReprojection(std::vector<Eigen::Vector3d> p_in_plate,
                        std::vector<Eigen::Vector2d> uv_px,
                        double sigma_px);

  bool Evaluate(double const* const* parameters,
                double* residuals,
                double** jacobians) const override;

 private:
  std::vector<Eigen::Vector3d> p_;
  std::vector<Eigen::Vector2d> uv_;
  double inv_sigma_;
};

// PointPriorRows: two rows of the CT prior, r = A (p - p_measured) with A 2x3 (a row of A may be
// zero). The pose problem hands each 3-row prior to Ceres as two of these, rows (0, 1) and
// (2, zero), so that every residual block on a marker has 2 rows and Ceres picks its fixed-size
// SchurEliminator<2, 3, 6> instead of the dynamic <-1, -1, -1> one. The cost, gradient and normal
// equations are those of the 3-row prior: the zero row adds nothing.
class PointPriorRows final : public ceres::SizedCostFunction<2, 3> {
 public:
  PointPriorRows(const Eigen::Vector3d& p_measured, const Eigen::Matrix<double, 2, 3>& A)
      : p_measured_(p_measured), A_(A) {}

  bool Evaluate(double const* const* parameters,
                double* residuals,
                double** jacobians) const override;

  // The two blocks that together are the prior with square-root information S (S^T S = C^-1).
  static std::pair<PointPriorRows*, PointPriorRows*> Split(const Eigen::Vector3d& p_measured,
                                                          const Eigen::Matrix3d& sqrt_information);

 private:
  Eigen::Vector3d p_measured_;
  Eigen::Matrix<double, 2, 3> A_;
};

// Returns the upper-triangular square-root information S with S^T S = covariance^-1, or false if
// the covariance is not symmetric positive definite.
bool SqrtInformation(const Eigen::Matrix3d& covariance, Eigen::Matrix3d* S);

}  // namespace carmba
