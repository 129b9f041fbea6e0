#include "ct/marker_detection.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <map>
#include <mutex>
#include <numeric>
#include <unordered_map>

#include "ct/ct_phantom.h"
#include "util/format.h"
#include "util/plausible.h"

namespace carmba {

bool MarkerDetectionOptions::Check(std::string* error) const {
  if (!CheckRange("threshold_hu", threshold_hu, plausible::kHounsfield, error) ||
      !CheckRange("diameter_mm", diameter_mm, plausible::kMarkerDiameterMm, error) ||
      !CheckRange("expected (marker count, 0: any)", expected_count, plausible::kMarkerCount,
                  error)) {
    return false;
  }
  if (!(min_volume_fraction >= 0) || !(max_volume_fraction > min_volume_fraction)) {
    *error = "volume fractions must satisfy 0 <= min < max";
    return false;
  }
  if (!(roi_margin_mm >= 0) || !(shell_mm > 0) || iterations < 1 || iterations > 20) {
    *error = "roi margin must be >= 0 mm, shell > 0 mm, iterations 1 .. 20";
    return false;
  }
  if (!(max_core_fraction > 0 && max_core_fraction <= 1)) {
    *error = "max_core_fraction must be in (0, 1]";
    return false;
  }
  if (!std::isfinite(min_metal_hu)) {
    *error = "min_metal_hu must be a finite HU value";
    return false;
  }
  if (!(min_inner_fraction >= 0 && min_inner_fraction <= 1)) {
    *error = "min_inner_fraction must be in [0, 1]";
    return false;
  }
  if (!(contamination_chi2 > 0)) {
    *error = "contamination_chi2 must be > 0";
    return false;
  }
  if (!std::isfinite(clip_hu)) {
    *error = "clip_hu must be finite (0: read from the data, < 0: none)";
    return false;
  }
  if (max_seeds_per_component < 1) {
    *error = "max_seeds_per_component must be >= 1";
    return false;
  }
  return true;
}

bool SlicesHaveGaps(const CtVolume& volume) {
  return volume.slice_thickness_mm > 0 && volume.spacing_mm.z() > 1.01 * volume.slice_thickness_mm;
}

double SamplingVarianceMm2(double radius_mm, double spacing_mm, double extent_mm) {
  const double R = radius_mm, h = spacing_mm, e = extent_mm;
  // Integral of the projected area pi (R^2 - x^2) from -R to x (x clipped to [-R, R]).
  auto I = [R](double x) {
    x = std::clamp(x, -R, R);
    return M_PI * (R * R * x - x * x * x / 3.0);
  };
  constexpr int kPhases = 64;
  const int n_max = static_cast<int>(std::ceil((R + e) / h)) + 2;
  double sum_sq = 0;
  for (int p = 0; p < kPhases; ++p) {
    const double s = (p + 0.5) / kPhases * h;
    double m0 = 0, m1 = 0;
    for (int n = -n_max; n <= n_max; ++n) {
      const double x = n * h + s;
      const double g = I(x + 0.5 * e) - I(x - 0.5 * e);
      m0 += g;
      m1 += g * x;
    }
    const double err = m0 > 0 ? m1 / m0 : 0;
    sum_sq += err * err;
  }
  return sum_sq / kPhases;
}

namespace {

struct UnionFind {
  std::vector<int> parent;
  explicit UnionFind(int n) : parent(n) { std::iota(parent.begin(), parent.end(), 0); }
  int Find(int a) {
    while (parent[a] != a) a = parent[a] = parent[parent[a]];
    return a;
  }
  void Union(int a, int b) {
    a = Find(a);
    b = Find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  }
};

std::string Mm2(const Eigen::Vector3d& v) { return FmtTriple("%.2f", v.x(), v.y(), v.z()); }

double Median(std::vector<double>* v) {
  const size_t m = v->size() / 2;
  std::nth_element(v->begin(), v->begin() + m, v->end());
  return (*v)[m];
}


// A voxel of a fit: offset of its centre from the reference point (patient-frame mm), HU.
struct FitVoxel {
  Eigen::Vector3d d;
  double v;
};

// Fraction of the voxel centred at d (patient-frame mm offsets) inside the ball of radius R
// centred at c: the voxel is the parallelepiped sum_a t_a e_a axes.col(a), |t_a| <= 1/2. Value:
// for voxels cut by the surface, a sub-grid of lines along axes.col(2) (at least S per axis,
// at most ~0.05 mm apart), each line's chord through the ball exact. Its
// gradient with respect to c, from the tangent-plane approximation: the voxel's projection on
// the surface normal n is the sum of three uniforms of widths w_a = |n . axes.col(a)| e_a, whose
// CDF at t = -s + (w_1 + w_2 + w_3) / 2, s = |d - c| - R, is
//   F(t) = sum_{S in subsets of {1,2,3}} (-1)^|S| (t - sum_{a in S} w_a)_+^3 / (6 w_1 w_2 w_3),
// so df/dc = F'(t) n with F'(t) = sum (-1)^|S| (t - sum_S w)_+^2 / (2 w_1 w_2 w_3).
double BallFraction(const Eigen::Vector3d& d,
                    const Eigen::Vector3d& c,
                    const Eigen::Matrix3d& axes,
                    const Eigen::Vector3d& e,
                    double R,
                    int S,
                    Eigen::Vector3d* df_dc) {
  const Eigen::Vector3d q = d - c;
  const double dist = q.norm();
  const Eigen::Vector3d n = dist > 1e-9 ? Eigen::Vector3d(q / dist) : Eigen::Vector3d::UnitX();
  Eigen::Vector3d w = (axes.transpose() * n).cwiseAbs().cwiseProduct(e);
  w = w.cwiseMax(1e-3 * e.maxCoeff());
  const double t = -(dist - R) + 0.5 * w.sum();
  double dF = 0;
  for (int subset = 0; subset < 8; ++subset) {
    double shift = 0;
    int sign = 1;
    for (int a = 0; a < 3; ++a) {
      if (subset & (1 << a)) {
        shift += w[a];
        sign = -sign;
      }
    }
    const double x = std::max(0.0, t - shift);
    dF += sign * x * x;
  }
  dF /= 2 * w.prod();
  *df_dc = dF * n;
  const double half_diag = 0.5 * (axes * e.asDiagonal()).colwise().norm().norm();
  if (dist <= R - half_diag) return 1.0;
  if (dist >= R + half_diag) return 0.0;
  // In-plane sub-samples at most ~0.05 mm apart; along the third axis the chord of the ball
  // through each sub-sample's line is exact.
  const Eigen::Vector3d X = e.x() * axes.col(0), Y = e.y() * axes.col(1), u = axes.col(2);
  const int sx = std::max(S, static_cast<int>(std::ceil(e.x() / 0.05)));
  const int sy = std::max(S, static_cast<int>(std::ceil(e.y() / 0.05)));
  double inside = 0;
  for (int a = 0; a < sx; ++a) {
    const Eigen::Vector3d pa = q + ((a + 0.5) / sx - 0.5) * X;
    for (int b = 0; b < sy; ++b) {
      const Eigen::Vector3d p = pa + ((b + 0.5) / sy - 0.5) * Y;
      // |p + t u|^2 <= R^2 for t in [-beta - root, -beta + root].
      const double beta = p.dot(u), gamma = p.squaredNorm() - R * R;
      const double disc = beta * beta - gamma;
      if (disc <= 0) continue;
      const double root = std::sqrt(disc);
      const double lo = std::max(-beta - root, -0.5 * e.z()),
                   hi = std::min(-beta + root, 0.5 * e.z());
      if (hi > lo) inside += (hi - lo) / e.z();
    }
  }
  return inside / (sx * sy);
}

struct BallFitResult {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  // mm, same frame as FitVoxel::d
  double metal_hu = 0, background_hu = 0;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // of centre, mm^2
  double scale_hu = 0;         // robust residual scale
  double metal_sigma_hu = 0;   // standard deviation of the fitted metal HU
  double cost = 0;             // sum of the robust loss
  double outlier_mass = 0;     // sum of |residual| (1 - w) over the voxels, HU
  double inner_fraction = 0;   // of the voxels with f >= 0.75 f_max, those within 25 % of f (M - b)
};

// Robust (Cauchy, scale 3 x the MAD-based sigma of the residuals where the ball has f > 0.05)
// Gauss-Newton fit of
// v = b + (M - b) f(d; c) with the radius fixed.
bool FitBall(const std::vector<FitVoxel>& vox,
             const Eigen::Matrix3d& axes,
             const Eigen::Vector3d& e,
             double R,
             Eigen::Vector3d c,
             double M,
             double b,
             BallFitResult* out) {
  constexpr int kSupersampling = 8;
  constexpr int kIterations = 50;
  const int n = static_cast<int>(vox.size());
  if (n < 10) return false;
  std::vector<double> f(n), res(n), w(n);
  std::vector<Eigen::Vector3d> g(n);
  double scale = 0;
  Eigen::Matrix<double, 5, 5> H;
  auto evaluate = [&]() {
    for (int i = 0; i < n; ++i) {
      f[i] = BallFraction(vox[i].d, c, axes, e, R, kSupersampling, &g[i]);
      res[i] = vox[i].v - (b + (M - b) * f[i]);
    }
    // The scale from the voxels the ball touches (their residuals are noise for a marker,
    // whatever mix of materials surrounds it), or from all when fewer than 10.
    std::vector<double> a;
    for (int i = 0; i < n; ++i) {
      if (f[i] > 0.05) a.push_back(std::abs(res[i]));
    }
    if (a.size() < 10) {
      a.clear();
      for (int i = 0; i < n; ++i) a.push_back(std::abs(res[i]));
    }
    const size_t half = a.size() / 2;
    std::nth_element(a.begin(), a.begin() + half, a.end());
    scale = std::max(1.4826 * a[half], 1.0);
  };
  for (int it = 0; it < kIterations; ++it) {
    evaluate();
    const double k = 3 * scale;
    H.setZero();
    Eigen::Matrix<double, 5, 1> rhs = Eigen::Matrix<double, 5, 1>::Zero();
    for (int i = 0; i < n; ++i) {
      const double u = res[i] / k;
      w[i] = 1.0 / (1.0 + u * u);
      Eigen::Matrix<double, 5, 1> J;
      J.head<3>() = (M - b) * g[i];
      J(3) = f[i];
      J(4) = 1 - f[i];
      H += w[i] * J * J.transpose();
      rhs += w[i] * res[i] * J;
    }
    Eigen::Matrix<double, 5, 1> step = H.ldlt().solve(rhs);
    if (!step.allFinite()) return false;
    const double len = step.head<3>().norm();
    constexpr double kMaxStepMm = 0.5;
    if (len > kMaxStepMm) step *= kMaxStepMm / len;
    c += step.head<3>();
    // A local fit: the centre stays within R of where it started (a marker's seed is within
    // its radius of its centre); beyond lies a neighbour's optimum (bone, air), not this one.
    if (c.norm() > R) c *= R / c.norm();
    M += step(3);
    b += step(4);
    if (step.head<3>().norm() < 1e-5 && it > 3) break;
  }
  evaluate();
  const double k = 3 * scale;
  double cost = 0, sw = 0, swr2 = 0, outlier = 0;
  H.setZero();
  Eigen::Matrix<double, 5, 5> B = Eigen::Matrix<double, 5, 5>::Zero();
  for (int i = 0; i < n; ++i) {
    const double u = res[i] / k;
    w[i] = 1.0 / (1.0 + u * u);
    cost += std::log1p(u * u);
    sw += w[i];
    swr2 += w[i] * res[i] * res[i];
    outlier += (1 - w[i]) * std::abs(res[i]);
    Eigen::Matrix<double, 5, 1> J;
    J.head<3>() = (M - b) * g[i];
    J(3) = f[i];
    J(4) = 1 - f[i];
    H += w[i] * J * J.transpose();
    B += (w[i] * res[i]) * (w[i] * res[i]) * J * J.transpose();
  }
  if (!(sw > 6) || !(M > b)) return false;
  // Covariance: the larger (in the centre block's trace) of the model-based s^2 H^-1 and the
  // sandwich H^-1 B H^-1 (Huber-White), which holds when the residuals are not identically
  // distributed: bone or air mixed into the marker's voxels leaves large residuals exactly
  // where the centre is decided.
  // The scale: the robust residual variance, or the plain mean square of the residuals of the
  // voxels the ball's surface cuts (0 < f < 1: the ones that decide the centre) when larger --
  // bone or air mixed into them biases the centre by about what their residuals show.
  double edge_ss = 0;
  int edge_n = 0;
  for (int i = 0; i < n; ++i) {
    if (f[i] <= 0 || f[i] >= 1) continue;
    edge_ss += res[i] * res[i];
    ++edge_n;
  }
  const double s2 = std::max(swr2 / (sw - 5), edge_n > 5 ? edge_ss / (edge_n - 5) : 0.0);
  const Eigen::Matrix<double, 5, 5> H_inv = H.inverse();
  Eigen::Matrix<double, 5, 5> cov = s2 * H_inv;
  const Eigen::Matrix<double, 5, 5> sandwich = n / (n - 5.0) * H_inv * B * H_inv;
  if (sandwich.topLeftCorner<3, 3>().trace() > cov.topLeftCorner<3, 3>().trace()) cov = sandwich;
  if (!cov.allFinite()) return false;
  out->centre = c;
  out->metal_hu = M;
  out->background_hu = b;
  out->covariance = cov.topLeftCorner<3, 3>();
  out->metal_sigma_hu = std::sqrt(std::max(0.0, cov(3, 3)));
  out->scale_hu = scale;
  out->cost = cost;
  out->outlier_mass = outlier;
  int inner = 0, inner_ok = 0;
  const double f_max = *std::max_element(f.begin(), f.end());
  for (int i = 0; i < n; ++i) {
    if (f[i] < 0.75 * f_max) continue;
    ++inner;
    inner_ok += std::abs(res[i]) <= 0.25 * (M - b) * f[i];
  }
  out->inner_fraction = inner ? static_cast<double>(inner_ok) / inner : 0.0;
  return true;
}

// The least, over sub-voxel positions (a 6 x 6 x 6 grid of phases), of the largest voxel
// fraction a ball of radius R reaches: a marker's peak is at least b + this x (M - b).
double MinPeakFraction(const CtVolume& vol, double R) {
  const Eigen::Matrix3d A = vol.PatientFromIndexLinear();
  const double thickness = vol.slice_thickness_mm > 0 ? vol.slice_thickness_mm : vol.spacing_mm.z();
  const Eigen::Vector3d e(vol.spacing_mm.x(), vol.spacing_mm.y(), thickness);
  constexpr int kPhases = 6;
  double least = 1;
  Eigen::Vector3d unused;
  for (int a = 0; a < kPhases; ++a) {
    for (int b = 0; b < kPhases; ++b) {
      for (int c = 0; c < kPhases; ++c) {
        const Eigen::Vector3d centre = A * (Eigen::Vector3d(a, b, c) / kPhases);
        double most = 0;
        for (int k = -1; k <= 2; ++k) {
          for (int j = -1; j <= 2; ++j) {
            for (int i = -1; i <= 2; ++i) {
              most = std::max(most, BallFraction(A * Eigen::Vector3d(i, j, k), centre, vol.axes,
                                                 e, R, 4, &unused));
            }
          }
        }
        least = std::min(least, most);
      }
    }
  }
  return least;
}

// The voxels around a centre: the region of interest (within r_roi of c, by the voxel's nearest
// point) and the shell beyond a gap, with their offsets from c (mm) and HU.
struct CentroidRegion {
  std::vector<std::pair<Eigen::Vector3d, double>> roi;
  std::vector<double> shell;
  std::vector<Eigen::Vector3d> shell_offsets;  // parallel to `shell`
};

constexpr double kShellGapMm = 0.5;

void GatherCentroidRegion(const CtVolume& vol, const Eigen::Vector3d& c, const Eigen::Vector3d& e,
                          double r_roi, double r_outer, CentroidRegion* region) {
  const Eigen::Vector3d h = vol.spacing_mm;
  int lo[3], hi[3];
  const int dims[3] = {vol.columns, vol.rows, vol.slices};
  for (int a = 0; a < 3; ++a) {
    const double reach = (r_outer + 0.5 * e[a]) / h[a];
    lo[a] = std::max(0, static_cast<int>(std::floor(c[a] - reach)));
    hi[a] = std::min(dims[a] - 1, static_cast<int>(std::ceil(c[a] + reach)));
  }
  region->shell.clear();
  region->shell_offsets.clear();
  region->roi.clear();
  for (int k = lo[2]; k <= hi[2]; ++k) {
    for (int j = lo[1]; j <= hi[1]; ++j) {
      for (int i = lo[0]; i <= hi[0]; ++i) {
        const Eigen::Vector3d d((i - c.x()) * h.x(), (j - c.y()) * h.y(), (k - c.z()) * h.z());
        const Eigen::Vector3d gap = (d.cwiseAbs() - 0.5 * e).cwiseMax(0.0);
        const double dist = gap.norm();
        const double v = vol.At(i, j, k);
        if (dist <= r_roi) {
          region->roi.emplace_back(d, v);
        } else if (dist > r_roi + kShellGapMm && dist <= r_outer) {
          region->shell.push_back(v);
          region->shell_offsets.push_back(d);
        }
      }
    }
  }
}

// Structured background (metal streaks, a neighbour's artefacts, a bone edge) biases the
// centroid where white noise of the MAD-based sigma would not: only the part of the background
// that is odd under reflection through the centre moves the first moment. Its RMS, from each
// voxel of the region's rim and the shell (outside the marker's blur, beyond r_in) against the
// trilinear value at its reflection through the new centre c + shift, (v - v') / sqrt(2); 0 with
// fewer than 8 such voxels (white noise gives sigma, a bit less for the interpolated v').
double OddBackgroundRms(const CtVolume& vol, const CentroidRegion& region, const Eigen::Vector3d& c,
                        const Eigen::Vector3d& shift_mm, double r_in) {
  const Eigen::Vector3d h = vol.spacing_mm;
  double ss = 0;
  int ns = 0;
  const Eigen::Vector3d c_new = c + shift_mm.cwiseQuotient(h);
  auto odd = [&](const Eigen::Vector3d& d, double v) {
    if ((d - shift_mm).norm() <= r_in) return;
    const Eigen::Vector3d idx = c + d.cwiseQuotient(h);
    const Eigen::Vector3d refl = 2 * c_new - idx;
    const int i0 = static_cast<int>(std::floor(refl.x()));
    const int j0 = static_cast<int>(std::floor(refl.y()));
    const int k0 = static_cast<int>(std::floor(refl.z()));
    if (i0 < 0 || j0 < 0 || k0 < 0 || i0 + 1 >= vol.columns || j0 + 1 >= vol.rows ||
        k0 + 1 >= vol.slices) {
      return;
    }
    const double fx = refl.x() - i0, fy = refl.y() - j0, fz = refl.z() - k0;
    double r = 0;
    for (int dk = 0; dk < 2; ++dk) {
      for (int dj = 0; dj < 2; ++dj) {
        for (int di = 0; di < 2; ++di) {
          r += (di ? fx : 1 - fx) * (dj ? fy : 1 - fy) * (dk ? fz : 1 - fz) *
               vol.At(i0 + di, j0 + dj, k0 + dk);
        }
      }
    }
    const double dv = v - r;
    ss += 0.5 * dv * dv;
    ++ns;
  };
  for (const auto& [d, v] : region.roi) odd(d, v);
  for (size_t q = 0; q < region.shell.size(); ++q) odd(region.shell_offsets[q], region.shell[q]);
  return ns >= 8 ? std::sqrt(ss / ns) : 0.0;
}

// The weighted centroid's state: the shell's background and noise, the weight, the
// white-noise covariance (for the contamination test), whether it succeeded.
struct WeightedCentroid {
  bool ok = true;
  double background = 0, sigma = 0, weight = 0;
  Eigen::Matrix3d white_covariance = Eigen::Matrix3d::Zero();
  int roi_voxels = 0;
};

// The last iteration's covariance in the axis frame (offsets relative to the final centre): the
// noise's part at the white sigma (centroid_white_cov) and at the larger of it and the odd
// background's RMS (the marker's covariance_noise_mm2 and covariance_mm2).
void CentroidCovarianceMm2(const CtVolume& vol,
                           const CentroidRegion& region,
                           const Eigen::Vector3d& c,
                           const Eigen::Vector3d& shift_mm,
                           double r_in,
                           WeightedCentroid* wc,
                           DetectedMarker* m) {
  const double W = wc->weight;
  Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
  Eigen::Vector3d g = Eigen::Vector3d::Zero();
  for (const auto& [d, v] : region.roi) {
    const Eigen::Vector3d r = d - shift_mm;
    S += r * r.transpose();
    g += r;
  }
  g /= W;
  m->odd_background_hu = OddBackgroundRms(vol, region, c, shift_mm, r_in);
  auto noise_of = [&](double s) -> Eigen::Matrix3d {
    const Eigen::Matrix3d n =
        s * s * S / (W * W) + s * s / static_cast<double>(region.shell.size()) * g * g.transpose();
    return vol.axes * n * vol.axes.transpose();
  };
  // The contamination test (7.) compares the centroid with the fit at the white-noise
  // covariance (a bone edge next to the marker should switch to the fit, not widen the
  // centroid); the centroid's reported covariance takes the odd part.
  wc->white_covariance = noise_of(wc->sigma) + m->covariance_sampling_mm2;
  wc->sigma = std::max(wc->sigma, m->odd_background_hu);
  m->covariance_noise_mm2 = noise_of(wc->sigma);
  m->covariance_mm2 = m->covariance_noise_mm2 + m->covariance_sampling_mm2;
}

// 4-5. The background-subtracted weighted centroid, iterated from *c: the region of interest
// (radius plus a margin, the first pass half a voxel wider) against the shell's median; its
// covariance at the last iteration.
WeightedCentroid IterateWeightedCentroid(const CtVolume& vol,
                                         const MarkerDetectionOptions& opt,
                                         double radius,
                                         const Eigen::Vector3d& e,
                                         Eigen::Vector3d* c,
                                         DetectedMarker* m) {
  const Eigen::Vector3d h = vol.spacing_mm;
  WeightedCentroid wc;
  CentroidRegion region;
  for (int it = 0; it <= opt.iterations; ++it) {
    const double margin = opt.roi_margin_mm + (it == 0 ? 0.5 * e.maxCoeff() : 0.0);
    const double r_roi = radius + margin;
    const double r_outer = r_roi + kShellGapMm + opt.shell_mm;
    GatherCentroidRegion(vol, *c, e, r_roi, r_outer, &region);
    wc.roi_voxels = static_cast<int>(region.roi.size());
    if (region.shell.size() < 8 || region.roi.empty()) {
      wc.ok = false;
      break;
    }
    // KNOWN ISSUE: Median reorders region.shell in place, so at the last iteration
    // OddBackgroundRms pairs the shell's values with other voxels' offsets, not their own, and
    // measures more than the odd part: roughly the shell's whole structured spread. Taking the
    // median of a copy (the pairing the comments describe) makes the metal-streak covariances
    // too small: SkullBeads.MetalStreaksKeepEveryBeadFoundAndTheCovarianceHonest's mean NEES goes
    // from <= 3.6 to 9.06 (worst 9.5 sigma). Kept until a principled structured-background term
    // replaces both.
    wc.background = Median(&region.shell);
    std::vector<double> dev(region.shell.size());
    for (size_t s = 0; s < region.shell.size(); ++s)
      dev[s] = std::abs(region.shell[s] - wc.background);
    wc.sigma = 1.4826 * Median(&dev);
    wc.weight = 0;
    Eigen::Vector3d moment = Eigen::Vector3d::Zero();
    for (const auto& [d, v] : region.roi) {
      wc.weight += v - wc.background;
      moment += (v - wc.background) * d;
    }
    if (!(wc.weight > 0)) {
      wc.ok = false;
      break;
    }
    const Eigen::Vector3d shift_mm = moment / wc.weight;
    *c += shift_mm.cwiseQuotient(h);
    if (it == opt.iterations) {
      CentroidCovarianceMm2(vol, region, *c, shift_mm, radius + e.maxCoeff(), &wc, m);
    }
  }
  return wc;
}

// The robust partial-volume ball fit over the voxels within R + e_max of `start`, re-fitted once
// over the region around its first result; false when it fails or ends farther from the peak
// voxel than a ball's peak can be (half a voxel diagonal: it found a neighbour, bone or air).
bool FitBallFrom(const CtVolume& vol,
                 const MarkerDetectionOptions& opt,
                 const Eigen::Vector3d& e,
                 const DetectedMarker& m,
                 double background,
                 Eigen::Vector3d start,
                 BallFitResult* fit,
                 int* n_vox) {
  const Eigen::Vector3d h = vol.spacing_mm;
  const double r_fit = 0.5 * opt.diameter_mm + e.maxCoeff();
  const Eigen::Matrix3d A = vol.PatientFromIndexLinear(), A_inv = A.inverse();
  const int dims[3] = {vol.columns, vol.rows, vol.slices};
  for (int pass = 0; pass < 2; ++pass) {
    std::vector<FitVoxel> vox;
    int lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      const double reach = r_fit / h[a];
      lo[a] = std::max(0, static_cast<int>(std::floor(start[a] - reach)));
      hi[a] = std::min(dims[a] - 1, static_cast<int>(std::ceil(start[a] + reach)));
    }
    for (int k = lo[2]; k <= hi[2]; ++k) {
      for (int j = lo[1]; j <= hi[1]; ++j) {
        for (int i = lo[0]; i <= hi[0]; ++i) {
          const Eigen::Vector3d d = A * (Eigen::Vector3d(i, j, k) - start);
          if (d.norm() <= r_fit) vox.push_back({d, vol.At(i, j, k)});
        }
      }
    }
    if (!FitBall(vox,
                 vol.axes,
                 e,
                 0.5 * opt.diameter_mm,
                 Eigen::Vector3d::Zero(),
                 m.peak_hu,
                 background,
                 fit)) {
      return false;
    }
    *n_vox = static_cast<int>(vox.size());
    start += A_inv * fit->centre;
    fit->centre = start;  // now in continuous voxel indices
  }
  return (A * (start - m.peak_index)).norm() <= 0.5 * opt.diameter_mm + 0.5 * e.norm();
}

// 7. With a ball fit: the centroid and the fit disagree beyond their covariances (bone or air in
// the region of interest or its shell pulls the centroid) -- or there is no centroid (the
// surroundings outweigh the marker) -- and the fit is the centre; else the centroid, its
// covariance widened by the Birge ratio of the disagreement when it exceeds its expectation (3)
// (the odd part's widening (5.) may already cover it: the larger of the two).
void ChooseCentroidOrFit(const CtVolume& vol,
                         const MarkerDetectionOptions& opt,
                         const BallFitResult& fit,
                         int n_fit,
                         bool centroid_ok,
                         const Eigen::Matrix3d& centroid_white_cov,
                         DetectedMarker* m) {
  const Eigen::Vector3d cf = fit.centre;
  m->fit_centre_mm = vol.PatientFromIndex(cf);
  m->fit_covariance_mm2 = fit.covariance;  // patient frame already
  m->fit_metal_hu = fit.metal_hu;
  m->fit_metal_sigma_hu = fit.metal_sigma_hu;
  m->fit_background_hu = fit.background_hu;
  m->fit_scale_hu = fit.scale_hu;
  m->fit_outlier_mass = fit.outlier_mass;
  m->fit_voxels = n_fit;
  m->fit_inner_fraction = fit.inner_fraction;
  const Eigen::Vector3d delta = m->centre_mm - m->fit_centre_mm;
  const Eigen::Matrix3d C = centroid_white_cov + m->fit_covariance_mm2;
  m->contamination_chi2 = centroid_ok ? delta.dot(C.ldlt().solve(delta)) : -1;
  if (!centroid_ok || m->contamination_chi2 > opt.contamination_chi2) {
    m->contaminated = true;
    m->centroid_mm = m->centre_mm;
    m->centre_mm = m->fit_centre_mm;
    m->centre_index = cf;
    m->covariance_noise_mm2 = m->fit_covariance_mm2;
    m->covariance_mm2 = m->covariance_noise_mm2 + m->covariance_sampling_mm2;
  } else {
    m->centroid_mm = m->centre_mm;
    const Eigen::Matrix3d birge = centroid_white_cov * std::max(1.0, m->contamination_chi2 / 3.0);
    if (birge.trace() > m->covariance_mm2.trace()) m->covariance_mm2 = birge;
  }
}

// Refines one marker's centre (steps 4-5 of the header), then the ball fit (6-7) started from the
// peak voxel, the seed and the centroid; a metal ball's fit is kept before one that is not, and
// among them the one with the lower mean robust cost.
// Returns false if there is no contrast.
bool Refine(const CtVolume& vol,
            const MarkerDetectionOptions& opt,
            double core_radius_mm,
            double min_peak_fraction,
            DetectedMarker* m) {
  const Eigen::Vector3d h = vol.spacing_mm;
  const double thickness = vol.slice_thickness_mm > 0 ? vol.slice_thickness_mm : h.z();
  const Eigen::Vector3d e(h.x(), h.y(), thickness);  // voxel extent along the axes
  const double radius = std::max(0.5 * opt.diameter_mm, core_radius_mm);
  Eigen::Vector3d c = m->centre_index;
  const Eigen::Vector3d seed_index = c;
  Eigen::Matrix3d sampling = Eigen::Matrix3d::Zero();
  for (int a = 0; a < 3; ++a) {
    sampling(a, a) = SamplingVarianceMm2(0.5 * opt.diameter_mm, h[a], e[a]);
  }
  m->covariance_sampling_mm2 = vol.axes * sampling * vol.axes.transpose();
  const WeightedCentroid wc = IterateWeightedCentroid(vol, opt, radius, e, &c, m);
  m->centre_index = c;
  m->centre_mm = vol.PatientFromIndex(c);
  BallFitResult fit, other;
  int n_fit = 0, n_other = 0;
  // "Peak HU consistent with metal": below what the ball of min_metal_hu gives at its least
  // favourable sub-voxel position, no fit is tried.
  m->peak_needed_hu = wc.background + min_peak_fraction * (opt.min_metal_hu - wc.background);
  const bool peak_ok = m->peak_hu >= m->peak_needed_hu;
  m->fit_ok = peak_ok && FitBallFrom(vol, opt, e, *m, wc.background, m->peak_index, &fit, &n_fit);
  std::vector<Eigen::Vector3d> starts = {seed_index};
  if (wc.ok) starts.push_back(c);
  // A fit that is a metal ball (metal_hu >= min_metal_hu) is preferred to one that is not: from
  // a centroid pulled by bone touching the marker the fit can settle on a lower-cost mix of the
  // two (1923 HU, SkullBeads' streak seed 13), while the one from the peak voxel is the metal's.
  const auto better = [&](const BallFitResult& a, int na, const BallFitResult& b, int nb) {
    const bool metal_a = a.metal_hu >= opt.min_metal_hu, metal_b = b.metal_hu >= opt.min_metal_hu;
    return metal_a != metal_b ? metal_a : a.cost / na < b.cost / nb;
  };
  for (const Eigen::Vector3d& start : starts) {
    if (peak_ok && FitBallFrom(vol, opt, e, *m, wc.background, start, &other, &n_other) &&
        (!m->fit_ok || better(other, n_other, fit, n_fit))) {
      fit = other;
      n_fit = n_other;
      m->fit_ok = true;
    }
  }
  if (!wc.ok && !m->fit_ok) return false;
  if (m->fit_ok) ChooseCentroidOrFit(vol, opt, fit, n_fit, wc.ok, wc.white_covariance, m);
  m->background_hu = wc.background;
  m->noise_hu = wc.sigma;
  m->roi_voxels = wc.roi_voxels;
  const double contrast = m->peak_hu - wc.background;
  m->weight_volume_mm3 = contrast > 0 ? wc.weight * vol.VoxelVolumeMm3() / contrast : 0;
  return true;
}

// ---- 8. Saturated metal -------------------------------------------------------------------

// The voxels (index, patient mm offset from `centre_mm`) within `radius_mm` of centre_mm.
template <typename F>
void ForVoxelsWithin(const CtVolume& vol, const Eigen::Vector3d& centre_mm, double radius_mm,
                     F&& visit) {
  const Eigen::Matrix3d A = vol.PatientFromIndexLinear();
  const Eigen::Vector3d c = A.inverse() * (centre_mm - vol.origin_mm);
  const int dims[3] = {vol.columns, vol.rows, vol.slices};
  int lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    const double reach = radius_mm / vol.spacing_mm[a] + 1;
    lo[a] = std::max(0, static_cast<int>(std::floor(c[a] - reach)));
    hi[a] = std::min(dims[a] - 1, static_cast<int>(std::ceil(c[a] + reach)));
  }
  for (int k = lo[2]; k <= hi[2]; ++k) {
    for (int j = lo[1]; j <= hi[1]; ++j) {
      for (int i = lo[0]; i <= hi[0]; ++i) {
        const Eigen::Vector3d d = A * (Eigen::Vector3d(i, j, k) - c);
        if (d.norm() <= radius_mm) visit(i, j, k, d);
      }
    }
  }
}

