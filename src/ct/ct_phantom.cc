#include "ct/ct_phantom.h"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>
#include <random>

#include "util/random.h"

namespace carmba {

bool CtPhantom::Check(std::string* error) const {
  if (!(marker_diameter_mm > 0) || !std::isfinite(marker_diameter_mm)) {
    *error = "marker diameter must be > 0 mm";
    return false;
  }
  for (const auto& m : markers) {
    if (!m.centre_mm.allFinite()) {
      *error = "marker " + std::to_string(m.id) + " has a non-finite centre";
      return false;
    }
  }
  if (!std::isfinite(marker_hu) || !std::isfinite(block_hu) || !std::isfinite(air_hu)) {
    *error = "HU values must be finite";
    return false;
  }
  if (has_block && !(block_max_mm.array() > block_min_mm.array()).all()) {
    *error = "the block must have a positive size along x, y and z";
    return false;
  }
  return true;
}

bool CtVoxeliseOptions::Check(std::string* error) const {
  if (marker_supersampling < 1 || marker_supersampling > 32 || block_supersampling < 1 ||
      block_supersampling > 32) {
    *error = "supersampling must be between 1 and 32";
    return false;
  }
  if (!(noise_hu >= 0) || !std::isfinite(noise_hu)) {
    *error = "noise must be >= 0 HU";
    return false;
  }
  if (!(metal_streak_hu >= 0) || !(metal_streak_hu <= 10000)) {
    *error = "metal_streak_hu must be 0 .. 10000 HU";
    return false;
  }
  if (!(psf_sigma_mm >= 0) || !(psf_sigma_mm <= 10)) {
    *error = "psf_sigma_mm must be 0 .. 10 mm";
    return false;
  }
  if (!(clip_hu >= 0) || !(clip_hu <= 32767)) {
    *error = "clip_hu must be 0 (none) .. 32767 HU";
    return false;
  }
  return true;
}

namespace {

// Signed distance from p to the surface of an axis-aligned box (negative inside).
double BoxSignedDistance(const Eigen::Vector3d& p,
                         const Eigen::Vector3d& centre,
                         const Eigen::Vector3d& half) {
  const Eigen::Vector3d q = (p - centre).cwiseAbs() - half;
  const double outside = q.cwiseMax(0.0).norm();
  const double inside = std::min(q.maxCoeff(), 0.0);
  return outside + inside;
}

}  // namespace

Status VoxelisePhantom(const CtPhantom& phantom,
                       const CtVoxeliseOptions& options,
                       CtVolume* volume) {
  std::string error;
  if (!phantom.Check(&error)) return Status::Error("CT phantom: " + error);
  if (!options.Check(&error)) return Status::Error("CT voxelisation: " + error);
  CtVolume& v = *volume;
  if (v.columns <= 0 || v.rows <= 0 || v.slices <= 0 || !(v.spacing_mm.array() > 0).all()) {
    return Status::Error("CT voxelisation: empty volume or non-positive spacing");
  }
  const Eigen::Matrix3d A = v.PatientFromIndexLinear();
  if (std::abs(A.determinant()) < 1e-12) {
    return Status::Error("CT voxelisation: degenerate volume axes");
  }
  const Eigen::Matrix3d A_inv = A.inverse();
  const double thickness = v.slice_thickness_mm > 0 ? v.slice_thickness_mm : v.spacing_mm.z();
  // The voxel's extent along its axes (the k extent is the slice thickness).
  const Eigen::Vector3d extent(v.spacing_mm.x(), v.spacing_mm.y(), thickness);
  const double half_diag = 0.5 * extent.norm();
  const double radius = 0.5 * phantom.marker_diameter_mm;
  const Eigen::Vector3d block_centre = 0.5 * (phantom.block_min_mm + phantom.block_max_mm);
  const Eigen::Vector3d block_half = 0.5 * (phantom.block_max_mm - phantom.block_min_mm);

  // Index-space bounds of each marker's influence (conservative for sheared axes).
  struct Bound {
    Eigen::Vector3d c;
    int lo[3], hi[3];
  };
  std::vector<Bound> bounds;
  for (const auto& m : phantom.markers) {
    Bound b;
    b.c = m.centre_mm;
    const Eigen::Vector3d idx = A_inv * (m.centre_mm - v.origin_mm);
    for (int a = 0; a < 3; ++a) {
      const double r = A_inv.row(a).norm() * (radius + half_diag) + 1;
      b.lo[a] = static_cast<int>(std::floor(idx[a] - r));
      b.hi[a] = static_cast<int>(std::ceil(idx[a] + r));
    }
    bounds.push_back(b);
  }

  const Eigen::Vector3d X = v.axes.col(0), Y = v.axes.col(1), Z = v.axes.col(2);
  auto material_at = [&](const Eigen::Vector3d& p, const std::vector<const Bound*>& near) {
    for (const Bound* b : near) {
      if ((p - b->c).squaredNorm() <= radius * radius) return phantom.marker_hu;
    }
    if (phantom.has_block && BoxSignedDistance(p, block_centre, block_half) <= 0) {
      return phantom.block_hu;
    }
    return phantom.air_hu;
  };
  auto supersample = [&](const Eigen::Vector3d& p, int S, const std::vector<const Bound*>& near) {
    double sum = 0;
    for (int a = 0; a < S; ++a) {
      const double oa = ((a + 0.5) / S - 0.5) * extent.x();
      for (int b = 0; b < S; ++b) {
        const double ob = ((b + 0.5) / S - 0.5) * extent.y();
        for (int c = 0; c < S; ++c) {
          const double oc = ((c + 0.5) / S - 0.5) * extent.z();
          sum += material_at(p + oa * X + ob * Y + oc * Z, near);
        }
      }
    }
    return sum / (S * S * S);
  };

  v.hu.assign(static_cast<size_t>(v.columns) * v.rows * v.slices, 0.0f);
  std::vector<const Bound*> in_slice, in_row, near;
  for (int k = 0; k < v.slices; ++k) {
    in_slice.clear();
    for (const auto& b : bounds) {
      if (k >= b.lo[2] && k <= b.hi[2]) in_slice.push_back(&b);
    }
    Rng rng(options.seed * 0x9E3779B97F4A7C15ull + static_cast<uint64_t>(k));
    std::normal_distribution<float> noise(0.0f, static_cast<float>(options.noise_hu));
    for (int j = 0; j < v.rows; ++j) {
      in_row.clear();
      for (const Bound* b : in_slice) {
        if (j >= b->lo[1] && j <= b->hi[1]) in_row.push_back(b);
      }
      const Eigen::Vector3d row_start = v.PatientFromIndex(Eigen::Vector3d(0, j, k));
      const Eigen::Vector3d di = v.spacing_mm.x() * X;
      float* out = v.hu.data() + v.Index(0, j, k);
      for (int i = 0; i < v.columns; ++i) {
        const Eigen::Vector3d p = row_start + i * di;
        near.clear();
        bool sphere_edge = false, inside_sphere = false;
        for (const Bound* b : in_row) {
          if (i < b->lo[0] || i > b->hi[0]) continue;
          near.push_back(b);
          const double d = (p - b->c).norm();
          if (d < radius - half_diag) inside_sphere = true;
          else if (d <= radius + half_diag) sphere_edge = true;
        }
        double value;
        if (inside_sphere) {
          value = phantom.marker_hu;
        } else if (sphere_edge) {
          value = supersample(p, options.marker_supersampling, near);
        } else {
          const double sd = phantom.has_block ? BoxSignedDistance(p, block_centre, block_half)
                                              : 1e30;
          if (std::abs(sd) <= half_diag) {
            value = supersample(p, options.block_supersampling, near);
          } else {
            value = sd < 0 ? phantom.block_hu : phantom.air_hu;
          }
        }
        out[i] = static_cast<float>(value);
        if (options.noise_hu > 0) out[i] += noise(rng);
      }
    }
  }
  AddScannerEffects(phantom.markers, phantom.marker_diameter_mm, options, volume);
  return Status::Ok();
}

Status EmbedMarkers(const std::vector<CtMarker>& markers,
                    double diameter_mm,
                    double marker_hu,
                    const CtVoxeliseOptions& options,
                    CtVolume* volume) {
  std::string error;
  if (!options.Check(&error)) return Status::Error("CT marker embedding: " + error);
  if (!(diameter_mm > 0) || !std::isfinite(marker_hu)) {
    return Status::Error("CT marker embedding: diameter must be > 0 mm and HU finite");
  }
  CtVolume& v = *volume;
  if (v.hu.size() != static_cast<size_t>(v.columns) * v.rows * v.slices || v.hu.empty()) {
    return Status::Error("CT marker embedding: empty or inconsistent volume");
  }
  const Eigen::Matrix3d A = v.PatientFromIndexLinear();
  if (std::abs(A.determinant()) < 1e-12) {
    return Status::Error("CT marker embedding: degenerate volume axes");
  }
  const Eigen::Matrix3d A_inv = A.inverse();
  const double thickness = v.slice_thickness_mm > 0 ? v.slice_thickness_mm : v.spacing_mm.z();
  const Eigen::Vector3d extent(v.spacing_mm.x(), v.spacing_mm.y(), thickness);
  const double half_diag = 0.5 * extent.norm();
  const double radius = 0.5 * diameter_mm;
  const int S = options.marker_supersampling;
  const Eigen::Vector3d X = v.axes.col(0), Y = v.axes.col(1), Z = v.axes.col(2);
  const int dims[3] = {v.columns, v.rows, v.slices};
  for (size_t mi = 0; mi < markers.size(); ++mi) {
    const Eigen::Vector3d c = markers[mi].centre_mm;
    if (!c.allFinite()) return Status::Error("CT marker embedding: non-finite marker centre");
    const Eigen::Vector3d idx = A_inv * (c - v.origin_mm);
    int lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      const double r = A_inv.row(a).norm() * (radius + half_diag) + 1;
      lo[a] = std::max(0, static_cast<int>(std::floor(idx[a] - r)));
      hi[a] = std::min(dims[a] - 1, static_cast<int>(std::ceil(idx[a] + r)));
    }
    Rng rng(options.seed * 0x9E3779B97F4A7C15ull + 0x51ED2701ull * (mi + 1));
    std::normal_distribution<double> noise(0.0, options.noise_hu);
    for (int k = lo[2]; k <= hi[2]; ++k) {
      for (int j = lo[1]; j <= hi[1]; ++j) {
        for (int i = lo[0]; i <= hi[0]; ++i) {
          const Eigen::Vector3d p = v.PatientFromIndex(Eigen::Vector3d(i, j, k));
          const double d = (p - c).norm();
          double f = 0;
          if (d < radius - half_diag) {
            f = 1;
          } else if (d <= radius + half_diag) {
            int inside = 0;
            for (int a = 0; a < S; ++a) {
              const double oa = ((a + 0.5) / S - 0.5) * extent.x();
              for (int b = 0; b < S; ++b) {
                const double ob = ((b + 0.5) / S - 0.5) * extent.y();
                for (int e = 0; e < S; ++e) {
                  const double oc = ((e + 0.5) / S - 0.5) * extent.z();
                  inside += (p + oa * X + ob * Y + oc * Z - c).squaredNorm() <= radius * radius;
                }
              }
            }
            f = static_cast<double>(inside) / (S * S * S);
          }
          if (f <= 0) continue;
          float& out = v.hu[v.Index(i, j, k)];
          const double n = options.noise_hu > 0 ? noise(rng) : 0.0;
          out = static_cast<float>((1 - f) * out + f * marker_hu + f * n);
        }
      }
    }
  }
  AddScannerEffects(markers, diameter_mm, options, volume);
  return Status::Ok();
}

