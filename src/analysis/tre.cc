#include "analysis/tre.h"

#include <chrono>
#include <cmath>
#include <limits>
#include <map>

#include "analysis/triangulation.h"

namespace carmba {
namespace analysis {

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

namespace {

// The problem with the full solve's rejections removed and its solution as initial values.
ba::BaProblem AtTheSolution(const ba::BaProblem& problem, const ba::BaResult& full) {
  ba::BaProblem base = problem;
  for (size_t g = 0; g < base.groups.size(); ++g) {
    base.groups[g].initial = full.GroupIntrinsics(static_cast<int>(g));
  }
  for (size_t v = 0; v < base.views.size(); ++v) {
    ba::BaView& view = base.views[v];
    view.initial = full.ViewPose(static_cast<int>(v));
    if (v < full.dropped.size() && !full.dropped[v].empty()) {
      std::vector<char> keep(view.point_ids.size());
      for (size_t i = 0; i < keep.size(); ++i) keep[i] = !full.dropped[v][i];
      view = ba::KeepObservations(view, keep);
    }
  }
  return base;
}

// Marker m's pixels in the object views, with their covariances.
std::vector<PixelObservation> MarkerPixels(const ba::BaProblem& base, size_t m) {
  std::vector<PixelObservation> obs;
  for (size_t v = 0; v < base.views.size(); ++v) {
    const ba::BaView& view = base.views[v];
    if (view.kind != ba::ViewKind::kObject) continue;
    for (size_t i = 0; i < view.point_ids.size(); ++i) {
      if (view.point_ids[i] != base.markers[m].id) continue;
      PixelObservation o;
      o.view = static_cast<int>(v);
      o.uv_px = view.uv_px[i];
      o.covariance_px2 = view.CovariancePx2(i);
      obs.push_back(o);
    }
  }
  return obs;
}

// The fiducial localisation errors: the CT's (mean trace of the markers' covariances) and the
// X-ray's (mean trace of each marker's pixel-only triangulation with the full solve), squared.
void FiducialLocalisationErrors(const ba::BaProblem& base,
                                const ba::BaResult& full,
                                const std::vector<std::vector<PixelObservation>>& obs_of,
                                double* fle_ct2,
                                double* fle_xray2) {
  *fle_ct2 = 0, *fle_xray2 = 0;
  int n_xray = 0;
  for (size_t m = 0; m < base.markers.size(); ++m) {
    *fle_ct2 += base.markers[m].covariance.trace();
    if (obs_of[m].size() < 2) continue;
    TriangulationOptions to;
    to.min_ray_angle_deg = 0;
    auto t = TriangulatePoint(base, full, obs_of[m], to);
    if (t.ok()) {
      *fle_xray2 += t->covariance_pixels.trace();
      ++n_xray;
    }
  }
  *fle_ct2 /= std::max<size_t>(1, base.markers.size());
  *fle_xray2 = n_xray ? *fle_xray2 / n_xray : std::numeric_limits<double>::quiet_NaN();
}

// The problem without marker m: the marker gone, object views left with fewer than 4 other
// markers left out (counted in row->num_views_left_out); `obs` mapped to the reduced views.
ba::BaProblem WithoutMarker(const ba::BaProblem& base,
                            size_t m,
                            std::vector<PixelObservation>* obs,
                            MarkerTre* row) {
  const int id = base.markers[m].id;
  ba::BaProblem reduced = base;
  reduced.markers.erase(reduced.markers.begin() + static_cast<long>(m));
  reduced.views.clear();
  std::map<int, int> reduced_index;  // base view index -> reduced
  for (size_t v = 0; v < base.views.size(); ++v) {
    ba::BaView view = base.views[v];
    if (view.kind == ba::ViewKind::kObject) {
      std::vector<char> keep(view.point_ids.size());
      for (size_t i = 0; i < keep.size(); ++i) keep[i] = view.point_ids[i] != id;
      const ba::BaView kept = ba::KeepObservations(view, keep);
      if (kept.point_ids.size() < 4) {
        ++row->num_views_left_out;
        continue;
      }
      view = kept;
    }
    reduced_index[static_cast<int>(v)] = static_cast<int>(reduced.views.size());
    reduced.views.push_back(view);
  }
  std::vector<PixelObservation> mapped;
  for (PixelObservation o : *obs) {
    auto it = reduced_index.find(o.view);
    if (it == reduced_index.end()) continue;
    o.view = it->second;
    mapped.push_back(o);
  }
  *obs = std::move(mapped);
  return reduced;
}

// The sums over the markers evaluated, for the RMS figures.
struct TreSums {
  double e2 = 0, predicted2 = 0, fitzpatrick2 = 0, mahalanobis2 = 0;
  int n = 0;
};

// Marker m left out: the solve without it, its triangulation from that solve against its CT
// position, the predicted errors and Fitzpatrick's, added to `sums`. row.skipped says why when it
// cannot be.
MarkerTre LeaveOut(const ba::BaProblem& base, size_t m, std::vector<PixelObservation> obs,
                   const ba::BaOptions& options, double fle2, TreSums* sums) {
  MarkerTre row;
  const ba::BaMarker& marker = base.markers[m];
  row.marker_id = marker.id;
  row.p_ct = marker.p_ct;
  row.ct_covariance = marker.covariance;
  const ba::BaProblem reduced = WithoutMarker(base, m, &obs, &row);
  row.num_views = static_cast<int>(obs.size());
  if (obs.size() < 2) {
    row.skipped = "seen in " + std::to_string(obs.size()) + " view(s) of the solve without it" +
                  (row.num_views_left_out ? " (" + std::to_string(row.num_views_left_out) +
                                                " view(s) left out: fewer than 4 other markers)"
                                          : std::string()) +
                  ": at least two are needed";
    return row;
  }
  const Status check = reduced.Check();
  if (!check.ok()) {
    row.skipped = "the solve without it is not possible: " + check.message();
    return row;
  }
  auto r = ba::SolveBundleAdjustment(reduced, options);
  if (!r.ok()) {
    row.skipped = "the solve without it failed: " + r.status().message();
    return row;
  }
  TriangulationOptions to;
  to.min_ray_angle_deg = 0;
  auto t = TriangulatePoint(reduced, *r, obs, to);
  if (!t.ok()) {
    row.skipped = "triangulation failed: " + t.status().message();
    return row;
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
  for (const ba::BaMarker& o : reduced.markers) fid.push_back(o.p_ct);
  const double tre_f2 = FitzpatrickTre2(fid, row.p_ct, fle2);
  row.fitzpatrick_tre_mm = std::sqrt(tre_f2);
  row.fitzpatrick_rms_mm =
      std::sqrt(tre_f2 + row.covariance_pixels.trace() + row.ct_covariance.trace());
  sums->e2 += e.squaredNorm();
  sums->predicted2 += C.trace();
  sums->fitzpatrick2 += row.fitzpatrick_rms_mm * row.fitzpatrick_rms_mm;
  sums->mahalanobis2 += row.mahalanobis2;
  ++sums->n;
  return row;
}

// The RMS figures over the markers evaluated (NaN without any).
void TreSummary(const TreSums& sums, TreResult* out) {
  out->num_evaluated = sums.n;
  if (sums.n > 0) {
    const double n = sums.n;
    out->rms_error_mm = std::sqrt(sums.e2 / n);
    out->rms_predicted_mm = std::sqrt(sums.predicted2 / n);
    out->rms_fitzpatrick_mm = std::sqrt(sums.fitzpatrick2 / n);
    out->mean_mahalanobis2_per_dof = sums.mahalanobis2 / n / 3.0;
  } else {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    out->rms_error_mm = out->rms_predicted_mm = out->rms_fitzpatrick_mm = nan;
    out->mean_mahalanobis2_per_dof = nan;
  }
}

}  // namespace

StatusOr<TreResult> LeaveOneMarkerOut(const ba::BaProblem& problem,
                                      const ba::BaResult& full,
                                      const ba::BaOptions& options_in) {
  const auto t0 = std::chrono::steady_clock::now();
  if (!full.covariance) return Status::Error("leave-one-marker-out: the solve has no covariance");
  if (!problem.rigs.empty())
    return Status::Error("leave-one-marker-out: a problem with rigs is not supported");
  for (const ba::IntrinsicsGroup& g : problem.groups) {
    if (g.smooth) {
      return Status::Error(
          "leave-one-marker-out: group '" + g.name +
          "' has angle-dependent (smooth) intrinsics, which the TRE does not support");
    }
  }
  ba::BaOptions options = options_in;
  options.reject_sigma = 0;
  options.compute_covariance = true;
  const ba::BaProblem base = AtTheSolution(problem, full);
  std::vector<std::vector<PixelObservation>> obs_of;
  for (size_t m = 0; m < base.markers.size(); ++m) obs_of.push_back(MarkerPixels(base, m));
  TreResult out;
  double fle_ct2 = 0, fle_xray2 = 0;
  FiducialLocalisationErrors(base, full, obs_of, &fle_ct2, &fle_xray2);
  out.fle_ct_mm = std::sqrt(fle_ct2);
  out.fle_xray_mm = std::sqrt(fle_xray2);
  out.fle_mm = std::sqrt(fle_ct2 + fle_xray2);
  TreSums sums;
  for (size_t m = 0; m < base.markers.size(); ++m) {
    out.markers.push_back(LeaveOut(base, m, obs_of[m], options, fle_ct2 + fle_xray2, &sums));
  }
  TreSummary(sums, &out);
  out.time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

}  // namespace analysis
}  // namespace carmba
