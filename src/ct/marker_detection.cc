#include "ct/marker_detection.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <unordered_map>

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
  return true;
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

std::string V3(const Eigen::Vector3d& v) {
  char b[96];
  std::snprintf(b, sizeof(b), "(%.2f, %.2f, %.2f)", v.x(), v.y(), v.z());
  return b;
}

double Median(std::vector<double>* v) {
  const size_t m = v->size() / 2;
  std::nth_element(v->begin(), v->begin() + m, v->end());
  return (*v)[m];
}

// Refines one marker's centre (steps 4-5 of the header). Returns false if there is no contrast.
bool Refine(const CtVolume& vol,
            const MarkerDetectionOptions& opt,
            double core_radius_mm,
            DetectedMarker* m) {
  const Eigen::Vector3d h = vol.spacing_mm;
  const double thickness = vol.slice_thickness_mm > 0 ? vol.slice_thickness_mm : h.z();
  const Eigen::Vector3d e(h.x(), h.y(), thickness);  // voxel extent along the axes
  const double radius = std::max(0.5 * opt.diameter_mm, core_radius_mm);
  constexpr double kShellGapMm = 0.5;
  Eigen::Vector3d c = m->centre_index;
  std::vector<double> shell;
  std::vector<std::pair<Eigen::Vector3d, double>> roi;  // mm offset from c, HU
  double b = 0, sigma = 0, W = 0;
  for (int it = 0; it <= opt.iterations; ++it) {
    const double margin = opt.roi_margin_mm + (it == 0 ? 0.5 * e.maxCoeff() : 0.0);
    const double r_roi = radius + margin;
    const double r_outer = r_roi + kShellGapMm + opt.shell_mm;
    int lo[3], hi[3];
    const int dims[3] = {vol.columns, vol.rows, vol.slices};
    for (int a = 0; a < 3; ++a) {
      const double reach = (r_outer + 0.5 * e[a]) / h[a];
      lo[a] = std::max(0, static_cast<int>(std::floor(c[a] - reach)));
      hi[a] = std::min(dims[a] - 1, static_cast<int>(std::ceil(c[a] + reach)));
    }
    shell.clear();
    roi.clear();
    for (int k = lo[2]; k <= hi[2]; ++k) {
      for (int j = lo[1]; j <= hi[1]; ++j) {
        for (int i = lo[0]; i <= hi[0]; ++i) {
          const Eigen::Vector3d d((i - c.x()) * h.x(), (j - c.y()) * h.y(), (k - c.z()) * h.z());
          const Eigen::Vector3d gap = (d.cwiseAbs() - 0.5 * e).cwiseMax(0.0);
          const double dist = gap.norm();
          const double v = vol.At(i, j, k);
          if (dist <= r_roi) {
            roi.emplace_back(d, v);
          } else if (dist > r_roi + kShellGapMm && dist <= r_outer) {
            shell.push_back(v);
          }
        }
      }
    }
    if (shell.size() < 8 || roi.empty()) return false;
    b = Median(&shell);
    std::vector<double> dev(shell.size());
    for (size_t s = 0; s < shell.size(); ++s) dev[s] = std::abs(shell[s] - b);
    sigma = 1.4826 * Median(&dev);
    W = 0;
    Eigen::Vector3d moment = Eigen::Vector3d::Zero();
    for (const auto& [d, v] : roi) {
      W += v - b;
      moment += (v - b) * d;
    }
    if (!(W > 0)) return false;
    const Eigen::Vector3d shift_mm = moment / W;
    c += shift_mm.cwiseQuotient(h);
    if (it == opt.iterations) {
      // Covariance in the axis frame (offsets relative to the final centre).
      Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
      Eigen::Vector3d g = Eigen::Vector3d::Zero();
      for (const auto& [d, v] : roi) {
        const Eigen::Vector3d r = d - shift_mm;
        S += r * r.transpose();
        g += r;
      }
      g /= W;
      Eigen::Matrix3d noise = sigma * sigma * S / (W * W) +
                              sigma * sigma / static_cast<double>(shell.size()) * g *
                                  g.transpose();
      Eigen::Matrix3d sampling = Eigen::Matrix3d::Zero();
      for (int a = 0; a < 3; ++a) {
        sampling(a, a) = SamplingVarianceMm2(0.5 * opt.diameter_mm, h[a], e[a]);
      }
      m->covariance_noise_mm2 = vol.axes * noise * vol.axes.transpose();
      m->covariance_sampling_mm2 = vol.axes * sampling * vol.axes.transpose();
      m->covariance_mm2 = m->covariance_noise_mm2 + m->covariance_sampling_mm2;
    }
  }
  m->centre_index = c;
  m->centre_mm = vol.PatientFromIndex(c);
  m->background_hu = b;
  m->noise_hu = sigma;
  m->roi_voxels = static_cast<int>(roi.size());
  const double contrast = m->peak_hu - b;
  m->weight_volume_mm3 = contrast > 0 ? W * vol.VoxelVolumeMm3() / contrast : 0;
  return true;
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
  // 1. Threshold.
  const float thr = static_cast<float>(opt.threshold_hu);
  const size_t max_core = static_cast<size_t>(opt.max_core_fraction * n) + 1;
  std::vector<size_t> core;
  for (size_t v = 0; v < n; ++v) {
    if (vol.hu[v] >= thr) {
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
  }
  MarkerDetection out;
  out.core_voxels = static_cast<int>(core.size());
  // 2. 26-connected components.
  std::unordered_map<size_t, int> position;
  position.reserve(core.size() * 2);
  for (size_t p = 0; p < core.size(); ++p) position[core[p]] = static_cast<int>(p);
  UnionFind uf(static_cast<int>(core.size()));
  const size_t nx = vol.columns, nxy = static_cast<size_t>(vol.columns) * vol.rows;
  auto ijk = [&](size_t v) {
    const int k = static_cast<int>(v / nxy);
    const size_t r = v % nxy;
    return Eigen::Vector3i(static_cast<int>(r % nx), static_cast<int>(r / nx), k);
  };
  for (size_t p = 0; p < core.size(); ++p) {
    const Eigen::Vector3i q = ijk(core[p]);
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
  std::unordered_map<int, std::vector<int>> groups;
  std::vector<int> roots;
  for (size_t p = 0; p < core.size(); ++p) {
    const int r = uf.Find(static_cast<int>(p));
    if (!groups.count(r)) roots.push_back(r);
    groups[r].push_back(static_cast<int>(p));
  }
  // 3. Size and border filter; 4-5. centres.
  const double voxel_mm3 = vol.VoxelVolumeMm3();
  const double nominal_mm3 = M_PI / 6.0 * std::pow(opt.diameter_mm, 3);
  for (int r : roots) {
    const auto& members = groups[r];
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    Eigen::Vector3i lo = ijk(core[members[0]]), hi = lo;
    double peak = -1e30;
    for (int p : members) {
      const Eigen::Vector3i q = ijk(core[p]);
      sum += q.cast<double>();
      lo = lo.cwiseMin(q);
      hi = hi.cwiseMax(q);
      peak = std::max(peak, static_cast<double>(vol.hu[core[p]]));
    }
    const Eigen::Vector3d centroid = sum / members.size();
    const double volume = members.size() * voxel_mm3;
    RejectedComponent rej;
    rej.centroid_mm = vol.PatientFromIndex(centroid);
    rej.volume_mm3 = volume;
    rej.peak_hu = peak;
    rej.voxels = static_cast<int>(members.size());
    char why[160] = "";
    if (volume < opt.min_volume_fraction * nominal_mm3) {
      std::snprintf(why, sizeof(why), "too small: %.3f mm^3 < %.2f x %.3f mm^3", volume,
                    opt.min_volume_fraction, nominal_mm3);
    } else if (volume > opt.max_volume_fraction * nominal_mm3) {
      std::snprintf(why, sizeof(why), "too large: %.3f mm^3 > %.2f x %.3f mm^3", volume,
                    opt.max_volume_fraction, nominal_mm3);
    } else if (lo.minCoeff() == 0 || hi.x() == vol.columns - 1 || hi.y() == vol.rows - 1 ||
               hi.z() == vol.slices - 1) {
      std::snprintf(why, sizeof(why), "touches the border of the volume");
    }
    if (why[0]) {
      rej.reason = why;
      out.rejected.push_back(rej);
      continue;
    }
    DetectedMarker m;
    m.core_voxels = static_cast<int>(members.size());
    m.volume_mm3 = volume;
    m.peak_hu = peak;
    m.core_centroid_mm = vol.PatientFromIndex(centroid);
    m.bbox_centre_mm = vol.PatientFromIndex(0.5 * (lo + hi).cast<double>());
    m.centre_index = centroid;
    const double core_radius = std::cbrt(3.0 * volume / (4.0 * M_PI));
    if (!Refine(vol, opt, core_radius, &m)) {
      rej.reason = "no contrast against its surroundings (weighted mass <= 0) or no background";
      out.rejected.push_back(rej);
      continue;
    }
    m.id = static_cast<int>(out.markers.size()) + 1;
    out.markers.push_back(m);
  }
  const int found = static_cast<int>(out.markers.size());
  if (found == 0 || (opt.expected_count > 0 && found != opt.expected_count)) {
    char b[200];
    std::snprintf(b, sizeof(b), "found %d marker%s (threshold %.0f HU, diameter %.2f mm)", found,
                  found == 1 ? "" : "s", opt.threshold_hu, opt.diameter_mm);
    std::string msg = b;
    if (opt.expected_count > 0) msg += ", expected " + std::to_string(opt.expected_count);
    if (found > 0) {
      msg += "; found at";
      for (const auto& m : out.markers) msg += " " + V3(m.centre_mm);
    }
    if (!out.rejected.empty()) {
      msg += "; rejected " + std::to_string(out.rejected.size()) + " component(s):";
      int shown = 0;
      for (const auto& r : out.rejected) {
        if (shown++ == 5) {
          msg += " ...";
          break;
        }
        msg += " " + V3(r.centroid_mm) + " " + r.reason + ";";
      }
    }
    return Status::Error(msg);
  }
  return out;
}

}  // namespace carmba
