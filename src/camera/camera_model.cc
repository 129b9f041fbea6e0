#include "camera/camera_model.h"

#include <cmath>

#include "geometry/rotation.h"

namespace carmba {

bool ProjectCamPointWithJac(const double* in,
                            const double* p,
                            double* uv,
                            double* J_uv_intrinsics,
                            double* J_uv_p_in_cam) {
  if (!(p[2] > 0) || !std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
    return false;
  }
  const double iz = 1.0 / p[2];
  const double x = p[0] * iz, y = p[1] * iz;
  const double x2 = x * x, y2 = y * y, xy = x * y;
  const double r2 = x2 + y2, r4 = r2 * r2, r6 = r4 * r2;
  const double fx = in[kFx], fy = in[kFy];
  const double k1 = in[kK1], k2 = in[kK2], p1 = in[kP1], p2 = in[kP2], k3 = in[kK3];
  const double a = 1.0 + k1 * r2 + k2 * r4 + k3 * r6;
  const double xd = x * a + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x2);
  const double yd = y * a + p1 * (r2 + 2.0 * y2) + 2.0 * p2 * xy;
  uv[0] = fx * xd + in[kCx];
  uv[1] = fy * yd + in[kCy];

  if (J_uv_intrinsics) {
    // du/d[fx fy cx cy] = [xd 0 1 0];  du/dk = fx dxd/dk with dxd/dk1 = x r2, dxd/dk2 = x r4,
    // dxd/dp1 = 2xy, dxd/dp2 = r2 + 2x^2, dxd/dk3 = x r6; likewise for v.
    double* Ju = J_uv_intrinsics;
    double* Jv = J_uv_intrinsics + kNumIntrinsics;
    Ju[kFx] = xd, Ju[kFy] = 0, Ju[kCx] = 1, Ju[kCy] = 0;
    Ju[kK1] = fx * x * r2, Ju[kK2] = fx * x * r4, Ju[kP1] = fx * 2.0 * xy;
    Ju[kP2] = fx * (r2 + 2.0 * x2), Ju[kK3] = fx * x * r6;
    Jv[kFx] = 0, Jv[kFy] = yd, Jv[kCx] = 0, Jv[kCy] = 1;
    Jv[kK1] = fy * y * r2, Jv[kK2] = fy * y * r4, Jv[kP1] = fy * (r2 + 2.0 * y2);
    Jv[kP2] = fy * 2.0 * xy, Jv[kK3] = fy * y * r6;
  }
  if (J_uv_p_in_cam) {
    // da/dx = 2x (k1 + 2 k2 r2 + 3 k3 r4) = 2x b, da/dy = 2y b
    // dxd/dx = a + x da/dx + 2 p1 y + 6 p2 x     dxd/dy = x da/dy + 2 p1 x + 2 p2 y
    // dyd/dx = y da/dx + 2 p1 x + 2 p2 y         dyd/dy = a + y da/dy + 6 p1 y + 2 p2 x
    // dx/dp = [1/Z, 0, -X/Z^2] = iz [1, 0, -x];  dy/dp = iz [0, 1, -y]
    const double b = k1 + 2.0 * k2 * r2 + 3.0 * k3 * r4;
    const double dxd_dx = a + 2.0 * x2 * b + 2.0 * p1 * y + 6.0 * p2 * x;
    const double dxd_dy = 2.0 * xy * b + 2.0 * p1 * x + 2.0 * p2 * y;
    const double dyd_dx = 2.0 * xy * b + 2.0 * p1 * x + 2.0 * p2 * y;
    const double dyd_dy = a + 2.0 * y2 * b + 6.0 * p1 * y + 2.0 * p2 * x;
    const double du_dx = fx * dxd_dx, du_dy = fx * dxd_dy;
    const double dv_dx = fy * dyd_dx, dv_dy = fy * dyd_dy;
    double* J = J_uv_p_in_cam;
    J[0] = du_dx * iz, J[1] = du_dy * iz, J[2] = -(du_dx * x + du_dy * y) * iz;
    J[3] = dv_dx * iz, J[4] = dv_dy * iz, J[5] = -(dv_dx * x + dv_dy * y) * iz;
  }
  return true;
}

