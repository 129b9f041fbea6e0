#include "pose/posit.h"

#include <Eigen/Dense>
#include <cmath>

#include "geometry/rotation.h"

namespace carmba {

bool PositOptions::Check(std::string* error) const {
  if (max_iterations < 1) return *error = "max_iterations must be >= 1", false;
  if (!(epsilon > 0)) return *error = "epsilon must be positive", false;
  if (!(coplanarity_threshold >= 0 && coplanarity_threshold < 1)) {
    return *error = "coplanarity_threshold must be in [0, 1)", false;
  }
  return true;
}

namespace {

// The POSIT iteration in scalar type S (float for the legacy mode, double otherwise).
template <typename S>
PositResult PositIterate(const std::vector<Eigen::Vector3d>& obj,
                         const std::vector<Eigen::Vector2d>& img,
                         double focal_length,
                         const PositOptions& o) {
  using Mat3 = Eigen::Matrix<S, 3, 3>;
  using MatX3 = Eigen::Matrix<S, Eigen::Dynamic, 3>;
  const int n = static_cast<int>(obj.size()) - 1;
  MatX3 A(n, 3);  // object vectors M0Mi
  for (int i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) A(i, c) = static_cast<S>(obj[i + 1][c] - obj[0][c]);
  }
  // Pseudo-inverse B = (A^T A)^-1 A^T (3 x n), as cvPOSIT's icvPseudoInverse3D (method 0).
  const Mat3 AtA = A.transpose() * A;
  const Eigen::Matrix<S, 3, Eigen::Dynamic> B = AtA.inverse() * A.transpose();

  const S f = static_cast<S>(focal_length);
  const S x0 = static_cast<S>(img[0].x()), y0 = static_cast<S>(img[0].y());
  Eigen::Matrix<S, Eigen::Dynamic, 1> xv(n), yv(n);
  for (int i = 0; i < n; ++i) {
    xv[i] = static_cast<S>(img[i + 1].x()) - x0;
    yv[i] = static_cast<S>(img[i + 1].y()) - y0;
  }
  Mat3 R = Mat3::Zero();
  S scale = 0, inv_z = 0;
  PositResult res;
  for (int it = 0; it < o.max_iterations; ++it) {
    S diff = 0;
    if (it > 0) {
      // New scaled-orthographic image: x_i' = x_i (1 + eps_i) with eps_i = (M0Mi . k) / Z0.
      for (int i = 0; i < n; ++i) {
        const S eps = (A(i, 0) * R(2, 0) + A(i, 1) * R(2, 1) + A(i, 2) * R(2, 2)) * inv_z + S(1);
        const S nx = static_cast<S>(img[i + 1].x()) * eps - x0;
        const S ny = static_cast<S>(img[i + 1].y()) * eps - y0;
        diff = std::max<S>(diff, std::max<S>(std::fabs(nx - xv[i]), std::fabs(ny - yv[i])));
        xv[i] = nx, yv[i] = ny;
      }
    }
    const Eigen::Matrix<S, 3, 1> I = B * xv, J = B * yv;
    const S inorm = I.norm(), jnorm = J.norm();
    const Eigen::Matrix<S, 3, 1> i_hat = I / inorm, j_hat = J / jnorm;
    R.row(0) = i_hat.transpose();
    R.row(1) = j_hat.transpose();
    R.row(2) = i_hat.cross(j_hat).transpose();
    if (o.mode == PositMode::kOrthonormal) {
      R = NearestRotation(R.template cast<double>()).template cast<S>();
    }
    scale = (inorm + jnorm) / S(2);
    inv_z = scale / f;
    res.iterations = it + 1;
    if (it > 0 && diff < static_cast<S>(o.epsilon)) {
      res.converged = true;
      break;
    }
  }
  res.R = R.template cast<double>();
  res.t = Eigen::Vector3d(x0 / scale, y0 / scale, 1.0 / inv_z);
  return res;
}

}  // namespace