struct SurfaceFit {
  Eigen::Vector3d centre_mm = Eigen::Vector3d::Zero();
  Eigen::Matrix3d covariance_mm2 = Eigen::Matrix3d::Zero();  // of independent rays
  Eigen::Vector2d radii_mm = Eigen::Vector2d::Zero();  // in-plane, along the slices
  int rays = 0, inliers = 0;
  double rms_mm = 0;
  std::vector<Eigen::Vector3d> edge;                      // the last rays' edge points (patient mm)
  Eigen::Vector3d traced_from = Eigen::Vector3d::Zero();  // where they were cast from
};

// Where each ray from `c` first falls below `level` (patient-frame edge points).
constexpr int kEdgeRays = 400;
// Ball-shaped (8.): at least kMinBallRays of the rays end within kBallRayTolerance of the fitted
// spheroid (tails, posts and streaks spoil the rest); its radii within kMinRadiusFraction ..
// kMaxRadiusFraction x the nominal one and their ratio within kMaxAspect (the scanner's blur
// differs across the slices; a pin's piece is much thinner than long).
constexpr double kBallRayTolerance = 0.2;
constexpr double kMinBallRays = 0.5;
constexpr double kMinRadiusFraction = 0.6, kMaxRadiusFraction = 1.6, kMaxAspect = 1.3;
// The clipped centroid's region: the fitted spheroid grown by this (mm).
constexpr double kRoiDelta = 0.5;
constexpr double kMinClipContrastHu = 500;

