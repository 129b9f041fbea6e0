#include "ba/tre.h"

#include <chrono>
#include <cmath>
#include <limits>
#include <map>

#include "ba/triangulation.h"

namespace carmba {
namespace ba {

double FitzpatrickTre2(const std::vector<Eigen::Vector3d>& fid,
                       const Eigen::Vector3d& target,
                       double fle2) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  if (fid.size() < 3) return nan;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& p : fid) c += p;
  c /= static_cast<double>(fid.size());
  Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
  for (const auto& p : fid) S += (p - c) * (p - c).transpose();
  const Eigen::Matrix3d U = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(S).eigenvectors();
  // Squared distance of q (relative to the centroid) from the axis u through the centroid.
  auto dist2 = [](const Eigen::Vector3d& q, const Eigen::Vector3d& u) {
    const double a = q.dot(u);
    return std::max(0.0, q.squaredNorm() - a * a);
  };
  double sum = 0;
  for (int a = 0; a < 3; ++a) {
    double f2 = 0;
    for (const auto& p : fid) f2 += dist2(p - c, U.col(a));
    f2 /= static_cast<double>(fid.size());
    if (!(f2 > 1e-12 * S.trace())) return nan;  // collinear: an axis with all fiducials on it
    sum += dist2(target - c, U.col(a)) / f2;
  }
  return fle2 / static_cast<double>(fid.size()) * (1.0 + sum / 3.0);
}