namespace {

// Separable Gaussian blur of sigma `sigma_mm` along each volume axis (truncated at 3 sigma,
// renormalised at the borders).
void GaussianBlur(double sigma_mm, CtVolume* v) {
  const int dims[3] = {v->columns, v->rows, v->slices};
  const size_t strides[3] = {1, static_cast<size_t>(v->columns),
                             static_cast<size_t>(v->columns) * v->rows};
  std::vector<float> line;
  for (int a = 0; a < 3; ++a) {
    const double s = sigma_mm / v->spacing_mm[a];
    const int half = static_cast<int>(std::ceil(3 * s));
    if (half < 1) continue;
    std::vector<double> w(2 * half + 1);
    for (int t = -half; t <= half; ++t) w[t + half] = std::exp(-0.5 * t * t / (s * s));
    const int b1 = (a + 1) % 3, b2 = (a + 2) % 3;
    line.resize(dims[a]);
    for (int q2 = 0; q2 < dims[b2]; ++q2) {
      for (int q1 = 0; q1 < dims[b1]; ++q1) {
        const size_t base = q1 * strides[b1] + q2 * strides[b2];
        for (int t = 0; t < dims[a]; ++t) line[t] = v->hu[base + t * strides[a]];
        for (int t = 0; t < dims[a]; ++t) {
          double sum = 0, sw = 0;
          for (int u = std::max(0, t - half); u <= std::min(dims[a] - 1, t + half); ++u) {
            sum += w[u - t + half] * line[u];
            sw += w[u - t + half];
          }
          v->hu[base + t * strides[a]] = static_cast<float>(sum / sw);
        }
      }
    }
  }
}

}  // namespace