std::vector<Eigen::Vector3d> EdgePoints(const CtVolume& vol, const Eigen::Vector3d& c,
                                        double level, double clip, double reach_mm) {
  constexpr int kRays = kEdgeRays;
  constexpr double kStepMm = 0.05;
  const Eigen::Matrix3d A_inv = vol.PatientFromIndexLinear().inverse();
  std::vector<Eigen::Vector3d> edge;
  for (int n = 0; n < kRays; ++n) {
    const double z = 1 - 2 * (n + 0.5) / kRays, rho = std::sqrt(1 - z * z);
    const double phi = M_PI * (1 + std::sqrt(5.0)) * (n + 0.5);
    const Eigen::Vector3d u(rho * std::cos(phi), rho * std::sin(phi), z);
    auto value = [&](double t) { return TrilinearHu(vol, A_inv * (c + t * u - vol.origin_mm)); };
    // The first fall below `l` from the inside; < 0: none within the reach.
    auto crossing = [&](double l) {
      double prev = value(0);
      if (prev < l) return -1.0;
      for (double t = kStepMm; t <= reach_mm; t += kStepMm) {
        const double v = value(t);
        if (v < l) return t - kStepMm + (prev - l) / (prev - v) * kStepMm;
        prev = v;
      }
      return -1.0;
    };
    const double r0 = crossing(level);
    if (r0 < 0) continue;
    // The ray's own background, 1 .. 2 mm beyond the edge (past the blur): plastic on one side,
    // air on the other move a common level's crossing by different amounts. The ray's half level
    // between it and the clip instead.
    std::vector<double> beyond;
    for (double t = r0 + 1.0; t <= r0 + 2.0; t += 0.25) beyond.push_back(value(t));
    const double b_ray = Median(&beyond);
    const double l_ray = b_ray + 0.5 * (clip - b_ray);
    if (!(clip - b_ray > kMinClipContrastHu)) continue;
    const double r = crossing(l_ray);
    if (r >= 0) edge.push_back(c + r * u);
  }
  return edge;
}