StatusOr<TreResult> LeaveOneMarkerOut(const BaProblem& problem,
                                      const BaResult& full,
                                      const BaOptions& options_in) {
  const auto t0 = std::chrono::steady_clock::now();
  if (!full.covariance) return Status::Error("leave-one-marker-out: the solve has no covariance");
  if (!problem.rigs.empty()) return Status::Error("leave-one-marker-out: a problem with rigs is not supported");
  const StateLayout& L = *full.layout;
  BaOptions options = options_in;
  options.reject_sigma = 0;
  options.compute_covariance = true;
  const double nan = std::numeric_limits<double>::quiet_NaN();

  for (const IntrinsicsGroup& g : problem.groups) {
    if (g.smooth) {
      return Status::Error("leave-one-marker-out: group '" + g.name +
                           "' has angle-dependent (smooth) intrinsics, which the TRE does not support");
    }
  }
  // The problem with the full solve's rejections removed and its solution as initial values.
  BaProblem base = problem;
  for (size_t g = 0; g < base.groups.size(); ++g) {
    const double* x = full.block(L.group_block(static_cast<int>(g)));
    std::copy(x, x + kNumIntrinsics, base.groups[g].initial.begin());
  }
  for (size_t v = 0; v < base.views.size(); ++v) {
    BaView& view = base.views[v];
    view.initial = Eigen::Map<const Pose6>(full.block(L.view_block(static_cast<int>(v))));
    if (v < full.dropped.size() && !full.dropped[v].empty()) {
      std::vector<char> keep(view.point_ids.size());
      for (size_t i = 0; i < keep.size(); ++i) keep[i] = !full.dropped[v][i];
      view = KeepObservations(view, keep);
    }
  }

  // Each marker's pixel-only localisation with the full solve (FLE_xray) and its CT error.
  TreResult out;
  double fle_ct2 = 0, fle_xray2 = 0;
  int n_xray = 0;
  std::vector<std::vector<PixelObservation>> obs_of(base.markers.size());
  for (size_t m = 0; m < base.markers.size(); ++m) {
    fle_ct2 += base.markers[m].covariance.trace();
    for (size_t v = 0; v < base.views.size(); ++v) {
      const BaView& view = base.views[v];
      if (view.kind != ViewKind::kObject) continue;
      for (size_t i = 0; i < view.point_ids.size(); ++i) {
        if (view.point_ids[i] != base.markers[m].id) continue;
        PixelObservation o;
        o.view = static_cast<int>(v);
        o.uv_px = view.uv_px[i];
        o.covariance_px2 = view.CovariancePx2(i);
        obs_of[m].push_back(o);
      }
    }
    if (obs_of[m].size() >= 2) {
      TriangulationOptions to;
      to.min_ray_angle_deg = 0;
      auto t = TriangulatePoint(base, full, obs_of[m], to);
      if (t.ok()) {
        fle_xray2 += t->covariance_pixels.trace();
        ++n_xray;
      }
    }
  }
  fle_ct2 /= std::max<size_t>(1, base.markers.size());
  fle_xray2 = n_xray ? fle_xray2 / n_xray : nan;
  out.fle_ct_mm = std::sqrt(fle_ct2);
  out.fle_xray_mm = std::sqrt(fle_xray2);
  out.fle_mm = std::sqrt(fle_ct2 + fle_xray2);

  double sum_e2 = 0, sum_pred2 = 0, sum_fitz2 = 0, sum_m2 = 0;
  for (size_t m = 0; m < base.markers.size(); ++m) {
    MarkerTre row;
    const BaMarker& marker = base.markers[m];
    row.marker_id = marker.id;
    row.p_ct = marker.p_ct;
    row.ct_covariance = marker.covariance;
    // The reduced problem.
    BaProblem reduced = base;
    reduced.markers.erase(reduced.markers.begin() + static_cast<long>(m));
    reduced.views.clear();
    std::map<int, int> reduced_index;  // base view index -> reduced
    for (size_t v = 0; v < base.views.size(); ++v) {
      BaView view = base.views[v];
      if (view.kind == ViewKind::kObject) {
        std::vector<char> keep(view.point_ids.size());
        for (size_t i = 0; i < keep.size(); ++i) keep[i] = view.point_ids[i] != marker.id;
        const BaView kept = KeepObservations(view, keep);
        if (kept.point_ids.size() < 4) {
          ++row.num_views_left_out;
          continue;
        }
        view = kept;
      }
      reduced_index[static_cast<int>(v)] = static_cast<int>(reduced.views.size());
      reduced.views.push_back(view);
    }
    std::vector<PixelObservation> obs;
    for (PixelObservation o : obs_of[m]) {
      auto it = reduced_index.find(o.view);
      if (it == reduced_index.end()) continue;
      o.view = it->second;
      obs.push_back(o);
    }
    row.num_views = static_cast<int>(obs.size());
    if (obs.size() < 2) {
      row.skipped = "seen in " + std::to_string(obs.size()) + " view(s) of the solve without it" +
                    (row.num_views_left_out ? " (" + std::to_string(row.num_views_left_out) +
                                                  " view(s) left out: fewer than 4 other markers)"
                                            : std::string()) +
                    ": at least two are needed";
      out.markers.push_back(row);
      continue;
    }
    const Status check = reduced.Check();
    if (!check.ok()) {
      row.skipped = "the solve without it is not possible: " + check.message();
      out.markers.push_back(row);
      continue;
    }
    auto r = SolveBundleAdjustment(reduced, options);
    if (!r.ok()) {
      row.skipped = "the solve without it failed: " + r.status().message();
      out.markers.push_back(row);
      continue;
    }
    TriangulationOptions to;
    to.min_ray_angle_deg = 0;
    auto t = TriangulatePoint(reduced, *r, obs, to);
    if (!t.ok()) {
      row.skipped = "triangulation failed: " + t.status().message();
      out.markers.push_back(row);
      continue;
    }
    row.p_triangulated = t->p_in_object;
    row.covariance = t->covariance;
    row.covariance_pixels = t->covariance_pixels;
    row.covariance_calibration = t->covariance_calibration;
    row.max_ray_angle_deg = t->max_ray_angle_deg;
    const Eigen::Vector3d e = row.p_triangulated - row.p_ct;
    row.error_mm = e.norm();
    const Eigen::Matrix3d C = row.covariance + row.ct_covariance;
    row.predicted_rms_mm = std::sqrt(C.trace());
    row.predicted_tre_mm = std::sqrt(row.covariance.trace());
    row.mahalanobis2 = e.dot(C.ldlt().solve(e));
    std::vector<Eigen::Vector3d> fid;
    for (const BaMarker& o : reduced.markers) fid.push_back(o.p_ct);
    const double tre_f2 = FitzpatrickTre2(fid, row.p_ct, fle_ct2 + fle_xray2);
    row.fitzpatrick_tre_mm = std::sqrt(tre_f2);
    row.fitzpatrick_rms_mm =
        std::sqrt(tre_f2 + row.covariance_pixels.trace() + row.ct_covariance.trace());
    sum_e2 += e.squaredNorm();
    sum_pred2 += C.trace();
    sum_fitz2 += row.fitzpatrick_rms_mm * row.fitzpatrick_rms_mm;
    sum_m2 += row.mahalanobis2;
    ++out.num_evaluated;
    out.markers.push_back(row);
  }
  if (out.num_evaluated > 0) {
    const double n = out.num_evaluated;
    out.rms_error_mm = std::sqrt(sum_e2 / n);
    out.rms_predicted_mm = std::sqrt(sum_pred2 / n);
    out.rms_fitzpatrick_mm = std::sqrt(sum_fitz2 / n);
    out.mean_mahalanobis2_per_dof = sum_m2 / n / 3.0;
  } else {
    out.rms_error_mm = out.rms_predicted_mm = out.rms_fitzpatrick_mm = nan;
    out.mean_mahalanobis2_per_dof = nan;
  }
  out.time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

}  // namespace ba
}  // namespace carmba
