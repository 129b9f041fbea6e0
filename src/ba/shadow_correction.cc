#include "ba/shadow_correction.h"

#include <cmath>

#include "ba/bundle_adjuster.h"
#include "ba/view_intrinsics.h"
#include "camera/camera_model.h"
#include "geometry/rotation.h"

namespace carmba {
namespace ba {

namespace {

// The lens map D: normalised image point -> pixel (camera_model.h with z = 1).
bool Lens(const double* intrinsics, const Eigen::Vector2d& x, Eigen::Vector2d* uv) {
  const double p[3] = {x.x(), x.y(), 1.0};
  return ProjectCamPoint(intrinsics, p, uv->data());
}

// Central-difference Jacobian of D at x (step h, normalised units).
bool LensJacobian(const double* intrinsics,
                  const Eigen::Vector2d& x,
                  double h,
                  Eigen::Matrix2d* J) {
  for (int k = 0; k < 2; ++k) {
    Eigen::Vector2d a, b;
    if (!Lens(intrinsics, x + h * Eigen::Vector2d::Unit(k), &a) ||
        !Lens(intrinsics, x - h * Eigen::Vector2d::Unit(k), &b)) {
      return false;
    }
    J->col(k) = (a - b) / (2 * h);
  }
  return true;
}

}  // namespace

Eigen::Vector2d SphereShadowOffsetPx(const double* intrinsics, const Eigen::Vector3d& p_cam,
                                     double radius_mm) {
  const double d2 = p_cam.squaredNorm(), r2 = radius_mm * radius_mm;
  if (!(radius_mm > 0) || !(p_cam.z() > 0) || !(d2 > r2)) return Eigen::Vector2d::Zero();
  // The outline in the normalised image plane: an ellipse with centre e, semi-axes a (radial)
  // and b (Dandelin: eccentricity sin(theta) / cos(alpha)).
  const Eigen::Vector2d p = p_cam.head<2>() / p_cam.z();  // |p| = tan(theta)
  const double tan_theta = p.norm(), theta = std::atan(tan_theta);
  const double alpha = std::asin(radius_mm / std::sqrt(d2));
  if (!(theta + alpha < M_PI / 2 - 1e-6)) return Eigen::Vector2d::Zero();  // reaches the horizon
  const double tan2_alpha = std::tan(alpha) * std::tan(alpha), tan2_theta = tan_theta * tan_theta;
  const Eigen::Vector2d e = p * (1 + tan2_alpha * (1 + tan2_theta) / (1 - tan2_theta * tan2_alpha));
  const double a = 0.5 * (std::tan(theta + alpha) - std::tan(theta - alpha));
  const double ecc = std::sin(theta) / std::cos(alpha);
  const double b = a * std::sqrt(std::max(0.0, 1 - ecc * ecc));
  const Eigen::Vector2d u =
      tan_theta > 0 ? Eigen::Vector2d(p / tan_theta) : Eigen::Vector2d::UnitX();
  const Eigen::Vector2d w(-u.y(), u.x());
  // Second moments of the (uniform) ellipse about its centre.
  const Eigen::Matrix2d M = 0.25 * (a * a * u * u.transpose() + b * b * w * w.transpose());
  // The centroid of the shadow in pixels, to second order in the ellipse's size: the area
  // centroid of D(ellipse) with D's area element |det J|:
  //   D(e) + 1/2 sum_k tr(H_k M) e_k + J M grad(ln |det J|).
  Eigen::Vector2d uv_p, uv_e;
  if (!Lens(intrinsics, p, &uv_p) || !Lens(intrinsics, e, &uv_e)) return Eigen::Vector2d::Zero();
  const double h = 1e-3;
  Eigen::Matrix2d J;
  if (!LensJacobian(intrinsics, e, h, &J)) return Eigen::Vector2d::Zero();
  Eigen::Vector2d curvature = Eigen::Vector2d::Zero(), grad_log_det;
  for (int k = 0; k < 2; ++k) {
    const Eigen::Vector2d step = h * Eigen::Vector2d::Unit(k);
    Eigen::Matrix2d Jp, Jm;
    if (!LensJacobian(intrinsics, e + step, h, &Jp) ||
        !LensJacobian(intrinsics, e - step, h, &Jm)) {
      return Eigen::Vector2d::Zero();
    }
    // Column k of the Hessians: d J / d x_k, and d ln|det J| / d x_k.
    const Eigen::Matrix2d dJ = (Jp - Jm) / (2 * h);
    for (int l = 0; l < 2; ++l) curvature += 0.5 * dJ.col(l) * M(l, k);
    grad_log_det[k] =
        (std::log(std::abs(Jp.determinant())) - std::log(std::abs(Jm.determinant()))) / (2 * h);
  }
  return uv_e + curvature + J * M * grad_log_det - uv_p;
}

namespace {

// The rotation and translation of view v's cam_from_source at the solution (a rig view's
// composed with its held cam_from_rig).
void ViewTransform(const BaProblem& problem, const BaResult& result, int v, Eigen::Matrix3d* R,
                   Eigen::Vector3d* t) {
  const double* block = result.block(result.layout->view_block(v));
  *R = RotationOf(block);
  *t = Eigen::Vector3d(block[3], block[4], block[5]);
  const BaView& view = problem.views[v];
  if (view.rig < 0) return;
  const Eigen::Matrix3d Rc = RotationOf(view.cam_from_rig.data());
  *R = Rc * *R;
  *t = Rc * *t + view.cam_from_rig.tail<3>();
}

// The solved position of point `id` of view v (its plate point or marker), or false.
bool PointOf(const BaProblem& problem, const BaResult& result, const BaView& view, int id,
             Eigen::Vector3d* p) {
  if (view.kind == ViewKind::kPlate) {
    if (id < 0 || id >= static_cast<int>(problem.plate.points.size())) return false;
    *p = Eigen::Map<const Eigen::Vector3d>(result.block(result.layout->plate_point_block(id)));
    return true;
  }
  for (size_t m = 0; m < problem.markers.size(); ++m) {
    if (problem.markers[m].id != id) continue;
    *p = Eigen::Map<const Eigen::Vector3d>(
        result.block(result.layout->marker_block(static_cast<int>(m))));
    return true;
  }
  return false;
}

}  // namespace

std::vector<std::vector<Eigen::Vector2d>> ShadowOffsets(const BaProblem& problem,
                                                        const BaResult& result) {
  std::vector<std::vector<Eigen::Vector2d>> out(problem.views.size());
  for (size_t v = 0; v < problem.views.size(); ++v) {
    const BaView& view = problem.views[v];
    out[v].assign(view.point_ids.size(), Eigen::Vector2d::Zero());
    const double radius =
        view.kind == ViewKind::kPlate ? problem.plate.sphere_radius_mm : problem.marker_radius_mm;
    if (!(radius > 0)) continue;
    const auto intrinsics = IntrinsicsValueOfView(problem, result, static_cast<int>(v));
    Eigen::Matrix3d R;
    Eigen::Vector3d t;
    ViewTransform(problem, result, static_cast<int>(v), &R, &t);
    for (size_t i = 0; i < view.point_ids.size(); ++i) {
      Eigen::Vector3d p;
      if (!PointOf(problem, result, view, view.point_ids[i], &p)) continue;
      out[v][i] = SphereShadowOffsetPx(intrinsics.data(), R * p + t, radius);
    }
  }
  return out;
}

ShadowCorrectionSummary SummariseShadowOffsets(
    const BaProblem& problem,
    const std::vector<std::vector<Eigen::Vector2d>>& offsets,
    double sigma_scale) {
  ShadowCorrectionSummary s;
  s.evaluated = problem.marker_radius_mm > 0 || problem.plate.sphere_radius_mm > 0;
  if (!s.evaluated) return s;
  double sum2 = 0;
  for (size_t v = 0; v < offsets.size(); ++v) {
    for (size_t i = 0; i < offsets[v].size(); ++i) {
      const double n = offsets[v][i].norm();
      if (n == 0) continue;
      ++s.num_observations;
      sum2 += n * n;
      s.max_px = std::max(s.max_px, n);
      s.max_sigma = std::max(s.max_sigma, n / (sigma_scale * problem.views[v].SigmaPx(i)));
    }
  }
  if (s.num_observations > 0) s.rms_px = std::sqrt(sum2 / (2.0 * s.num_observations));
  s.applied = s.max_sigma > kShadowCorrectionMinSigma;
  return s;
}

BaProblem WithShadowOffsetsRemoved(const BaProblem& problem,
                                   const std::vector<std::vector<Eigen::Vector2d>>& offsets) {
  BaProblem out = problem;
  for (size_t v = 0; v < out.views.size(); ++v) {
    for (size_t i = 0; i < out.views[v].uv_px.size(); ++i) out.views[v].uv_px[i] -= offsets[v][i];
  }
  return out;
}

}  // namespace ba
}  // namespace carmba