// Tukey-weighted fit of an axis-aligned spheroid (in the volume's axis frame) to edge points.
bool FitSpheroid(const std::vector<Eigen::Vector3d>& edge, const Eigen::Matrix3d& axes,
                 double R, Eigen::Vector3d* c, Eigen::Vector2d* radii,
                 Eigen::Matrix<double, 5, 5>* H_out, double* s2_out, int* inliers) {
  const int n = static_cast<int>(edge.size());
  if (n < 20) return false;
  Eigen::Matrix<double, 5, 1> p;
  p << axes.transpose() * *c, radii->x(), radii->y();
  std::vector<Eigen::Vector3d> x(n);
  for (int i = 0; i < n; ++i) x[i] = axes.transpose() * edge[i];
  std::vector<double> res(n), w(n);
  std::vector<Eigen::Matrix<double, 5, 1>> J(n);
  Eigen::Matrix<double, 5, 5> H;
  double sigma = 0;
  int iteration = 0;
  auto evaluate = [&]() {
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d d = x[i] - p.head<3>();
      const Eigen::Vector3d s(p(3), p(3), p(4));
      const double q = d.cwiseQuotient(s).norm(), len = d.norm();
      res[i] = (q - 1) * len;
      for (int a = 0; a < 3; ++a) J[i](a) = -len * d[a] / (s[a] * s[a] * q);
      J[i](3) = -len * (d[0] * d[0] + d[1] * d[1]) / (p(3) * p(3) * p(3) * q);
      J[i](4) = -len * d[2] * d[2] / (p(4) * p(4) * p(4) * q);
    }
    std::vector<double> a(n);
    for (int i = 0; i < n; ++i) a[i] = std::abs(res[i]);
    // The scale from the first iterations only: re-estimated as the fit drifts it would let
    // the fit follow the outliers (a tail, a post).
    if (iteration < 3) sigma = std::max(1.4826 * Median(&a), 1e-3);
    for (int i = 0; i < n; ++i) {
      const double u = res[i] / (4.685 * sigma);
      w[i] = std::abs(u) < 1 ? (1 - u * u) * (1 - u * u) : 0.0;
    }
    H.setZero();
    for (int i = 0; i < n; ++i) H += w[i] * J[i] * J[i].transpose();
  };
  for (iteration = 0; iteration < 60; ++iteration) {
    evaluate();
    Eigen::Matrix<double, 5, 1> g = Eigen::Matrix<double, 5, 1>::Zero();
    for (int i = 0; i < n; ++i) g += w[i] * res[i] * J[i];
    Eigen::Matrix<double, 5, 1> step = H.ldlt().solve(-g);
    if (!step.allFinite()) return false;
    // Damped: at most 0.5 mm per step, the radii kept within 0.3 .. 2.5 x the nominal radius.
    const double largest = step.cwiseAbs().maxCoeff();
    if (largest > 0.5) step *= 0.5 / largest;
    p += step;
    p(3) = std::clamp(p(3), 0.3 * R, 2.5 * R);
    p(4) = std::clamp(p(4), 0.3 * R, 2.5 * R);
    if (step.norm() < 1e-6) break;
  }
  evaluate();
  double sw = 0, swr2 = 0;
  int in = 0;
  for (int i = 0; i < n; ++i) {
    sw += w[i];
    swr2 += w[i] * res[i] * res[i];
    in += w[i] > 0;
  }
  if (!(sw > 6)) return false;
  *c = axes * p.head<3>();
  *radii = p.tail<2>();
  *H_out = H;
  *s2_out = swr2 / (sw - 5);
  *inliers = in;
  return true;
}

