#include "calib/calibrate.h"

#include <ceres/rotation.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <set>

#include "ba/bundle_adjuster.h"
#include "ba/quantities.h"
#include "ba/schur_lm.h"
#include "util/plausible.h"
#include "util/yaml_reader.h"

namespace carmba {

namespace {

using ba::LeftJacobianOf;
using ba::RobustWeight;

double Seconds(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

int IntrinsicIndexOf(const std::string& name) {
  for (int i = 0; i < kNumIntrinsics; ++i) {
    if (name == kIntrinsicNames[i]) return i;
  }
  return -1;
}

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
void PoseFromHomography(const Eigen::Matrix3d& H, const double* intr, std::array<double, 6>* pose) {
  Eigen::Matrix3d K;
  K << intr[kFx], 0, intr[kCx], 0, intr[kFy], intr[kCy], 0, 0, 1;
  const Eigen::Matrix3d M = K.inverse() * H;
  double lambda = 2.0 / (M.col(0).norm() + M.col(1).norm());
  if (M(2, 2) * lambda < 0) lambda = -lambda;
  Eigen::Matrix3d R;
  R.col(0) = lambda * M.col(0);
  R.col(1) = lambda * M.col(1);
  R.col(2) = R.col(0).cross(R.col(1));
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d Ro = svd.matrixU() * svd.matrixV().transpose();
  if (Ro.determinant() < 0) {
    Eigen::Matrix3d U = svd.matrixU();
    U.col(2) *= -1;
    Ro = U * svd.matrixV().transpose();
  }
  const Eigen::Vector3d t = lambda * M.col(2);
  double Rc[9];
  Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::ColMajor>> Rc_map(Rc);
  Rc_map = Ro;
  ceres::RotationMatrixToAngleAxis(Rc, pose->data());
  (*pose)[3] = t.x(), (*pose)[4] = t.y(), (*pose)[5] = t.z();
}

// The calibration as a problem of the bundle-adjustment engine: one intrinsics group, one plate
// pose per view, the plate's points held at the nominal grid.
ba::BaProblem CalibrationProblem(const ObservationSet& obs,
                                 const std::array<double, kNumIntrinsics>& x,
                                 const std::array<bool, kNumIntrinsics>& free,
                                 double fy_over_fx,
                                 double sigma_px,
                                 const std::vector<std::array<double, 6>>& poses) {
  ba::BaProblem p;
  p.name = "calibration";
  ba::IntrinsicsGroup g;
  g.width = obs.width;
  g.height = obs.height;
  g.initial = x;
  g.free = free;
  g.fy_over_fx = fy_over_fx;
  p.groups.push_back(g);
  for (int id = 0; id < obs.grid.NumPoints(); ++id) p.plate.points.push_back(obs.grid.PointInPlate(id));
  std::set<std::string> names;
  for (const auto& v : obs.views) names.insert(v.image);
  const bool by_image = names.size() == obs.views.size() && !names.count("");
  for (size_t v = 0; v < obs.views.size(); ++v) {
    ba::BaView view;
    view.id = by_image ? obs.views[v].image : std::to_string(v);
    view.kind = ba::ViewKind::kPlate;
    view.initial = Eigen::Map<const Pose6>(poses[v].data());
    view.point_ids = obs.views[v].point_ids;
    view.uv_px = obs.views[v].uv_px;
    view.sigma_px = sigma_px;
    p.views.push_back(std::move(view));
  }
  p.markers_free = false;
  return p;
}

// Gradient (2 x free state) of mrcal's projection of pixel (u, v) at distance d: the point
// p_cam = d * unproject(q) is fixed in the frame averaged over the plate poses,
//   q(theta) = project(intrinsics, mean_i T_i(theta) T_i0^-1 p_cam);
// each view maps p_cam back to itself at the solution, so view i's pose gradient is
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
      const Eigen::RowVector3d gr = w * LeftJacobianOf(pose) / num_views;
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

}  // namespace

bool CalibrationOptions::Check(std::string* error) const {
  for (const auto& n : fix) {
    if (IntrinsicIndexOf(n) < 0) {
      *error = "fix: unknown intrinsic '" + n + "' (expected fx fy cx cy k1 k2 p1 p2 k3)";
      return false;
    }
  }
  if (!(aspect_ratio_fy_over_fx >= 0) || !std::isfinite(aspect_ratio_fy_over_fx)) {
    *error = "aspect_ratio_fy_over_fx: expected >= 0 (0 = from the initial estimate)";
    return false;
  }
  if (!principal_point_px.empty() && principal_point_px.size() != 2) {
    *error = "principal_point_px: expected [cx, cy] or []";
    return false;
  }
  namespace pl = plausible;
  for (size_t i = 0; i < principal_point_px.size(); ++i) {
    if (!CheckRange("principal_point_px: element " + std::to_string(i), principal_point_px[i],
                    pl::kPixelCoordinatePx, error)) {
      return false;
    }
  }
  if (distortion_auto) {
    const char* conflict = zero_tangential ? "zero_tangential" : fix_k3 ? "fix_k3" : nullptr;
    for (const auto& n : fix) {
      if (!conflict && IntrinsicIndexOf(n) >= kK1) conflict = "fix";
    }
    if (conflict) {
      *error = std::string("distortion: auto chooses the distortion terms itself; remove ") +
               conflict + " (or set distortion: given)";
      return false;
    }
  }
  if (!initial_intrinsics.empty() && initial_intrinsics.size() != kNumIntrinsics) {
    *error = "initial_intrinsics: expected 9 values [fx, fy, cx, cy, k1, k2, p1, p2, k3]";
    return false;
  }
  for (size_t i = 0; i < initial_intrinsics.size(); ++i) {
    const PlausibleRange& r = i < 2 ? pl::kFocalPx : i < 4 ? pl::kPixelCoordinatePx : pl::kDistortion;
    if (!CheckRange(std::string("initial_intrinsics: ") + kIntrinsicNames[i],
                    initial_intrinsics[i], r, error)) {
      return false;
    }
  }
  if (robust_loss != "none" && robust_loss != "huber" && robust_loss != "cauchy") {
    *error = "robust_loss: expected none, huber or cauchy, got '" + robust_loss + "'";
    return false;
  }
  if (!CheckRange("robust_loss_scale_px", robust_loss_scale_px, pl::kLossScalePx, error) ||
      !CheckRange("outlier_threshold_sigma", outlier_threshold_sigma, pl::kSigmaMultiple,
                  error)) {
    return false;
  }
  if (pixel_sigma_px != 0 && !InRange(pixel_sigma_px, pl::kPixelSigmaPx)) {
    *error = "pixel_sigma_px: expected 0 (estimate) or " + FormatRange(pl::kPixelSigmaPx) +
             ", got " + FormatCompact(pixel_sigma_px);
    return false;
  }
  if (min_views < 1) {
    *error = "min_views: expected >= 1";
    return false;
  }
  if (max_iterations < 1) {
    *error = "max_iterations: expected >= 1";
    return false;
  }
  if (!CheckRange("max_iterations", max_iterations, pl::kMaxIterations, error)) return false;
  if (uncertainty_distance_mm != 0 && !InRange(uncertainty_distance_mm, pl::kDistanceMm)) {
    *error = "uncertainty_distance_mm: expected 0 (the median plate distance) or " +
             FormatRange(pl::kDistanceMm) + ", got " + FormatCompact(uncertainty_distance_mm);
    return false;
  }
  if (solver != "lm" && solver != "ceres") {
    *error = "solver: expected lm or ceres, got '" + solver + "'";
    return false;
  }
  if (!CheckRange("num_threads", num_threads, pl::kThreads, error)) return false;
  return true;
}

Status LoadCalibrationOptions(const std::string& path,
                              CalibrationOptions* o,
                              const std::vector<std::string>& other_keys) {
  YamlMap m = YamlMap::Load(path);
  CARMBA_RETURN_IF_ERROR(m.status());
  for (const char* k : {"initializer", "linear_solver", "covariance", "jacobians", "refine"}) {
    if (m.Has(k)) {
      return Status::Error(path + ": this is a solver config (key '" + k +
                           "'), for `carmba solve`; `carmba calibrate` needs a calibration config "
                           "(fix, robust_loss, pixel_sigma_px, detection; configs/calib_*.yaml)");
    }
  }
  m.Get("fix", &o->fix);
  m.Get("fix_aspect_ratio", &o->fix_aspect_ratio);
  m.Get("aspect_ratio_fy_over_fx", &o->aspect_ratio_fy_over_fx);
  m.Get("zero_tangential", &o->zero_tangential);
  m.Get("fix_principal_point", &o->fix_principal_point);
  m.Get("principal_point_px", &o->principal_point_px);
  m.Get("fix_k3", &o->fix_k3);
  std::string distortion = "given";
  m.GetEnum("distortion", {"given", "auto"}, &distortion);
  o->distortion_auto = distortion == "auto";
  m.Get("initial_intrinsics", &o->initial_intrinsics);
  m.GetEnum("robust_loss", {"none", "huber", "cauchy"}, &o->robust_loss);
  m.GetInRange("robust_loss_scale_px", &o->robust_loss_scale_px, plausible::kLossScalePx);
  m.GetInRange("outlier_threshold_sigma", &o->outlier_threshold_sigma, plausible::kSigmaMultiple);
  m.GetNonNegative("pixel_sigma_px", &o->pixel_sigma_px);
  m.Get("min_views", &o->min_views);
  m.GetInRange("max_iterations", &o->max_iterations, plausible::kMaxIterations);
  m.GetNonNegative("uncertainty_distance_mm", &o->uncertainty_distance_mm);
  m.GetInRange("num_threads", &o->num_threads, plausible::kThreads);
  m.GetEnum("solver", {"lm", "ceres"}, &o->solver);
  for (const auto& k : other_keys) {
    if (m.Has(k)) m.Raw(k);
  }
  CARMBA_RETURN_IF_ERROR(m.Finish());
  std::string err;
  if (!o->Check(&err)) return Status::Error(path + ": " + err);
  return Status::Ok();
}

StatusOr<CalibrationResult> Calibrate(const ObservationSet& obs, const CalibrationOptions& opt) {
  std::string err;
  if (!opt.Check(&err)) return Status::Error("calibration options: " + err);
  if (!obs.grid.Check(&err)) return Status::Error(err);
  if (obs.width <= 0 || obs.height <= 0) return Status::Error("image size unknown (expected > 0)");
  const int num_views = static_cast<int>(obs.views.size());
  if (num_views < opt.min_views) {
    return Status::Error("only " + std::to_string(num_views) + " usable view(s), min_views is " +
                         std::to_string(opt.min_views));
  }
  std::vector<std::vector<Eigen::Vector3d>> plate(num_views);
  for (int v = 0; v < num_views; ++v) {
    const auto& view = obs.views[v];
    if (view.uv_px.size() < 4 || view.uv_px.size() != view.point_ids.size()) {
      return Status::Error("view " + std::to_string(v) + " (" + view.image +
                           "): expected at least 4 points, got " +
                           std::to_string(view.uv_px.size()));
    }
    for (size_t j = 0; j < view.uv_px.size(); ++j) {
      if (!view.uv_px[j].allFinite()) {
        return Status::Error("view " + std::to_string(v) + " (" + view.image + "): point " +
                             std::to_string(view.point_ids[j]) + " is not finite");
      }
      plate[v].push_back(obs.grid.PointInPlate(view.point_ids[j]));
    }
  }
  const auto t0 = std::chrono::steady_clock::now();

  // --- Closed-form initialisation.
  CalibrationResult r;
  double cx = (obs.width - 1) * 0.5, cy = (obs.height - 1) * 0.5;
  if (!opt.principal_point_px.empty()) {
    cx = opt.principal_point_px[0];
    cy = opt.principal_point_px[1];
  }
  std::vector<Eigen::Matrix3d> H(num_views);
  for (int v = 0; v < num_views; ++v) {
    std::vector<Eigen::Vector2d> src;
    for (const auto& p : plate[v]) src.emplace_back(p.x(), p.y());
    if (!FitHomography(src, obs.views[v].uv_px, &H[v])) {
      return Status::Error("view " + std::to_string(v) + " (" + obs.views[v].image +
                           "): no homography (collinear points?)");
    }
  }
  std::array<double, kNumIntrinsics> x0{};
  if (!opt.initial_intrinsics.empty()) {
    std::copy(opt.initial_intrinsics.begin(), opt.initial_intrinsics.end(), x0.begin());
  } else {
    // Zhang with known principal point and zero skew, in units of s = max(w, h) px.
    const double s = std::max(obs.width, obs.height);
    Eigen::Matrix3d N;
    N << 1 / s, 0, -cx / s, 0, 1 / s, -cy / s, 0, 0, 1;
    Eigen::MatrixXd V(2 * num_views, 3);
    for (int v = 0; v < num_views; ++v) {
      Eigen::Matrix3d Hn = N * H[v];
      Hn /= Hn.col(0).norm() + Hn.col(1).norm();
      const Eigen::Vector3d h1 = Hn.col(0), h2 = Hn.col(1);
      V.row(2 * v) << h1(0) * h2(0), h1(1) * h2(1), h1(2) * h2(2);
      V.row(2 * v + 1) << h1(0) * h1(0) - h2(0) * h2(0), h1(1) * h1(1) - h2(1) * h2(1),
          h1(2) * h1(2) - h2(2) * h2(2);
    }
    double b1, b2, b3;
    const double ratio = opt.fix_aspect_ratio ? opt.aspect_ratio_fy_over_fx : 0.0;
    if (ratio > 0) {
      // b2 = b1 / r^2: unknowns (b1, b3).
      Eigen::MatrixXd V2(V.rows(), 2);
      V2.col(0) = V.col(0) + V.col(1) / (ratio * ratio);
      V2.col(1) = V.col(2);
      Eigen::JacobiSVD<Eigen::MatrixXd> svd(V2, Eigen::ComputeFullV);
      const Eigen::Vector2d b = svd.matrixV().col(1);
      b1 = b(0), b2 = b(0) / (ratio * ratio), b3 = b(1);
    } else {
      Eigen::JacobiSVD<Eigen::MatrixXd> svd(V, Eigen::ComputeFullV);
      const Eigen::Vector3d b = svd.matrixV().col(2);
      b1 = b(0), b2 = b(1), b3 = b(2);
    }
    if (!(b1 / b3 > 0) || !(b2 / b3 > 0) || !std::isfinite(b1 / b3) || !std::isfinite(b2 / b3)) {
      return Status::Error("closed-form initialisation failed: the views do not determine the "
                           "focal length (degenerate views, e.g. all fronto-parallel; tilt the "
                           "plate in several views)");
    }
    x0[kFx] = s * std::sqrt(b3 / b1);
    x0[kFy] = s * std::sqrt(b3 / b2);
    x0[kCx] = cx, x0[kCy] = cy;
    if (!(x0[kFx] < 1e4 * s) || !(x0[kFy] < 1e4 * s)) {
      return Status::Error("closed-form initialisation failed: focal length " +
                           std::to_string(x0[kFx]) +
                           " px is not determined (degenerate views, e.g. all fronto-parallel)");
    }
  }
  if (opt.fix_principal_point) x0[kCx] = cx, x0[kCy] = cy;
  if (opt.zero_tangential) x0[kP1] = x0[kP2] = 0;
  if (opt.fix_k3) x0[kK3] = 0;
  double ratio = opt.aspect_ratio_fy_over_fx;
  if (opt.fix_aspect_ratio) {
    if (ratio == 0) ratio = x0[kFy] / x0[kFx];
    const double f = std::sqrt(x0[kFx] * x0[kFy] / ratio);
    x0[kFx] = f, x0[kFy] = ratio * f;
  }
  r.initial_intrinsics = x0;
  r.cam_from_plate.resize(num_views);
  for (int v = 0; v < num_views; ++v) PoseFromHomography(H[v], x0.data(), &r.cam_from_plate[v]);
  r.initial_cam_from_plate = r.cam_from_plate;

  // --- What is free: intrinsics = x0 + A delta (held parameters, fy = r fx), the engine's basis.
  r.free.assign(kNumIntrinsics, true);
  for (const auto& n : opt.fix) r.free[IntrinsicIndexOf(n)] = false;
  if (opt.fix_principal_point) r.free[kCx] = r.free[kCy] = false;
  if (opt.zero_tangential) r.free[kP1] = r.free[kP2] = false;
  if (opt.fix_k3) r.free[kK3] = false;
  if (opt.fix_aspect_ratio) r.free[kFy] = r.free[kFx];  // fy follows fx
  std::array<bool, kNumIntrinsics> free{};
  for (int i = 0; i < kNumIntrinsics; ++i) free[i] = r.free[i];
  const double fy_over_fx = opt.fix_aspect_ratio ? ratio : 0.0;
  r.robust_loss = opt.robust_loss;
  r.robust_loss_scale_px = opt.robust_loss_scale_px;

  // --- Bundle adjustment through the engine, in two stages when distortion is estimated: first
  // the pinhole core with the distortion held at its initial value (mrcal seeds the same way),
  // then everything. Back end: carmba's Schur LM (solver: lm, no robust loss) or Ceres.
  const double sigma_solve = opt.pixel_sigma_px > 0 ? opt.pixel_sigma_px : 1.0;
  const bool own_lm = opt.solver == "lm" && opt.robust_loss == "none";
  ba::BaOptions bo;
  bo.backend = own_lm ? "carmba_lm" : "ceres";
  bo.loss = opt.robust_loss == "none" ? "trivial" : opt.robust_loss;
  bo.loss_scale_px = opt.robust_loss_scale_px;
  bo.linear_solver = "dense_schur";
  bo.max_iterations = opt.max_iterations;
  bo.num_threads = opt.num_threads;
  bo.outlier_sigma = opt.outlier_threshold_sigma;
  std::array<double, kNumIntrinsics> x = x0;
  auto run_stage = [&](const std::array<bool, kNumIntrinsics>& stage_free, bool coarse)
      -> StatusOr<ba::BaResult> {
    // The pinhole stage only seeds the full solve: loose tolerances.
    bo.function_tolerance = coarse ? 1e-6 : 1e-10;
    bo.gradient_tolerance = coarse ? 1e-10 : 1e-14;
    bo.parameter_tolerance = coarse ? 1e-6 : 1e-10;
    bo.compute_covariance = !coarse;
    bo.evaluate_solution = !coarse;
    const ba::BaProblem p =
        CalibrationProblem(obs, x, stage_free, fy_over_fx, sigma_solve, r.cam_from_plate);
    auto res = ba::SolveBundleAdjustment(p, bo);
    if (!res.ok()) {
      const std::string& m = res.status().message();
      if (m.find("not determined") != std::string::npos ||
          m.find("free direction") != std::string::npos) {
        return Status::Error("the views do not determine the intrinsics (" + m +
                             "); degenerate views, e.g. all fronto-parallel or too few tilts");
      }
      if (m.find("non-finite residual") != std::string::npos) {
        return Status::Error("initialisation puts grid points behind the source (bad detections?)");
      }
      return res.status();
    }
    const ba::StateLayout& L = *res->layout;
    std::copy(res->block(L.group_block(0)), res->block(L.group_block(0)) + kNumIntrinsics,
              x.begin());
    for (int v = 0; v < num_views; ++v) {
      std::copy(res->block(L.view_block(v)), res->block(L.view_block(v)) + 6,
                r.cam_from_plate[v].begin());
    }
    return res;
  };
  {
    std::array<bool, kNumIntrinsics> core = free;
    bool any_distortion = false;
    for (int i = kK1; i < kNumIntrinsics; ++i) any_distortion |= core[i], core[i] = false;
    if (any_distortion) CARMBA_RETURN_IF_ERROR(run_stage(core, true).status());
  }
  if (opt.distortion_auto) {
    // The distortion terms chosen by the data (ba/lens_models.h), seeded by the pinhole stage;
    // with an unknown pixel sigma the comparison estimates it from the full model.
    std::array<bool, kNumIntrinsics> all = free;
    for (int i = kK1; i < kNumIntrinsics; ++i) all[i] = true;
    ba::BaProblem p = CalibrationProblem(obs, x, all, fy_over_fx, sigma_solve, r.cam_from_plate);
    ba::BaOptions so = bo;
    so.function_tolerance = 1e-10, so.gradient_tolerance = 1e-14, so.parameter_tolerance = 1e-10;
    so.compute_covariance = so.evaluate_solution = true;
    auto sel = ba::SelectDistortionModel(p, so, ba::kDistortionFolds, opt.pixel_sigma_px == 0);
    if (!sel.ok()) return Status::Error("distortion: auto: " + sel.status().message());
    ba::ApplyDistortionModel(sel->recommended, &p);
    for (int i = kK1; i < kNumIntrinsics; ++i) {
      free[i] = p.groups[0].free[i];
      r.free[i] = free[i];
      if (!free[i]) x[i] = 0;
    }
    r.distortion = *sel;
  }
  auto solved = run_stage(free, false);
  if (!solved.ok()) return solved.status();
  auto engine = std::make_shared<ba::BaResult>(std::move(*solved));
  r.iterations = engine->iterations;
  r.termination = engine->termination + (own_lm ? "" : " (Ceres)");
  r.converged = engine->converged;
  {
    const ba::BlockInfo& gi = engine->layout->block(engine->layout->group_block(0));
    r.intrinsics_from_free =
        gi.constant ? Eigen::MatrixXd::Zero(kNumIntrinsics, 0) : gi.basis;
  }
  const int k = static_cast<int>(r.intrinsics_from_free.cols());
  r.num_free_intrinsics = k;
  std::copy(x.begin(), x.end(), r.camera.params.begin());
  r.camera.width = obs.width;
  r.camera.height = obs.height;
  const auto t1 = std::chrono::steady_clock::now();
  r.solve_seconds = Seconds(t0, t1);

  // --- Residual statistics.
  double ssr = 0, ssr_weighted = 0;
  std::vector<PointResidual> all;
  r.points.resize(obs.grid.NumPoints());
  std::vector<double> point_ssr(obs.grid.NumPoints(), 0.0);
  for (int v = 0; v < num_views; ++v) {
    const auto& view = obs.views[v];
    ViewStats vs;
    vs.image = view.image;
    vs.num_points = static_cast<int>(view.uv_px.size());
    double vssr = 0;
    const Eigen::Matrix3d R = RotationOf(r.cam_from_plate[v].data());
    const Eigen::Vector3d t(r.cam_from_plate[v][3], r.cam_from_plate[v][4], r.cam_from_plate[v][5]);
    for (size_t j = 0; j < view.uv_px.size(); ++j) {
      // A point behind the source (not at a solution that passed the solver) reads as NaN.
      double uv[2] = {std::nan(""), std::nan("")};
      const Eigen::Vector3d pc = R * plate[v][j] + t;
      ProjectCamPoint(x.data(), pc.data(), uv);
      PointResidual pr;
      pr.view = v;
      pr.point_id = view.point_ids[j];
      pr.du_px = uv[0] - view.uv_px[j].x();
      pr.dv_px = uv[1] - view.uv_px[j].y();
      const double e2 = pr.du_px * pr.du_px + pr.dv_px * pr.dv_px;
      pr.norm_px = std::sqrt(e2);
      vssr += e2;
      vs.max_px = std::max(vs.max_px, pr.norm_px);
      point_ssr[pr.point_id] += e2;
      r.points[pr.point_id].num_views++;
      const double w = opt.robust_loss == "none"
                           ? 1.0
                           : RobustWeight(opt.robust_loss, opt.robust_loss_scale_px / sigma_solve,
                                          e2 / (sigma_solve * sigma_solve));
      ssr_weighted += w * e2;
      all.push_back(pr);
    }
    ssr += vssr;
    vs.rms_px = std::sqrt(vssr / (2.0 * vs.num_points));
    vs.tilt_deg = std::acos(std::min(1.0, std::abs(R(2, 2)))) * 180.0 / M_PI;
    vs.distance_mm = Eigen::Vector3d(r.cam_from_plate[v][3], r.cam_from_plate[v][4],
                                     r.cam_from_plate[v][5])
                         .norm();
    r.views.push_back(vs);
  }
  for (int id = 0; id < obs.grid.NumPoints(); ++id) {
    r.points[id].point_id = id;
    if (r.points[id].num_views > 0) {
      r.points[id].rms_px = std::sqrt(point_ssr[id] / (2.0 * r.points[id].num_views));
    }
  }
  r.num_points = static_cast<int>(all.size());
  r.dof = 2 * r.num_points - (6 * num_views + k);
  r.rms_px = std::sqrt(ssr / (2.0 * r.num_points));
  r.rms_opencv_px = std::sqrt(ssr / r.num_points);
  if (opt.pixel_sigma_px > 0) {
    r.sigma_px = opt.pixel_sigma_px;
  } else {
    if (r.dof <= 0) {
      return Status::Error("cannot estimate the pixel sigma: " + std::to_string(2 * r.num_points) +
                           " residuals for " + std::to_string(6 * num_views + k) +
                           " parameters (give pixel_sigma_px or more points)");
    }
    r.sigma_px = std::sqrt(ssr_weighted / r.dof);
    r.sigma_estimated = true;
  }
  // Outliers and the 10 worst, largest first (only those are sorted).
  const auto larger = [](const PointResidual& a, const PointResidual& b) {
    return a.norm_px > b.norm_px;
  };
  for (const auto& pr : all) {
    if (pr.norm_px > opt.outlier_threshold_sigma * r.sigma_px) r.outliers.push_back(pr);
  }
  std::sort(r.outliers.begin(), r.outliers.end(), larger);
  const size_t num_worst = std::min<size_t>(all.size(), 10);
  std::partial_sort(all.begin(), all.begin() + num_worst, all.end(), larger);
  all.resize(num_worst);
  r.worst = all;

  // --- Covariance of the intrinsics, marginal over the poses (the engine's Schur covariance),
  // in units of the pixel sigma used.
  r.covariance_scale = (r.sigma_px / sigma_solve) * (r.sigma_px / sigma_solve);
  r.covariance = engine->Covariance({engine->layout->group_block(0)}) * r.covariance_scale;
  for (int i = 0; i < kNumIntrinsics; ++i) r.sigma[i] = std::sqrt(std::max(0.0, r.covariance(i, i)));
  r.engine = engine;
  // A focal length known to worse than 10 % means the views do not constrain it (a fronto-parallel
  // set is exactly singular without noise, nearly singular with it).
  constexpr double kMaxRelativeFocalSigma = 0.1;
  for (int i : {kFx, kFy}) {
    if (r.free[i] && !(r.sigma[i] < kMaxRelativeFocalSigma * r.camera.params[i])) {
      return Status::Error(std::string("the views do not determine ") + kIntrinsicNames[i] +
                           " (sigma " + std::to_string(r.sigma[i]) + " px for " +
                           std::to_string(r.camera.params[i]) +
                           " px); degenerate views, e.g. all fronto-parallel");
    }
  }
  r.camera.covariance_names.assign(kIntrinsicNames, kIntrinsicNames + kNumIntrinsics);
  r.camera.covariance.assign(kNumIntrinsics, std::vector<double>(kNumIntrinsics));
  for (int i = 0; i < kNumIntrinsics; ++i) {
    for (int j = 0; j < kNumIntrinsics; ++j) r.camera.covariance[i][j] = r.covariance(i, j);
  }

  // --- Projection uncertainty at the centre and the corners.
  if (opt.uncertainty_distance_mm > 0) {
    r.uncertainty_distance_mm = opt.uncertainty_distance_mm;
  } else {
    std::vector<double> d;
    for (const auto& vs : r.views) d.push_back(vs.distance_mm);
    std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
    r.uncertainty_distance_mm = d[d.size() / 2];
  }
  const double W = obs.width - 1, Hh = obs.height - 1;
  const std::pair<const char*, Eigen::Vector2d> where[] = {
      {"centre", {W / 2, Hh / 2}}, {"top-left", {0, 0}},      {"top-right", {W, 0}},
      {"bottom-left", {0, Hh}},    {"bottom-right", {W, Hh}}};
  for (const auto& [name, q] : where) {
    ProjectionSigma ps;
    if (!ProjectionSigmaAt(r, q.x(), q.y(), r.uncertainty_distance_mm, &ps)) continue;
    ps.where = name;
    r.projection_sigma.push_back(ps);
  }
  r.covariance_seconds = Seconds(t1, std::chrono::steady_clock::now());
  Status s = r.camera.Check();
  if (!s.ok()) return s.WithContext("calibrated camera");
  return r;
}

StatusOr<ProjectionSigma> ProjectionUncertainty(const ObservationSet& obs,
                                                const CalibrationResult& result,
                                                double u_px,
                                                double v_px,
                                                double distance_mm) {
  if (!result.engine || !result.engine->covariance) {
    return Status::Error("projection uncertainty: the calibration has no covariance");
  }
  if (result.engine->views.size() != obs.views.size()) {
    return Status::Error("projection uncertainty: the observations are not the calibration's");
  }
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
  if (!result.engine || !result.engine->covariance) {
    return Status::Error("projection uncertainty: the calibration has no covariance");
  }
  if (result.engine->views.size() != obs.views.size()) {
    return Status::Error("projection uncertainty: the observations are not the calibration's");
  }
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

Status CheckPlateDistance(const CalibrationResult& result,
                          double spacing_mm,
                          const std::string& pitch_source) {
  std::vector<double> d;
  for (const ViewStats& v : result.views) d.push_back(v.distance_mm);
  if (d.empty()) return Status::Ok();
  std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
  const double median = d[d.size() / 2];
  if (InRange(median, plausible::kPlateDistanceMm)) return Status::Ok();
  return Status::Error("the plate sits " + FormatCompact(median) + " mm from the source (median of " +
                       std::to_string(result.views.size()) + " views), expected " +
                       FormatRange(plausible::kPlateDistanceMm) + ": check the grid pitch, " +
                       pitch_source + " " + FormatCompact(spacing_mm) +
                       (median < plausible::kPlateDistanceMm.lo ? " (a unit slip? cm for mm)"
                                                                 : " (a unit slip?)"));
}

}  // namespace carmba