void AddScannerEffects(const std::vector<CtMarker>& markers,
                       double diameter_mm,
                       const CtVoxeliseOptions& options,
                       CtVolume* volume) {
  if (options.psf_sigma_mm > 0) GaussianBlur(options.psf_sigma_mm, volume);
  AddMetalStreaks(markers, diameter_mm, options, volume);
  if (options.clip_hu > 0) {
    const float clip = static_cast<float>(options.clip_hu);
    for (float& x : volume->hu) x = std::min(x, clip);
  }
}

void AddMetalStreaks(const std::vector<CtMarker>& markers,
                     double diameter_mm,
                     const CtVoxeliseOptions& options,
                     CtVolume* volume) {
  if (!(options.metal_streak_hu > 0) || markers.empty()) return;
  CtVolume& v = *volume;
  const double radius = 0.5 * diameter_mm;
  constexpr int kStreaks = 16;
  constexpr double kWidthMm = 0.6, kDecayMm = 25, kBandWidthMm = 1.0;
  const double reach = 3 * kDecayMm;  // exp(-3): 5 % of the amplitude
  const Eigen::Vector3d X = v.axes.col(0).normalized(), Y = v.axes.col(1).normalized();
  const Eigen::Vector3d N = X.cross(Y).normalized();
  const double sx = v.spacing_mm.x(), sy = v.spacing_mm.y();
  // The streaks' directions (unit vectors in the slice plane) and signs, per marker.
  std::vector<std::array<Eigen::Vector2d, kStreaks>> dirs(markers.size());
  for (size_t m = 0; m < markers.size(); ++m) {
    Rng rng(options.seed * 0xD1B54A32D192ED03ull + 0x8CB92BA72F3D8DD7ull * (m + 1));
    std::uniform_real_distribution<double> u(0, 2 * M_PI);
    for (int s = 0; s < kStreaks; ++s) {
      const double a = u(rng);
      dirs[m][s] = Eigen::Vector2d(std::cos(a), std::sin(a));
    }
  }
  std::vector<float> add;
  std::vector<char> metal;
  for (int k = 0; k < v.slices; ++k) {
    // The markers this slice cuts: in-plane centre (mm along X, Y from the slice's first voxel)
    // and chord fraction.
    const Eigen::Vector3d origin = v.PatientFromIndex(Eigen::Vector3d(0, 0, k));
    struct Cut {
      size_t m;
      Eigen::Vector2d c;
      double w;
    };
    std::vector<Cut> cuts;
    for (size_t m = 0; m < markers.size(); ++m) {
      const Eigen::Vector3d d = markers[m].centre_mm - origin;
      const double dz = d.dot(N);
      if (std::abs(dz) >= radius) continue;
      cuts.push_back({m, Eigen::Vector2d(d.dot(X), d.dot(Y)),
                      std::sqrt(1 - (dz / radius) * (dz / radius))});
    }
    if (cuts.empty()) continue;
    add.assign(static_cast<size_t>(v.rows) * v.columns, 0.f);
    metal.assign(add.size(), 0);
    // The voxel index box of a disc of radius r around c (in-plane mm).
    auto box = [&](const Eigen::Vector2d& lo_mm, const Eigen::Vector2d& hi_mm, int* i0, int* i1,
                   int* j0, int* j1) {
      *i0 = std::max(0, static_cast<int>(std::floor(lo_mm.x() / sx)));
      *i1 = std::min(v.columns - 1, static_cast<int>(std::ceil(hi_mm.x() / sx)));
      *j0 = std::max(0, static_cast<int>(std::floor(lo_mm.y() / sy)));
      *j1 = std::min(v.rows - 1, static_cast<int>(std::ceil(hi_mm.y() / sy)));
    };
    for (const Cut& c : cuts) {
      const double amplitude = c.w * options.metal_streak_hu;
      int i0, i1, j0, j1;
      box(c.c.array() - reach, c.c.array() + reach, &i0, &i1, &j0, &j1);
      for (int j = j0; j <= j1; ++j) {
        for (int i = i0; i <= i1; ++i) {
          const Eigen::Vector2d q = Eigen::Vector2d(i * sx, j * sy) - c.c;
          const double d = q.norm();
          const size_t idx = static_cast<size_t>(j) * v.columns + i;
          if (d <= radius) {
            metal[idx] = 1;
            continue;
          }
          if (d > reach) continue;
          double sum = 0;
          for (int s = 0; s < kStreaks; ++s) {
            const Eigen::Vector2d& u = dirs[c.m][s];
            const double across = std::abs(q.x() * u.y() - q.y() * u.x());
            if (across > 4 * kWidthMm) continue;
            sum += (s % 2 == 0 ? 1.0 : -1.0) *
                   std::exp(-0.5 * (across / kWidthMm) * (across / kWidthMm));
          }
          if (sum != 0)
            add[idx] += static_cast<float>(amplitude * std::exp(-(d - radius) / kDecayMm) * sum);
        }
      }
    }
    for (size_t a = 0; a < cuts.size(); ++a) {
      for (size_t b = a + 1; b < cuts.size(); ++b) {
        const Eigen::Vector2d ab = cuts[b].c - cuts[a].c;
        const double len = ab.norm();
        if (len <= 2 * radius) continue;
        const double amplitude = 0.5 * std::min(cuts[a].w, cuts[b].w) * options.metal_streak_hu;
        const double margin = 4 * kBandWidthMm;
        int i0, i1, j0, j1;
        box(cuts[a].c.cwiseMin(cuts[b].c).array() - margin,
            cuts[a].c.cwiseMax(cuts[b].c).array() + margin, &i0, &i1, &j0, &j1);
        for (int j = j0; j <= j1; ++j) {
          for (int i = i0; i <= i1; ++i) {
            const Eigen::Vector2d q = Eigen::Vector2d(i * sx, j * sy) - cuts[a].c;
            const double t = q.dot(ab) / (len * len);
            if (t <= 0 || t >= 1) continue;
            const double across = std::abs(q.x() * ab.y() - q.y() * ab.x()) / len;
            if (across > margin) continue;
            add[static_cast<size_t>(j) * v.columns + i] -= static_cast<float>(
                amplitude * std::exp(-0.5 * (across / kBandWidthMm) * (across / kBandWidthMm)));
          }
        }
      }
    }
    for (int j = 0; j < v.rows; ++j) {
      for (int i = 0; i < v.columns; ++i) {
        const size_t idx = static_cast<size_t>(j) * v.columns + i;
        if (!metal[idx] && add[idx] != 0) v.hu[v.Index(i, j, k)] += add[idx];
      }
    }
  }
}

}  // namespace carmba