// The 12 sectors of the sphere of directions around an icosahedron's vertices, one vertex along
// the slice axis: the caps across the slices, where sparse slices hide the edge, are sectors.
int EdgeSector(const Eigen::Vector3d& u) {
  static const std::array<Eigen::Vector3d, 12> vertices = [] {
    std::array<Eigen::Vector3d, 12> v;
    v[0] = Eigen::Vector3d::UnitZ();
    v[11] = -Eigen::Vector3d::UnitZ();
    const double z = 1 / std::sqrt(5.0), rho = 2 / std::sqrt(5.0);
    for (int k = 0; k < 5; ++k) {
      const double a = 2 * M_PI * k / 5, b = a + M_PI / 5;
      v[1 + k] = Eigen::Vector3d(rho * std::cos(a), rho * std::sin(a), z);
      v[6 + k] = Eigen::Vector3d(rho * std::cos(b), rho * std::sin(b), -z);
    }
    return v;
  }();
  int best = 0;
  for (int k = 1; k < 12; ++k) {
    if (vertices[k].dot(u) > vertices[best].dot(u)) best = k;
  }
  return best;
}

// Delete-one-sector jackknife of the spheroid's centre (axis frame, mm^2): each of the 12 sectors
// of edge directions (EdgeSector, seen from `traced_from`) left out in turn and the spheroid
// re-fitted from `c`, `radii`. It sees errors of the edge that are correlated over a sector,
// which s^2 H^-1 of independent rays does not: a real sphere's shape is not a spheroid (helical
// scanners distort metal), and slices with gaps put a whole cap's edge at the wrong height.
// Zero when fewer than 8 sectors could be left out.
Eigen::Matrix3d SectorJackknifeCovariance(const std::vector<Eigen::Vector3d>& edge,
                                          const Eigen::Vector3d& traced_from,
                                          const Eigen::Matrix3d& axes,
                                          double R,
                                          const Eigen::Vector3d& c,
                                          const Eigen::Vector2d& radii) {
  std::array<std::vector<Eigen::Vector3d>, 12> rest;
  for (const auto& x : edge) {
    const int sector = EdgeSector((axes.transpose() * (x - traced_from)).normalized());
    for (int k = 0; k < 12; ++k) {
      if (k != sector) rest[k].push_back(x);
    }
  }
  std::vector<Eigen::Vector3d> centres;
  for (const auto& points : rest) {
    if (points.size() == edge.size()) continue;  // an empty sector: nothing left out
    Eigen::Vector3d ck = c;
    Eigen::Vector2d rk = radii;
    Eigen::Matrix<double, 5, 5> H;
    double s2 = 0;
    int inliers = 0;
    if (FitSpheroid(points, axes, R, &ck, &rk, &H, &s2, &inliers)) {
      centres.push_back(axes.transpose() * ck);
    }
  }
  const int K = static_cast<int>(centres.size());
  if (K < 8) return Eigen::Matrix3d::Zero();
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& ck : centres) mean += ck / K;
  Eigen::Matrix3d J = Eigen::Matrix3d::Zero();
  for (const auto& ck : centres) J += (ck - mean) * (ck - mean).transpose();
  return J * (K - 1.0) / K;
}

// The smallest widening of covariance A that covers B too: A where B is within it, B's variance
// along the directions where B exceeds A (the eigenvalues of B whitened by A, each raised to at
// least 1).
Eigen::Matrix3d CoveringCovariance(const Eigen::Matrix3d& A, const Eigen::Matrix3d& B) {
  const Eigen::LLT<Eigen::Matrix3d> llt(A);
  if (llt.info() != Eigen::Success) return A + B;
  const Eigen::Matrix3d L = llt.matrixL();
  const Eigen::Matrix3d L_inv = L.inverse();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(L_inv * B * L_inv.transpose());
  const Eigen::Vector3d lambda = eig.eigenvalues().cwiseMax(1.0);
  return L * eig.eigenvectors() * lambda.asDiagonal() * eig.eigenvectors().transpose() *
         L.transpose();
}

// The surface fit of 8., from `start` (patient mm, inside the clipped core).
bool FitSaturatedSurface(const CtVolume& vol, const Eigen::Vector3d& start, double b,
                         double clip, double radius, SurfaceFit* out) {
  const double level = b + 0.5 * (clip - b);
  Eigen::Vector3d c = start;
  Eigen::Vector2d radii(radius, radius);
  Eigen::Matrix<double, 5, 5> H;
  double s2 = 0;
  int inliers = 0;
  std::vector<Eigen::Vector3d> edge;
  Eigen::Vector3d traced_from = c;
  for (int outer = 0; outer < 4; ++outer) {
    traced_from = c;
    edge = EdgePoints(vol, c, level, clip, 2.5 * radius);
    Eigen::Vector3d c_new = c;
    if (!FitSpheroid(edge, vol.axes, radius, &c_new, &radii, &H, &s2, &inliers)) return false;
    if ((c_new - start).norm() > radius) return false;
    c = c_new;
  }
  const Eigen::Matrix<double, 5, 5> H_inv = H.inverse();
  if (!H_inv.allFinite()) return false;
  const double rays = static_cast<double>(edge.size());
  const double share = inliers / std::max(rays, 1.0);
  // Ellipsoid area (Knud Thomsen's approximation, p = 1.6075).
  const double a = radii.x(), cz = radii.y(), pk = 1.6075;
  const double area =
      4 * M_PI * std::pow((2 * std::pow(a * a, pk) + 2 * std::pow(a * cz, pk)) / 3, 1 / pk);
  const double n_eff = std::max(6.0, share * area / std::pow(vol.VoxelVolumeMm3(), 2.0 / 3));
  out->centre_mm = c;
  out->covariance_mm2 = s2 * H_inv.topLeftCorner<3, 3>() * std::max(1.0, inliers / n_eff);
  out->covariance_mm2 = vol.axes * out->covariance_mm2 * vol.axes.transpose();
  out->radii_mm = radii;
  // Ball-shaped: the share of all rays whose edge is within 20 % of the spheroid's radius along it.
  int near = 0;
  for (const auto& x : edge) {
    const Eigen::Vector3d d = vol.axes.transpose() * (x - c);
    const double q = d.cwiseQuotient(Eigen::Vector3d(radii.x(), radii.x(), radii.y())).norm();
    near += std::abs(q - 1) <= kBallRayTolerance;
  }
  out->rays = kEdgeRays;
  out->inliers = near;
  out->rms_mm = std::sqrt(s2);
  out->edge = std::move(edge);
  out->traced_from = traced_from;
  return true;
}

// The share of the voxels inside the spheroid shrunk by one voxel extent that reach `level`.
double SpheroidFill(const CtVolume& vol, const SurfaceFit& s, double level) {
  const Eigen::Vector3d r(s.radii_mm.x() - 0.5 * vol.spacing_mm.x(),
                          s.radii_mm.x() - 0.5 * vol.spacing_mm.y(),
                          s.radii_mm.y() - 0.5 * vol.spacing_mm.z());
  if (r.minCoeff() <= 0) return 0;
  int inside = 0, full = 0;
  ForVoxelsWithin(
      vol, s.centre_mm, r.maxCoeff(), [&](int i, int j, int k, const Eigen::Vector3d& d) {
        if ((vol.axes.transpose() * d).cwiseQuotient(r).norm() > 1) return;
        ++inside;
        full += vol.At(i, j, k) >= level;
      });
  return inside ? static_cast<double>(full) / inside : 0.0;
}

// The sampling term of a saturated marker's surface fit (8.), by the fit itself: the half-level
// surface of noise-free clipped balls (ct/ct_phantom.h's voxeliser), kSamplingPhases sub-voxel
// positions (Halton), in a volume sampled as this one is (pixel, slice step, slice thickness), the
// mean over three metal contrasts (the clip hides the true one; denser metal has a sharper edge
// across slices). The analytic term
// (SamplingVarianceMm2) is the centroid's of an unclipped ball; a clipped ball's edge across
// sparse slices moves by up to half a step, which it misses (tests/ct/saturated_marker_test.cc).
// No blur: where the scanner's blur smooths the edge the simulated term is too large.
constexpr int kSamplingPhases = 8;
constexpr int kOccupancySubsamples = 5;  // per axis, for voxels the ball's surface cuts
// Metal above the background, in multiples of (clip - background).
constexpr double kSimulatedContrasts[] = {2, 4, 8};

double Halton(int index, int base) {
  double f = 1, r = 0;
  for (int i = index; i > 0; i /= base) f /= base, r += f * (i % base);
  return r;
}