StatusOr<PositResult> Posit(const std::vector<Eigen::Vector3d>& object_points,
                            const std::vector<Eigen::Vector2d>& image_points,
                            double focal_length,
                            const PositOptions& options) {
  std::string err;
  if (!options.Check(&err)) return Status::Error("POSIT options: " + err);
  if (object_points.size() != image_points.size()) {
    return Status::Error("POSIT: " + std::to_string(object_points.size()) + " object points but " +
                         std::to_string(image_points.size()) + " image points");
  }
  if (object_points.size() < 4) {
    return Status::Error("POSIT needs at least 4 non-coplanar points, got " +
                         std::to_string(object_points.size()));
  }
  if (!(focal_length > 0) || !std::isfinite(focal_length)) {
    return Status::Error("POSIT: focal length must be positive and finite");
  }
  for (size_t i = 0; i < object_points.size(); ++i) {
    if (!object_points[i].allFinite() || !image_points[i].allFinite()) {
      return Status::Error("POSIT: point " + std::to_string(i) + " is not finite");
    }
  }
  // Coplanarity: singular values of the reference-relative object vectors.
  Eigen::MatrixX3d A(object_points.size() - 1, 3);
  for (size_t i = 1; i < object_points.size(); ++i) {
    A.row(i - 1) = (object_points[i] - object_points[0]).transpose();
  }
  const Eigen::Vector3d sv = Eigen::JacobiSVD<Eigen::MatrixX3d>(A).singularValues();
  if (!(sv[0] > 0) || sv[2] < options.coplanarity_threshold * sv[0]) {
    return Status::Error("POSIT: the object points are (near-)coplanar (singular values " +
                         std::to_string(sv[0]) + ", " + std::to_string(sv[1]) + ", " +
                         std::to_string(sv[2]) + "); need 4 or more non-coplanar points");
  }
  const PositResult r =
      options.mode == PositMode::kLegacy
          ? PositIterate<float>(object_points, image_points, focal_length, options)
          : PositIterate<double>(object_points, image_points, focal_length, options);
  if (!r.R.allFinite() || !r.t.allFinite()) {
    return Status::Error("POSIT: the iteration diverged (non-finite pose)");
  }
  if (!(r.t.z() > 0)) return Status::Error("POSIT: solution places the object behind the source");
  if (!r.converged && options.mode == PositMode::kOrthonormal && options.require_convergence) {
    return Status::Error("POSIT did not converge to " + std::to_string(options.epsilon) +
                         " within " + std::to_string(options.max_iterations) + " iterations");
  }
  return r;
}

StatusOr<Eigen::Matrix<double, 6, 1>> PositPose(const Camera& camera,
                                                const std::vector<Eigen::Vector3d>& p_in_object,
                                                const std::vector<Eigen::Vector2d>& uv_px,
                                                const PositOptions& options) {
  const double f = std::sqrt(camera.params[kFx] * camera.params[kFy]);
  std::vector<Eigen::Vector2d> img(uv_px.size());
  for (size_t i = 0; i < uv_px.size(); ++i) {
    double xy[2];
    if (!uv_px[i].allFinite() ||
        !UnprojectToNormalized(camera.params.data(), uv_px[i].data(), xy)) {
      return Status::Error("POSIT: pixel " + std::to_string(i) + " cannot be undistorted");
    }
    img[i] = Eigen::Vector2d(xy[0], xy[1]) * f;
  }
  PositOptions o = options;
  o.mode = PositMode::kOrthonormal;
  auto r = Posit(p_in_object, img, f, o);
  if (!r.ok()) return r.status();
  // p_in_cam = R (p - p0) + t0 = R p + (t0 - R p0)
  const Eigen::Vector3d t = r->t - r->R * p_in_object[0];
  Eigen::Matrix<double, 6, 1> pose;
  pose.head<3>() = RvecFromRotation(r->R);
  pose.tail<3>() = t;
  return pose;
}

}  // namespace carmba
