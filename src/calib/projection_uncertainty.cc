#include "calib/projection_uncertainty.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "ba/quantities.h"
#include "geometry/rotation.h"

namespace carmba {

namespace {

// Gradient (2 x free state) of mrcal's projection of pixel (u, v) at distance d: each view maps
// p_cam back to itself at the solution, so view i's pose gradient is
// [((p_cam - t_i) x a) J_l(r_i), a] / n per row a of dq/dp_cam. False if q cannot be unprojected.
bool ProjectionGradient(const ba::BaResult& e,
                        double u,
                        double v,
                        double distance_mm,
                        Eigen::MatrixXd* G) {
  const ba::StateLayout& L = *e.layout;
  const int gb = L.group_block(0);
  const double* intr = e.block(gb);
  const double q[2] = {u, v};
  double xy[2];
  if (!UnprojectToNormalized(intr, q, xy)) return false;
  Eigen::Vector3d p_cam(xy[0], xy[1], 1.0);
  p_cam *= distance_mm / p_cam.norm();
  double uv[2], Jpc[6];
  Eigen::Matrix<double, 2, kNumIntrinsics, Eigen::RowMajor> Ji;
  if (!ProjectCamPointWithJac(intr, p_cam.data(), uv, Ji.data(), Jpc)) return false;
  *G = Eigen::MatrixXd::Zero(2, L.num_free());
  const int num_views = static_cast<int>(e.views.size());
  for (int row = 0; row < 2; ++row) {
    ba::AddGradientRow(L, gb, Ji.row(row).data(), row, G);
    const double* c = Jpc + 3 * row;
    for (int i = 0; i < num_views; ++i) {
      const int vb = L.view_block(i);
      const double* pose = e.block(vb);
      const Eigen::Vector3d Rp = p_cam - Eigen::Vector3d(pose[3], pose[4], pose[5]);
      const Eigen::RowVector3d w(Rp.y() * c[2] - Rp.z() * c[1], Rp.z() * c[0] - Rp.x() * c[2],
                                 Rp.x() * c[1] - Rp.y() * c[0]);
      double g[6];
      const Eigen::RowVector3d gr = w * SO3LeftJacobian(pose) / num_views;
      for (int k = 0; k < 3; ++k) g[k] = gr(k);
      for (int k = 0; k < 3; ++k) g[3 + k] = c[k] / num_views;
      ba::AddGradientRow(L, vb, g, row, G);
    }
  }
  return true;
}

// Cov(q) of the projection of (u, v) at distance_mm, in px^2 (scaled to the result's sigma_px).
bool ProjectionSigmaAt(const CalibrationResult& r,
                       double u,
                       double v,
                       double distance_mm,
                       ProjectionSigma* ps) {
  const ba::BaResult& e = *r.engine;
  Eigen::MatrixXd G;
  if (!ProjectionGradient(e, u, v, distance_mm, &G)) return false;
  Eigen::Matrix2d cov = G * e.covariance->Solve(G.transpose());
  cov *= r.covariance_scale;
  ps->u_px = u, ps->v_px = v;
  ps->sigma_u_px = std::sqrt(std::max(0.0, cov(0, 0)));
  ps->sigma_v_px = std::sqrt(std::max(0.0, cov(1, 1)));
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(cov);
  ps->worst_px = std::sqrt(std::max(0.0, es.eigenvalues()(1)));
  return true;
}

Status CheckSolvedFor(const ObservationSet& obs, const CalibrationResult& result) {
  if (!result.engine || !result.engine->covariance) {
    return Status::Error("projection uncertainty: the calibration has no covariance");
  }
  if (result.engine->views.size() != obs.views.size()) {
    return Status::Error("projection uncertainty: the observations are not the calibration's");
  }
  return Status::Ok();
}

}  // namespace

StatusOr<ProjectionSigma> ProjectionUncertainty(const ObservationSet& obs,
                                                const CalibrationResult& result,
                                                double u_px,
                                                double v_px,
                                                double distance_mm) {
  CARMBA_RETURN_IF_ERROR(CheckSolvedFor(obs, result));
  ProjectionSigma ps;
  if (!ProjectionSigmaAt(result, u_px, v_px, distance_mm, &ps)) {
    return Status::Error("pixel cannot be unprojected with the calibrated distortion");
  }
  return ps;
}

StatusOr<std::vector<ProjectionSigma>> ProjectionUncertainties(
    const ObservationSet& obs,
    const CalibrationResult& result,
    const std::vector<Eigen::Vector2d>& pixels,
    double distance_mm) {
  CARMBA_RETURN_IF_ERROR(CheckSolvedFor(obs, result));
  std::vector<ProjectionSigma> out;
  for (const auto& q : pixels) {
    ProjectionSigma ps;
    if (!ProjectionSigmaAt(result, q.x(), q.y(), distance_mm, &ps)) {
      ps.u_px = q.x();
      ps.v_px = q.y();
      ps.sigma_u_px = ps.sigma_v_px = ps.worst_px = std::numeric_limits<double>::quiet_NaN();
    }
    out.push_back(ps);
  }
  return out;
}

void ProjectionSigmaAtCentreAndCorners(int width, int height, double distance_mm,
                                       CalibrationResult* r) {
  if (distance_mm > 0) {
    r->uncertainty_distance_mm = distance_mm;
  } else {
    std::vector<double> d;
    for (const auto& vs : r->views) d.push_back(vs.distance_mm);
    std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
    r->uncertainty_distance_mm = d[d.size() / 2];
  }
  const double W = width - 1, H = height - 1;
  const std::pair<const char*, Eigen::Vector2d> where[] = {
      {"centre", {W / 2, H / 2}}, {"top-left", {0, 0}},     {"top-right", {W, 0}},
      {"bottom-left", {0, H}},    {"bottom-right", {W, H}}};
  for (const auto& [name, q] : where) {
    ProjectionSigma ps;
    if (!ProjectionSigmaAt(*r, q.x(), q.y(), r->uncertainty_distance_mm, &ps)) continue;
    ps.where = name;
    r->projection_sigma.push_back(ps);
  }
}

}  // namespace carmba