// Background 0, metal `clip` and more above it: the clip's contrast is all that matters.
Eigen::Vector3d SimulateSurfaceSamplingMm2(const Eigen::Vector3d& spacing, double thickness,
                                           double r, double clip) {
  Eigen::Vector3i n;
  for (int a = 0; a < 3; ++a) n[a] = 2 * static_cast<int>(std::ceil(2.5 * r / spacing[a])) + 5;
  CtVolume sim;
  sim.columns = n.x(), sim.rows = n.y(), sim.slices = n.z();
  sim.spacing_mm = spacing;
  sim.slice_thickness_mm = thickness;
  sim.origin_mm = -0.5 * spacing.cwiseProduct((n.array() - 1).matrix().cast<double>());
  CtPhantom ball;
  ball.marker_diameter_mm = 2 * r;
  ball.has_block = false;
  ball.air_hu = 0;
  ball.markers.resize(1);
  CtVoxeliseOptions noise_free;
  noise_free.marker_supersampling = kOccupancySubsamples;
  noise_free.noise_hu = 0;
  noise_free.clip_hu = clip;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  int contrasts = 0;
  for (double contrast : kSimulatedContrasts) {
    ball.marker_hu = contrast * clip;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    int fitted = 0;
    for (int p = 1; p <= kSamplingPhases; ++p) {
      const Eigen::Vector3d phase(Halton(p, 2) - 0.5, Halton(p, 3) - 0.5, Halton(p, 5) - 0.5);
      ball.markers[0].centre_mm = phase.cwiseProduct(spacing);
      SurfaceFit s;
      if (!VoxelisePhantom(ball, noise_free, &sim).ok() ||
          !FitSaturatedSurface(sim, ball.markers[0].centre_mm, 0, clip, r, &s)) {
        continue;
      }
      sum += (s.centre_mm - ball.markers[0].centre_mm).cwiseAbs2();
      ++fitted;
    }
    if (fitted > 0) mean += sum / fitted, ++contrasts;
  }
  return contrasts > 0 ? Eigen::Vector3d(mean / contrasts) : mean;
}

// SimulateSurfaceSamplingMm2 for `vol`'s sampling, along its axes (mm^2), remembered per
// sampling, radius (to 0.1 mm) and clip contrast (to 50 HU): the markers of one series share them.
Eigen::Vector3d SurfaceSamplingMm2(const CtVolume& vol, double r, double b, double clip) {
  const double thickness = vol.slice_thickness_mm > 0 ? vol.slice_thickness_mm : vol.spacing_mm.z();
  const Eigen::Vector3d& h = vol.spacing_mm;
  const std::array<long, 6> key{std::lround(h.x() * 1e4), std::lround(h.y() * 1e4),
                                std::lround(h.z() * 1e4), std::lround(thickness * 1e4),
                                std::lround(r * 10), 50 * std::lround((clip - b) / 50)};
  static std::mutex mutex;
  static std::map<std::array<long, 6>, Eigen::Vector3d> cache;
  {
    std::lock_guard<std::mutex> lock(mutex);
    auto it = cache.find(key);
    if (it != cache.end()) return it->second;
  }
  const Eigen::Vector3d v =
      SimulateSurfaceSamplingMm2(h, thickness, key[4] / 10.0, static_cast<double>(key[5]));
  std::lock_guard<std::mutex> lock(mutex);
  cache[key] = v;
  return v;
}

// The clipped centroid of 8.: returns false without mass.
bool ClippedCentroid(const CtVolume& vol, Eigen::Vector3d start, double b, double clip,
                     double sigma_b, const Eigen::Vector3d& roi_mm, Eigen::Vector3d* c_out,
                     Eigen::Matrix3d* cov) {
  Eigen::Vector3d c = start;
  double W = 0;
  Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
  for (int it = 0; it < 8; ++it) {
    W = 0;
    Eigen::Vector3d m = Eigen::Vector3d::Zero();
    std::vector<Eigen::Vector3d> offsets;
    ForVoxelsWithin(vol, c, roi_mm.maxCoeff(), [&](int i, int j, int k, const Eigen::Vector3d& d) {
      if ((vol.axes.transpose() * d).cwiseQuotient(roi_mm).norm() > 1) return;
      const double u = std::clamp((vol.At(i, j, k) - b) / (clip - b), 0.0, 1.0);
      W += u;
      m += u * d;
      offsets.push_back(d);
    });
    if (!(W > 0)) return false;
    const Eigen::Vector3d shift = m / W;
    S.setZero();
    for (const auto& d : offsets) S += (d - shift) * (d - shift).transpose();
    c += shift;
    if (shift.norm() < 1e-5) break;
  }
  const double su = sigma_b / (clip - b);
  *c_out = c;
  *cov = su * su * S / (W * W);
  return true;
}

// The fitted spheroid's axial radius with what sparse slices do to it taken off. The half-level
// edge across slices is interpolated over the slice step: the slice just outside a clipped
// sphere can still be above the half level, or the last slice inside it fall short of the edge,
// so the axial radius comes out up to half a step (less the in-plane pixel, which the in-plane
// radius shares) too large or too small: 3.8-3.9 mm against 2.8-2.9 mm in plane for a 5.5 mm
// steel sphere every 2.5 mm, 2.1-2.2 against 3.0-3.1 mm every 3 mm. Moved toward the in-plane
// radius, never past it: the allowance forgives only the sampling's share of a difference.
double SliceStepAllowanceMm(const CtVolume& vol) {
  return 0.5 * std::max(0.0, vol.spacing_mm.z() - vol.spacing_mm.x());
}

double AxialRadiusWithoutSliceSampling(const CtVolume& vol, const Eigen::Vector2d& radii_mm) {
  const double allowance = SliceStepAllowanceMm(vol);
  if (radii_mm.y() > radii_mm.x()) return std::max(radii_mm.x(), radii_mm.y() - allowance);
  return std::min(radii_mm.x(), radii_mm.y() + allowance);
}

// Measures a marker whose peak is at the clip (8.). On failure, *reason says why.
bool RefineSaturated(const CtVolume& vol, const MarkerDetectionOptions& opt, double clip,
                     DetectedMarker* m, std::string* reason) {
  const double R = 0.5 * opt.diameter_mm;
  const Eigen::Vector3d seed_mm = vol.PatientFromIndex(m->centre_index);
  // Start at the most interior clipped voxel within 1.5 R of the seed (farthest from any voxel
  // below the clip; the ball is the thickest part, a post or tail thinner), ties to the nearest.
  Eigen::Vector3d start = vol.PatientFromIndex(m->peak_index);
  std::vector<Eigen::Vector3d> clipped, unclipped;
  ForVoxelsWithin(vol, seed_mm, 2.5 * R, [&](int i, int j, int k, const Eigen::Vector3d& d) {
    (vol.At(i, j, k) >= clip ? clipped : unclipped).push_back(d);
  });
  double deepest = -1, nearest = 1e30;
  for (const auto& d : clipped) {
    if (d.norm() > 1.5 * R) continue;
    double depth = 1e30;
    for (const auto& o : unclipped) depth = std::min(depth, (o - d).squaredNorm());
    if (depth > deepest + 1e-9 || (std::abs(depth - deepest) <= 1e-9 && d.norm() < nearest)) {
      deepest = depth;
      nearest = d.norm();
      start = seed_mm + d;
    }
  }
  // Background: median and MAD of a shell beyond the blooming.
  std::vector<double> shell;
  const double r_in = 1.5 * R + 1.0, r_out = r_in + 1.5;
  ForVoxelsWithin(vol, start, r_out, [&](int i, int j, int k, const Eigen::Vector3d& d) {
    if (d.norm() > r_in) shell.push_back(vol.At(i, j, k));
  });
  if (shell.size() < 8) {
    *reason = "too close to the volume's border for a background shell";
    return false;
  }
  const double b = Median(&shell);
  std::vector<double> dev(shell.size());
  for (size_t s = 0; s < shell.size(); ++s) dev[s] = std::abs(shell[s] - b);
  const double sigma_b = std::max(1.4826 * Median(&dev), 1.0);
  if (!(clip - b > kMinClipContrastHu)) {
    *reason = "the clip is less than 500 HU above the background";
    return false;
  }
  SurfaceFit s;
  char b_[400];
  if (!FitSaturatedSurface(vol, start, b, clip, R, &s)) {
    *reason = "saturated but not a ball: its half-level edge does not close around a spheroid "
              "near the seed (a pin or wire?)";
    return false;
  }
  const double fill = SpheroidFill(vol, s, b + 0.5 * (clip - b));
  const double aspect = s.radii_mm.x() / AxialRadiusWithoutSliceSampling(vol, s.radii_mm);
  if (s.radii_mm.minCoeff() < kMinRadiusFraction * R ||
      s.radii_mm.maxCoeff() > kMaxRadiusFraction * R || aspect < 1 / kMaxAspect ||
      aspect > kMaxAspect) {
    std::snprintf(b_, sizeof(b_),
                  "saturated but not a ball of about the nominal size: its edge a spheroid of "
                  "radii %.2f (in-plane) and %.2f mm (need %.1f .. %.1f x the nominal %.2f mm, "
                  "ratio within %.2f with the axial radius moved up to %.2f mm toward the "
                  "in-plane one for the slice step: a pin or wire?)",
                  s.radii_mm.x(), s.radii_mm.y(), kMinRadiusFraction, kMaxRadiusFraction, R,
                  kMaxAspect, SliceStepAllowanceMm(vol));
    *reason = b_;
    return false;
  }
  if (s.inliers < kMinBallRays * s.rays || fill < opt.min_inner_fraction) {
    std::snprintf(b_, sizeof(b_),
                  "saturated but not a ball: %d of %d edge rays within %.0f%% of the fitted "
                  "spheroid (need %.0f%%), %.0f%% of its inside at the half level (need %.0f%%): "
                  "a pin or wire?",
                  s.inliers, s.rays, 100 * kBallRayTolerance, 100 * kMinBallRays, 100 * fill,
                  100 * opt.min_inner_fraction);
    *reason = b_;
    return false;
  }
  Eigen::Vector3d cc;
  Eigen::Matrix3d cc_cov;
  const Eigen::Vector3d roi(s.radii_mm.x() + kRoiDelta, s.radii_mm.x() + kRoiDelta,
                            s.radii_mm.y() + kRoiDelta);
  if (!ClippedCentroid(vol, start, b, clip, sigma_b, roi, &cc, &cc_cov)) {
    *reason = "saturated, but the clipped centroid has no mass";
    return false;
  }
  Eigen::Matrix3d sampling = Eigen::Matrix3d::Zero();
  const double thickness = vol.slice_thickness_mm > 0 ? vol.slice_thickness_mm : vol.spacing_mm.z();
  const Eigen::Vector3d e(vol.spacing_mm.x(), vol.spacing_mm.y(), thickness);
  for (int a = 0; a < 3; ++a) {
    sampling(a, a) = SamplingVarianceMm2(a < 2 ? s.radii_mm.x() : s.radii_mm.y(),
                                         vol.spacing_mm[a], e[a]);
  }
  // Without gaps the partial-volume averages cover the ball and the analytic term (5.) holds for
  // the surface fit too (NEES per dof 0.8-1.7 on contiguous clipped spheres, where the simulated
  // term, a ball with no blur, says 0.2-0.5); with gaps an edge can fall between slices unseen,
  // which only the simulation has.
  if (SlicesHaveGaps(vol)) {
    const Eigen::Vector3d simulated = SurfaceSamplingMm2(vol, s.radii_mm.x(), b, clip);
    for (int a = 0; a < 3; ++a) sampling(a, a) = std::max(sampling(a, a), simulated[a]);
  }
  const Eigen::Matrix3d sampling_mm2 = vol.axes * sampling * vol.axes.transpose();
  cc_cov += sampling_mm2;
  // The half-level edge is interpolated between voxels: its error over the sub-voxel phase is
  // of the order of the centroid's (5.), which thick or sparse slices make large.
  s.covariance_mm2 += sampling_mm2;
  // With gaps, also what leaving out each sector of the edge does to the centre (the real CT's
  // odd and even halves differ by twice what a simulated ball's sampling explains).
  if (SlicesHaveGaps(vol)) {
    const Eigen::Matrix3d sectors =
        SectorJackknifeCovariance(s.edge, s.traced_from, vol.axes, R, s.centre_mm, s.radii_mm);
    s.covariance_mm2 =
        CoveringCovariance(s.covariance_mm2, vol.axes * sectors * vol.axes.transpose());
  }
  m->saturated = true;
  m->surface_centre_mm = s.centre_mm;
  m->surface_covariance_mm2 = s.covariance_mm2;
  m->surface_radii_mm = s.radii_mm;
  m->surface_rays = s.rays;
  m->surface_inliers = s.inliers;
  m->surface_rms_mm = s.rms_mm;
  m->centroid_mm = cc;
  m->centroid_covariance_mm2 = cc_cov;
  const Eigen::Vector3d delta = cc - s.centre_mm;
  m->contamination_chi2 = delta.dot((cc_cov + s.covariance_mm2).ldlt().solve(delta));
  m->centre_mm = s.centre_mm;
  m->centre_index = vol.PatientFromIndexLinear().inverse() * (s.centre_mm - vol.origin_mm);
  m->covariance_noise_mm2 = s.covariance_mm2 - sampling_mm2;
  m->covariance_sampling_mm2 = sampling_mm2;
  m->covariance_mm2 = s.covariance_mm2 * std::max(1.0, m->contamination_chi2 / 3.0);
  m->fit_ok = true;
  m->fit_centre_mm = s.centre_mm;
  m->fit_covariance_mm2 = s.covariance_mm2;
  m->fit_metal_hu = clip;  // at least: the scanner clipped it
  m->fit_background_hu = b;
  m->fit_inner_fraction = fill;
  m->background_hu = b;
  m->noise_hu = sigma_b;
  m->peak_needed_hu = 0;
  return true;
}

}  // namespace

