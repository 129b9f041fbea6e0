// Beads embedded in the real skull CT of Debian's invesalius-examples (ct/ct_invesalius.h), for
// tests and measurements of marker detection and covariance on a real anatomical background.
//
// Placement (seeded, uniform over the volume with rejection, classified on the original scan):
//   "bone":  touching bone: the nearest voxel centre >= 500 HU is at r + 0.2 .. r + 1.0 mm from
//            the bead's centre (r the bead's radius), none nearer, the centre voxel < 300 HU;
//   "brain": no voxel >= 300 HU within r + 4 mm and none <= -300 HU within 12 mm (deep inside);
//   "soft":  no voxel >= 300 HU within r + 2.5 mm, none <= -300 HU within r + 2 mm, but air
//            (<= -300 HU) within 15 mm (superficial soft tissue: scalp, face, neck).
// Beads are at least 12 mm apart (so no bead's region of interest or shell sees another).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "ct/ct_invesalius.h"
#include "ct/ct_phantom.h"
#include "ct/ct_volume.h"

namespace carmba::testing {

struct SkullBead {
  Eigen::Vector3d centre_mm;
  std::string kind;  // "bone", "brain", "soft"
};

// The skull CT (read once), or null when invesalius-examples is not installed.
inline const CtVolume* SkullCt() {
  static const CtVolume* skull = [] () -> const CtVolume* {
    auto v = ReadInvesaliusVolume(kInvesaliusCraniumPath);
    if (!v.ok()) return nullptr;
    return new CtVolume(std::move(v).value());
  }();
  return skull;
}

inline std::vector<SkullBead> PlaceSkullBeads(const CtVolume& vol,
                                              uint64_t seed,
                                              double diameter_mm,
                                              int bone,
                                              int brain,
                                              int soft) {
  const double r = 0.5 * diameter_mm;
  std::mt19937_64 rng(seed);
  const Eigen::Vector3d h = vol.spacing_mm;
  const Eigen::Vector3d size_mm(vol.columns * h.x(), vol.rows * h.y(), vol.slices * h.z());
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<SkullBead> beads;
  int want[3] = {bone, brain, soft};
  const char* names[3] = {"bone", "brain", "soft"};
  constexpr double kMarginMm = 16;  // from the volume's faces
  constexpr double kReachMm = 15;   // neighbourhood examined
  for (int attempt = 0; attempt < 400000 && (want[0] + want[1] + want[2]) > 0; ++attempt) {
    Eigen::Vector3d idx;
    for (int a = 0; a < 3; ++a) {
      const double lo = kMarginMm / h[a], hi = (size_mm[a] - kMarginMm) / h[a] - 1;
      idx[a] = lo + u(rng) * (hi - lo);
    }
    const Eigen::Vector3d c = vol.PatientFromIndex(idx);
    bool far = true;
    for (const auto& b : beads) far = far && (b.centre_mm - c).norm() >= 12;
    if (!far) continue;
    const Eigen::Vector3i ci = idx.array().round().cast<int>();
    const double centre_hu = vol.At(ci.x(), ci.y(), ci.z());
    if (centre_hu > 300 || centre_hu < -300) continue;
    double d_bone = 1e9, d_dense = 1e9, d_air = 1e9;  // nearest >= 300, >= 500, <= -300 HU
    int reach[3];
    for (int a = 0; a < 3; ++a) reach[a] = static_cast<int>(std::ceil(kReachMm / h[a]));
    for (int k = ci.z() - reach[2]; k <= ci.z() + reach[2]; ++k) {
      for (int j = ci.y() - reach[1]; j <= ci.y() + reach[1]; ++j) {
        for (int i = ci.x() - reach[0]; i <= ci.x() + reach[0]; ++i) {
          if (i < 0 || j < 0 || k < 0 || i >= vol.columns || j >= vol.rows || k >= vol.slices) {
            continue;
          }
          const double v = vol.At(i, j, k);
          if (v < 300 && v > -300) continue;
          const double d = (vol.PatientFromIndex(Eigen::Vector3d(i, j, k)) - c).norm();
          if (v >= 300) {
            d_bone = std::min(d_bone, d);
            if (v >= 500) d_dense = std::min(d_dense, d);
          } else {
            d_air = std::min(d_air, d);
          }
        }
      }
    }
    int kind = -1;
    if (d_dense >= r + 0.2 && d_dense <= r + 1.0 && d_bone >= r) {
      kind = 0;
    } else if (d_bone > r + 4 && d_air > 12) {
      kind = 1;
    } else if (d_bone > r + 2.5 && d_air > r + 2 && d_air <= 15) {
      kind = 2;
    }
    if (kind < 0 || want[kind] == 0) continue;
    --want[kind];
    beads.push_back({c, names[kind]});
  }
  return beads;
}

// A copy of `skull` with the beads embedded (steel at `marker_hu`, partial volume, noise; metal
// streaks of `metal_streak_hu` at the surface when > 0, ct/ct_phantom.h AddMetalStreaks).
inline CtVolume SkullWithBeads(const CtVolume& skull,
                               const std::vector<SkullBead>& beads,
                               double diameter_mm,
                               double marker_hu,
                               double noise_hu,
                               uint64_t seed,
                               double metal_streak_hu = 0) {
  CtVolume v = skull;
  std::vector<CtMarker> markers;
  for (size_t a = 0; a < beads.size(); ++a) {
    markers.push_back(CtMarker{static_cast<int>(a) + 1, beads[a].centre_mm});
  }
  CtVoxeliseOptions opt;
  opt.noise_hu = noise_hu;
  opt.seed = seed;
  opt.marker_supersampling = 8;
  opt.metal_streak_hu = metal_streak_hu;
  const Status s = EmbedMarkers(markers, diameter_mm, marker_hu, opt, &v);
  if (!s.ok()) v.hu.clear();
  return v;
}

}  // namespace carmba::testing