bool ProjectPointWithJac(const double* intrinsics,
                         const double* pose,
                         const double* p_in_object,
                         double* uv,
                         double* J_uv_intrinsics,
                         double* J_uv_pose,
                         double* J_uv_p_in_object) {
  double p_in_cam[3];
  double J_Rp_r[9];
  const bool need_r = J_uv_pose != nullptr;
  RotatePointWithJac(pose, p_in_object, p_in_cam, need_r ? J_Rp_r : nullptr);
  p_in_cam[0] += pose[3];
  p_in_cam[1] += pose[4];
  p_in_cam[2] += pose[5];
  double J_uv_pc[6];
  const bool need_p = J_uv_pose || J_uv_p_in_object;
  if (!ProjectCamPointWithJac(intrinsics, p_in_cam, uv, J_uv_intrinsics,
                              need_p ? J_uv_pc : nullptr)) {
    return false;
  }
  if (J_uv_pose) {
    // d uv/d r = J_uv_pc * J_Rp_r;  d uv/d t = J_uv_pc
    for (int i = 0; i < 2; ++i) {
      for (int j = 0; j < 3; ++j) {
        J_uv_pose[6 * i + j] = J_uv_pc[3 * i] * J_Rp_r[j] + J_uv_pc[3 * i + 1] * J_Rp_r[3 + j] +
                               J_uv_pc[3 * i + 2] * J_Rp_r[6 + j];
        J_uv_pose[6 * i + 3 + j] = J_uv_pc[3 * i + j];
      }
    }
  }
  if (J_uv_p_in_object) {
    // d uv/d p_in_object = J_uv_pc * R
    double R[9];
    ceres::AngleAxisToRotationMatrix(pose, ceres::RowMajorAdapter3x3(R));
    for (int i = 0; i < 2; ++i) {
      for (int j = 0; j < 3; ++j) {
        J_uv_p_in_object[3 * i + j] = J_uv_pc[3 * i] * R[j] + J_uv_pc[3 * i + 1] * R[3 + j] +
                                      J_uv_pc[3 * i + 2] * R[6 + j];
      }
    }
  }
  return true;
}

bool UnprojectToNormalizedFrom(const double* in,
                               const double* uv,
                               const double* seed_xy,
                               int max_iterations,
                               double* xy) {
  // Refine (x, y) by Gauss-Newton on the distortion equations, using the analytic 2x2 Jacobian of
  // the projection of (x, y, 1).
  double x = seed_xy[0], y = seed_xy[1];
  for (int it = 0; it < max_iterations; ++it) {
    const double p[3] = {x, y, 1.0};
    double q[2], J[6];
    if (!ProjectCamPointWithJac(in, p, q, nullptr, J)) return false;
    const double ex = uv[0] - q[0], ey = uv[1] - q[1];
    if (ex * ex + ey * ey < 1e-20) {  // |e| < 1e-10 px (std::hypot is several times slower)
      xy[0] = x, xy[1] = y;
      return true;
    }
    // J columns 0,1 are d(u,v)/d(x,y) for Z = 1.
    const double a = J[0], b = J[1], c = J[3], d = J[4];
    const double det = a * d - b * c;
    if (!(std::fabs(det) > 1e-12)) return false;
    x += (d * ex - b * ey) / det;
    y += (-c * ex + a * ey) / det;
    if (!std::isfinite(x) || !std::isfinite(y)) return false;
  }
  const double p[3] = {x, y, 1.0};
  double q[2];
  if (!ProjectCamPoint(in, p, q) || std::hypot(uv[0] - q[0], uv[1] - q[1]) > 1e-9) return false;
  xy[0] = x, xy[1] = y;
  return true;
}

bool UnprojectToNormalized(const double* in, const double* uv, double* xy) {
  // From the undistorted pinhole inverse.
  const double seed[2] = {(uv[0] - in[kCx]) / in[kFx], (uv[1] - in[kCy]) / in[kFy]};
  return UnprojectToNormalizedFrom(in, uv, seed, 50, xy);
}

}  // namespace carmba