namespace {

// Voxel index -> (i, j, k).
Eigen::Vector3i VoxelIjk(const CtVolume& vol, size_t v) {
  const size_t nx = vol.columns, nxy = static_cast<size_t>(vol.columns) * vol.rows;
  const int k = static_cast<int>(v / nxy);
  const size_t r = v % nxy;
  return Eigen::Vector3i(static_cast<int>(r % nx), static_cast<int>(r / nx), k);
}

// 1. The voxels at or above the threshold; an error when they are too many for markers.
StatusOr<std::vector<size_t>> ThresholdCore(const CtVolume& vol,
                                            const MarkerDetectionOptions& opt) {
  const float thr = static_cast<float>(opt.threshold_hu);
  const size_t max_core = static_cast<size_t>(opt.max_core_fraction * vol.hu.size()) + 1;
  std::vector<size_t> core;
  for (size_t v = 0; v < vol.hu.size(); ++v) {
    if (vol.hu[v] < thr) continue;
    core.push_back(v);
    if (core.size() > max_core) {
      char b[256];
      std::snprintf(b, sizeof(b),
                    "more than %.1f%% of the CT's voxels are >= %.0f HU: the threshold is too "
                    "low for metal markers (set it above the object's and bone's HU)",
                    100 * opt.max_core_fraction, opt.threshold_hu);
      return Status::Error(b);
    }
  }
  return core;
}

// 8. The scanner's clip: given, or the largest value when enough voxels hold it; and how many
// core voxels hold it.
void ScannerClip(const CtVolume& vol,
                 const MarkerDetectionOptions& opt,
                 const std::vector<size_t>& core,
                 MarkerDetection* out) {
  if (opt.clip_hu > 0) {
    out->clip_hu = opt.clip_hu;
  } else if (opt.clip_hu == 0 && !core.empty()) {
    float top = static_cast<float>(opt.threshold_hu);
    for (size_t v : core) top = std::max(top, vol.hu[v]);
    int at_top = 0;
    for (size_t v : core) at_top += vol.hu[v] >= top;
    if (at_top >= kMinClippedVoxels) out->clip_hu = top;
  }
  if (out->clip_hu > 0) {
    for (size_t v : core) out->clipped_voxels += vol.hu[v] >= out->clip_hu;
  }
}

// 2. The 26-connected components of the core, as positions in `core`, in the order of their
// first voxel.
std::vector<std::vector<int>> CoreComponents(const CtVolume& vol, const std::vector<size_t>& core) {
  std::unordered_map<size_t, int> position;
  position.reserve(core.size() * 2);
  for (size_t p = 0; p < core.size(); ++p) position[core[p]] = static_cast<int>(p);
  UnionFind uf(static_cast<int>(core.size()));
  for (size_t p = 0; p < core.size(); ++p) {
    const Eigen::Vector3i q = VoxelIjk(vol, core[p]);
    for (int dk = 0; dk <= 1; ++dk) {
      for (int dj = -1; dj <= 1; ++dj) {
        for (int di = -1; di <= 1; ++di) {
          // The 13 forward neighbours: later in memory order.
          if (dk == 0 && (dj < 0 || (dj == 0 && di <= 0))) continue;
          const int i = q.x() + di, j = q.y() + dj, k = q.z() + dk;
          if (i < 0 || j < 0 || k < 0 || i >= vol.columns || j >= vol.rows || k >= vol.slices) {
            continue;
          }
          auto it = position.find(vol.Index(i, j, k));
          if (it != position.end()) uf.Union(static_cast<int>(p), it->second);
        }
      }
    }
  }
  std::unordered_map<int, int> component_of_root;
  std::vector<std::vector<int>> components;
  for (size_t p = 0; p < core.size(); ++p) {
    const int r = uf.Find(static_cast<int>(p));
    auto it = component_of_root.find(r);
    if (it == component_of_root.end()) {
      it = component_of_root.emplace(r, static_cast<int>(components.size())).first;
      components.emplace_back();
    }
    components[it->second].push_back(static_cast<int>(p));
  }
  return components;
}

// A component's extent, centroid and peak (voxel indices).
struct ComponentStats {
  Eigen::Vector3i lo, hi;
  Eigen::Vector3d centroid, peak_at = Eigen::Vector3d::Zero();
  double peak = -1e30, volume_mm3 = 0;
};

ComponentStats StatsOfComponent(const CtVolume& vol,
                                const std::vector<size_t>& core,
                                const std::vector<int>& members) {
  ComponentStats c;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  c.lo = c.hi = VoxelIjk(vol, core[members[0]]);
  for (int p : members) {
    const Eigen::Vector3i q = VoxelIjk(vol, core[p]);
    sum += q.cast<double>();
    c.lo = c.lo.cwiseMin(q);
    c.hi = c.hi.cwiseMax(q);
    if (vol.hu[core[p]] > c.peak) {
      c.peak = vol.hu[core[p]];
      c.peak_at = q.cast<double>();
    }
  }
  c.centroid = sum / members.size();
  c.volume_mm3 = members.size() * vol.VoxelVolumeMm3();
  return c;
}

// Where a marker's refinement starts.
struct MarkerSeed {
  Eigen::Vector3d index;
  double core_radius_mm;
  double peak_hu;
  Eigen::Vector3d peak_index;
};

// 3. Seeds: the component itself when it is marker-sized; else (a marker touching bone or
// another dense structure above the threshold) its local maxima, strongest first, at least one
// diameter apart, each started with the nominal radius.
std::vector<MarkerSeed> ComponentSeeds(const CtVolume& vol,
                                       const MarkerDetectionOptions& opt,
                                       const std::vector<size_t>& core,
                                       const std::vector<int>& members,
                                       const ComponentStats& c,
                                       bool large) {
  if (!large)
    return {{c.centroid, std::cbrt(3.0 * c.volume_mm3 / (4.0 * M_PI)), c.peak, c.peak_at}};
  const double radius = 0.5 * opt.diameter_mm;
  const Eigen::Matrix3d A = vol.PatientFromIndexLinear();
  std::vector<std::pair<double, Eigen::Vector3i>> maxima;
  for (int p : members) {
    const Eigen::Vector3i q = VoxelIjk(vol, core[p]);
    const float v = vol.hu[core[p]];
    bool is_max = true;
    for (int dk = -1; dk <= 1 && is_max; ++dk) {
      for (int dj = -1; dj <= 1 && is_max; ++dj) {
        for (int di = -1; di <= 1 && is_max; ++di) {
          const int i = q.x() + di, j = q.y() + dj, k = q.z() + dk;
          if (i < 0 || j < 0 || k < 0 || i >= vol.columns || j >= vol.rows || k >= vol.slices)
            continue;
          const float w = vol.At(i, j, k);
          // Ties: the first in memory order is the maximum.
          if (w > v || (w == v && vol.Index(i, j, k) < core[p])) is_max = false;
        }
      }
    }
    if (is_max) maxima.emplace_back(v, q);
  }
  std::sort(
      maxima.begin(), maxima.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<MarkerSeed> seeds;
  for (const auto& [v, q] : maxima) {
    const Eigen::Vector3d x = q.cast<double>();
    bool far = true;
    for (const auto& s : seeds) far = far && (A * (x - s.index)).norm() >= radius;
    if (far) seeds.push_back({x, radius, v, x});
    if (static_cast<int>(seeds.size()) >= opt.max_seeds_per_component) break;
  }
  return seeds;
}

// How far (mm) a marker's fitted centre lies from where its component put it: the nearer of the
// component's centroid and its densest voxel. A marker touching bone above the threshold makes
// one component with it, whose centroid lies between the two (1.5-2.4 mm from a 3 mm bead's
// centre in SkullBeads' streak seeds 7-24), while the densest voxel is the metal's.
double FitOffSeedMm(const CtVolume& vol, const DetectedMarker& m) {
  return std::min((m.fit_centre_mm - m.core_centroid_mm).norm(),
                  (m.fit_centre_mm - vol.PatientFromIndex(m.peak_index)).norm());
}

// 6. Why a refined marker is not accepted (not metal, no ball fit, not ball-shaped, far from its
// seed), or "".
std::string RefinedMarkerRejection(const CtVolume& vol,
                                   const MarkerDetectionOptions& opt,
                                   const DetectedMarker& m) {
  const double radius = 0.5 * opt.diameter_mm;
  const Eigen::Matrix3d A = vol.PatientFromIndexLinear();
  char b[200] = "";
  if (m.peak_hu < m.peak_needed_hu) {
    std::snprintf(b, sizeof(b),
                  "peak %.0f HU < %.0f HU, the least a %.3g mm ball of %.0f HU gives in these "
                  "voxels over its %.0f HU background (not metal: bone?)",
                  m.peak_hu, m.peak_needed_hu, opt.diameter_mm, opt.min_metal_hu, m.background_hu);
  } else if (!m.fit_ok) {
    std::snprintf(b, sizeof(b), "the partial-volume ball fit failed");
  } else if (m.fit_metal_hu < opt.min_metal_hu) {
    std::snprintf(b,
                  sizeof(b),
                  "fitted ball HU %.0f < %.0f (not metal: bone?)",
                  m.fit_metal_hu,
                  opt.min_metal_hu);
  } else if (m.fit_inner_fraction < opt.min_inner_fraction) {
    std::snprintf(b, sizeof(b),
                  "not ball-shaped: %.0f%% of the voxels inside the fitted %.3g mm ball are "
                  "within 25%% of its contrast (< %.0f%%)",
                  100 * m.fit_inner_fraction, opt.diameter_mm, 100 * opt.min_inner_fraction);
  } else if (const double off = FitOffSeedMm(vol, m);
             off > radius + 0.5 * A.colwise().norm().maxCoeff()) {
    std::snprintf(b, sizeof(b), "the fitted ball is %.2f mm from its seed", off);
  }
  return b;
}

// One component: rejected by size or the volume's border, or its seeds refined (4-6; saturated
// metal: 8) into markers not already taken. A component that gives none is rejected with the
// last seed's reason.
void DetectInComponent(const CtVolume& vol,
                       const MarkerDetectionOptions& opt,
                       const std::vector<size_t>& core,
                       const std::vector<int>& members,
                       double min_peak_fraction,
                       std::vector<DetectedMarker>* accepted,
                       MarkerDetection* out) {
  const double nominal_mm3 = M_PI / 6.0 * std::pow(opt.diameter_mm, 3);
  const ComponentStats c = StatsOfComponent(vol, core, members);
  const double volume = c.volume_mm3;
  RejectedComponent rej;
  rej.centroid_mm = vol.PatientFromIndex(c.centroid);
  rej.volume_mm3 = volume;
  rej.peak_hu = c.peak;
  rej.voxels = static_cast<int>(members.size());
  char why[200] = "";
  const bool large = volume > opt.max_volume_fraction * nominal_mm3;
  if (volume < opt.min_volume_fraction * nominal_mm3) {
    std::snprintf(why, sizeof(why), "too small: %.3f mm^3 < %.2f x %.3f mm^3", volume,
                  opt.min_volume_fraction, nominal_mm3);
  } else if (c.lo.minCoeff() == 0 || c.hi.x() == vol.columns - 1 || c.hi.y() == vol.rows - 1 ||
             c.hi.z() == vol.slices - 1) {
    std::snprintf(why, sizeof(why), "touches the border of the volume");
  }
  if (why[0]) {
    rej.reason = why;
    out->rejected.push_back(rej);
    return;
  }
  const std::vector<MarkerSeed> seeds = ComponentSeeds(vol, opt, core, members, c, large);
  int kept = 0;
  std::string last_reason;
  for (const auto& seed : seeds) {
    const Eigen::Vector3d seed_mm = vol.PatientFromIndex(seed.index);
    bool taken = false;
    for (const auto& a : *accepted)
      taken = taken || (a.centre_mm - seed_mm).norm() < opt.diameter_mm;
    if (taken) continue;
    DetectedMarker m;
    m.core_voxels = static_cast<int>(members.size());
    m.volume_mm3 = large ? 0 : volume;
    m.peak_hu = seed.peak_hu;
    m.core_centroid_mm = vol.PatientFromIndex(large ? seed.index : c.centroid);
    m.bbox_centre_mm =
        large ? m.core_centroid_mm : vol.PatientFromIndex(0.5 * (c.lo + c.hi).cast<double>());
    m.centre_index = seed.index;
    m.peak_index = seed.peak_index;
    m.merged = large;
    if (out->clip_hu > 0 && m.peak_hu >= out->clip_hu) {
      std::string reason;
      if (!RefineSaturated(vol, opt, out->clip_hu, &m, &reason)) {
        last_reason = reason;
        continue;
      }
      ++kept;
      accepted->push_back(m);
      continue;
    }
    if (!Refine(vol, opt, seed.core_radius_mm, min_peak_fraction, &m)) {
      last_reason = "no contrast against its surroundings (weighted mass <= 0) or no background";
      continue;
    }
    const std::string reason = RefinedMarkerRejection(vol, opt, m);
    if (!reason.empty()) {
      last_reason = reason;
      continue;
    }
    ++kept;
    accepted->push_back(m);
  }
  if (kept > 0) return;
  if (large) {
    std::snprintf(why, sizeof(why),
                  "too large: %.3f mm^3 > %.2f x %.3f mm^3, and no ball-shaped metal peak in "
                  "it (%zu seed(s)%s%s)",
                  volume, opt.max_volume_fraction, nominal_mm3, seeds.size(),
                  last_reason.empty() ? "" : "; last: ", last_reason.c_str());
    rej.reason = why;
  } else {
    rej.reason = last_reason;
  }
  out->rejected.push_back(rej);
}

// Two seeds of one marker (a merged component's maxima): the better fit is kept; the markers
// numbered from 1.
void KeepDistinctMarkers(const std::vector<DetectedMarker>& accepted,
                         double radius,
                         MarkerDetection* out) {
  std::vector<bool> dropped(accepted.size(), false);
  for (size_t a = 0; a < accepted.size(); ++a) {
    for (size_t b = a + 1; b < accepted.size(); ++b) {
      if (dropped[a] || dropped[b]) continue;
      if ((accepted[a].centre_mm - accepted[b].centre_mm).norm() >= radius) continue;
      const bool a_better = accepted[a].fit_inner_fraction >= accepted[b].fit_inner_fraction;
      dropped[a_better ? b : a] = true;
    }
  }
  for (size_t a = 0; a < accepted.size(); ++a) {
    if (dropped[a]) continue;
    out->markers.push_back(accepted[a]);
    out->markers.back().id = static_cast<int>(out->markers.size());
  }
}

// The error when no marker, or not the expected number, was found: where they were found and
// the first rejected components with their reasons.
Status CountError(const MarkerDetection& out, const MarkerDetectionOptions& opt) {
  const int found = static_cast<int>(out.markers.size());
  char b[200];
  std::snprintf(b, sizeof(b), "found %d marker%s (threshold %.0f HU, diameter %.2f mm)", found,
                found == 1 ? "" : "s", opt.threshold_hu, opt.diameter_mm);
  std::string msg = b;
  if (opt.expected_count > 0) msg += ", expected " + std::to_string(opt.expected_count);
  if (found > 0) {
    msg += "; found at";
    for (const auto& m : out.markers) msg += " " + Mm2(m.centre_mm);
  }
  if (!out.rejected.empty()) {
    msg += "; rejected " + std::to_string(out.rejected.size()) + " component(s):";
    int shown = 0;
    for (const auto& r : out.rejected) {
      if (shown++ == 5) {
        msg += " ...";
        break;
      }
      msg += " " + Mm2(r.centroid_mm) + " " + r.reason + ";";
    }
  }
  return Status::Error(msg);
}

}  // namespace

StatusOr<MarkerDetection> DetectMarkers(const CtVolume& vol,
                                        const MarkerDetectionOptions& opt) {
  std::string error;
  if (!opt.Check(&error)) return Status::Error("marker detection options: " + error);
  const size_t n = vol.hu.size();
  if (n == 0 || n != static_cast<size_t>(vol.columns) * vol.rows * vol.slices) {
    return Status::Error("marker detection: empty or inconsistent CT volume");
  }
  auto core = ThresholdCore(vol, opt);
  if (!core.ok()) return core.status();
  MarkerDetection out;
  out.core_voxels = static_cast<int>(core->size());
  ScannerClip(vol, opt, *core, &out);
  const double min_peak_fraction = MinPeakFraction(vol, 0.5 * opt.diameter_mm);
  std::vector<DetectedMarker> accepted;
  for (const std::vector<int>& members : CoreComponents(vol, *core)) {
    DetectInComponent(vol, opt, *core, members, min_peak_fraction, &accepted, &out);
  }
  KeepDistinctMarkers(accepted, 0.5 * opt.diameter_mm, &out);
  const int found = static_cast<int>(out.markers.size());
  if (found == 0 || (opt.expected_count > 0 && found != opt.expected_count))
    return CountError(out, opt);
  return out;
}

}  // namespace carmba
