#include "calib/zhang_init.h"

#include <ceres/rotation.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <string>

#include "geometry/rotation.h"

namespace carmba {

namespace {

// Normalised DLT homography: plate (x, y) mm -> pixel.
bool FitHomography(const std::vector<Eigen::Vector2d>& src,
                   const std::vector<Eigen::Vector2d>& dst,
                   Eigen::Matrix3d* H) {
  const int n = static_cast<int>(src.size());
  auto normaliser = [n](const std::vector<Eigen::Vector2d>& p) {
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (const auto& q : p) mean += q;
    mean /= n;
    double d = 0;
    for (const auto& q : p) d += (q - mean).norm();
    d /= n;
    const double s = d > 0 ? std::sqrt(2.0) / d : 1.0;
    Eigen::Matrix3d T;
    T << s, 0, -s * mean.x(), 0, s, -s * mean.y(), 0, 0, 1;
    return T;
  };
  const Eigen::Matrix3d Ts = normaliser(src), Td = normaliser(dst);
  Eigen::Matrix<double, 9, 9> AtA = Eigen::Matrix<double, 9, 9>::Zero();
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d s = Ts * src[i].homogeneous();
    const Eigen::Vector3d d = Td * dst[i].homogeneous();
    Eigen::Matrix<double, 9, 1> r1, r2;
    r1 << s.x(), s.y(), 1, 0, 0, 0, -d.x() * s.x(), -d.x() * s.y(), -d.x();
    r2 << 0, 0, 0, s.x(), s.y(), 1, -d.y() * s.x(), -d.y() * s.y(), -d.y();
    AtA.noalias() += r1 * r1.transpose() + r2 * r2.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> es(AtA);
  if (es.info() != Eigen::Success) return false;
  const Eigen::Matrix<double, 9, 1> h = es.eigenvectors().col(0);
  Eigen::Matrix3d Hn;
  Hn << h(0), h(1), h(2), h(3), h(4), h(5), h(6), h(7), h(8);
  *H = Td.inverse() * Hn * Ts;
  if (!H->allFinite() || std::abs((*H)(2, 2)) < 1e-300) return false;
  *H /= (*H)(2, 2);
  return true;
}

// Pose from a homography and K: K^-1 H = lambda [r1 r2 t].
void PoseFromHomography(const Eigen::Matrix3d& H, const double* intr, Pose6* pose) {
  Eigen::Matrix3d K;
  K << intr[kFx], 0, intr[kCx], 0, intr[kFy], intr[kCy], 0, 0, 1;
  const Eigen::Matrix3d M = K.inverse() * H;
  double lambda = 2.0 / (M.col(0).norm() + M.col(1).norm());
  if (M(2, 2) * lambda < 0) lambda = -lambda;
  Eigen::Matrix3d R;
  R.col(0) = lambda * M.col(0);
  R.col(1) = lambda * M.col(1);
  R.col(2) = R.col(0).cross(R.col(1));
  const Eigen::Matrix3d Ro = NearestRotation(R);
  const Eigen::Vector3d t = lambda * M.col(2);
  double Rc[9];
  Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::ColMajor>> Rc_map(Rc);
  Rc_map = Ro;
  ceres::RotationMatrixToAngleAxis(Rc, pose->data());
  (*pose)[3] = t.x(), (*pose)[4] = t.y(), (*pose)[5] = t.z();
}

StatusOr<std::vector<Eigen::Matrix3d>> ViewHomographies(const ObservationSet& obs) {
  std::vector<Eigen::Matrix3d> H(obs.views.size());
  for (size_t v = 0; v < obs.views.size(); ++v) {
    std::vector<Eigen::Vector2d> src;
    for (int id : obs.views[v].point_ids) {
      const Eigen::Vector3d p = obs.grid.PointInPlate(id);
      src.emplace_back(p.x(), p.y());
    }
    if (!FitHomography(src, obs.views[v].uv_px, &H[v])) {
      return Status::Error("view " + std::to_string(v) + " (" + obs.views[v].image +
                           "): no homography (collinear points?)");
    }
  }
  return H;
}

// (b11, b22, b33) of B from the homographies normalised by N (pixels in units of s around the
// principal point); with a held aspect ratio r, b22 = b11 / r^2.
Eigen::Vector3d SolveForB(const std::vector<Eigen::Matrix3d>& H,
                          const Eigen::Matrix3d& N,
                          double ratio) {
  const int num_views = static_cast<int>(H.size());
  Eigen::MatrixXd V(2 * num_views, 3);
  for (int v = 0; v < num_views; ++v) {
    Eigen::Matrix3d Hn = N * H[v];
    Hn /= Hn.col(0).norm() + Hn.col(1).norm();
    const Eigen::Vector3d h1 = Hn.col(0), h2 = Hn.col(1);
    V.row(2 * v) << h1(0) * h2(0), h1(1) * h2(1), h1(2) * h2(2);
    V.row(2 * v + 1) << h1(0) * h1(0) - h2(0) * h2(0), h1(1) * h1(1) - h2(1) * h2(1),
        h1(2) * h1(2) - h2(2) * h2(2);
  }
  if (ratio > 0) {
    // b2 = b1 / r^2: unknowns (b1, b3).
    Eigen::MatrixXd V2(V.rows(), 2);
    V2.col(0) = V.col(0) + V.col(1) / (ratio * ratio);
    V2.col(1) = V.col(2);
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(V2, Eigen::ComputeFullV);
    const Eigen::Vector2d b = svd.matrixV().col(1);
    return Eigen::Vector3d(b(0), b(0) / (ratio * ratio), b(1));
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(V, Eigen::ComputeFullV);
  return svd.matrixV().col(2);
}

// Zhang with known principal point (cx, cy) and zero skew, in units of s = max(w, h) px.
Status ZhangIntrinsics(const ObservationSet& obs,
                       const std::vector<Eigen::Matrix3d>& H,
                       const CalibrationOptions& opt,
                       double cx,
                       double cy,
                       std::array<double, kNumIntrinsics>* x0) {
  const double s = std::max(obs.width, obs.height);
  Eigen::Matrix3d N;
  N << 1 / s, 0, -cx / s, 0, 1 / s, -cy / s, 0, 0, 1;
  const Eigen::Vector3d b =
      SolveForB(H, N, opt.fix_aspect_ratio ? opt.aspect_ratio_fy_over_fx : 0.0);
  const double b1 = b(0), b2 = b(1), b3 = b(2);
  if (!(b1 / b3 > 0) || !(b2 / b3 > 0) || !std::isfinite(b1 / b3) || !std::isfinite(b2 / b3)) {
    return Status::Error("closed-form initialisation failed: the views do not determine the "
                         "focal length (degenerate views, e.g. all fronto-parallel; tilt the "
                         "plate in several views)");
  }
  (*x0)[kFx] = s * std::sqrt(b3 / b1);
  (*x0)[kFy] = s * std::sqrt(b3 / b2);
  (*x0)[kCx] = cx, (*x0)[kCy] = cy;
  if (!((*x0)[kFx] < 1e4 * s) || !((*x0)[kFy] < 1e4 * s)) {
    return Status::Error("closed-form initialisation failed: focal length " +
                         std::to_string((*x0)[kFx]) +
                         " px is not determined (degenerate views, e.g. all fronto-parallel)");
  }
  return Status::Ok();
}

}  // namespace

StatusOr<CalibrationStart> InitialiseCalibration(const ObservationSet& obs,
                                                 const CalibrationOptions& opt) {
  double cx = (obs.width - 1) * 0.5, cy = (obs.height - 1) * 0.5;
  if (!opt.principal_point_px.empty()) {
    cx = opt.principal_point_px[0];
    cy = opt.principal_point_px[1];
  }
  auto H = ViewHomographies(obs);
  if (!H.ok()) return H.status();
  CalibrationStart start;
  std::array<double, kNumIntrinsics>& x0 = start.intrinsics;
  if (!opt.initial_intrinsics.empty()) {
    std::copy(opt.initial_intrinsics.begin(), opt.initial_intrinsics.end(), x0.begin());
  } else {
    CARMBA_RETURN_IF_ERROR(ZhangIntrinsics(obs, *H, opt, cx, cy, &x0));
  }
  if (opt.fix_principal_point) x0[kCx] = cx, x0[kCy] = cy;
  if (opt.zero_tangential) x0[kP1] = x0[kP2] = 0;
  if (opt.fix_k3) x0[kK3] = 0;
  if (opt.fix_aspect_ratio) {
    double ratio = opt.aspect_ratio_fy_over_fx;
    if (ratio == 0) ratio = x0[kFy] / x0[kFx];
    const double f = std::sqrt(x0[kFx] * x0[kFy] / ratio);
    x0[kFx] = f, x0[kFy] = ratio * f;
    start.fy_over_fx = ratio;
  }
  start.cam_from_plate.resize(obs.views.size());
  for (size_t v = 0; v < obs.views.size(); ++v) {
    PoseFromHomography((*H)[v], x0.data(), &start.cam_from_plate[v]);
  }
  return start;
}

}  // namespace carmba
