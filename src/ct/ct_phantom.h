// A voxelised CT phantom: spherical metal markers in a rectangular block, in air.
//
// Model. Each voxel's value is the mean over the voxel's extent (a box of spacing_mm[0] x
// spacing_mm[1] x slice thickness along the volume's axes, centred at the voxel centre) of the
// material HU at each point: marker_hu inside any sphere, else block_hu inside the block, else
// air_hu (partial volume). The mean is exact for voxels that lie wholly in one material
// (decided from the distance of the voxel centre to every surface against the voxel's
// half-diagonal) and is estimated by S x S x S supersampling (regular sub-grid of sample
// centres) for voxels cut by a surface. Then independent Gaussian noise of sigma noise_hu is
// added to every voxel (white noise: real CT noise is correlated between neighbours, which is not
// modelled; streaks near metal are, optionally: AddMetalStreaks). The random stream of slice k is
// seeded from (seed, k), so a volume is the same for the same seed whatever the slice count.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "ct/ct_volume.h"
#include "util/status.h"

namespace carmba {

struct CtMarker {
  int id = 0;
  Eigen::Vector3d centre_mm = Eigen::Vector3d::Zero();  // patient coordinates
};

struct CtPhantom {
  std::vector<CtMarker> markers;
  double marker_diameter_mm = 2.0;
  double marker_hu = 3000;  // steel within a 12-bit scanner's range (max 3071)
  bool has_block = true;
  Eigen::Vector3d block_min_mm = Eigen::Vector3d::Zero();  // axis-aligned in patient coordinates
  Eigen::Vector3d block_max_mm = Eigen::Vector3d::Zero();
  double block_hu = 100;   // a plastic such as PMMA is ~ +120 HU
  double air_hu = -1000;

  bool Check(std::string* error) const;
};

struct CtVoxeliseOptions {
  int marker_supersampling = 8;  // S for voxels cut by a sphere surface
  int block_supersampling = 4;   // S for voxels cut only by a block face
  double noise_hu = 20;          // sigma of the white Gaussian noise, HU (0: noiseless)
  // Metal artefacts (0: none): the amplitude, HU, at a marker's surface in a slice through its
  // centre, of the streaks a reconstruction puts around metal (AddMetalStreaks).
  double metal_streak_hu = 0;
  // The scanner's point-spread function (0: none): a Gaussian of this sigma (mm, along every
  // axis) blurs the noisy volume before the streaks (the noise becomes correlated); with metal
  // above clip_hu the clipped region grows past the sphere: blooming.
  double psf_sigma_mm = 0;
  // The scanner's largest value (0: none): every voxel above it is set to it, last (a 12-bit
  // scanner stores at most 3071 HU; steel is far above).
  double clip_hu = 0;
  uint64_t seed = 1;

  bool Check(std::string* error) const;
};

// Fills volume->hu for the geometry already set in *volume (columns, rows, slices, origin_mm,
// axes, spacing_mm, slice_thickness_mm; thickness 0 means equal to the slice spacing).
Status VoxelisePhantom(const CtPhantom& phantom,
                       const CtVoxeliseOptions& options,
                       CtVolume* volume);

// Adds a model of the metal artefacts of filtered back-projection to each slice (the volume's
// k planes) that cuts a marker: photon starvation and beam hardening along the rays through
// metal. Per marker, 16 straight streaks along lines through its centre (a projection ray through
// the metal, both sides) in seeded random directions, alternately bright and dark, each a Gaussian
// profile 0.6 mm wide across and decaying as exp(-d / 25 mm) with the distance d from the
// marker's surface, of amplitude metal_streak_hu x the marker's chord fraction in the slice
// (sqrt(1 - (dz / r)^2)); between two markers cut by the same slice, a dark band (beam hardening
// between metal) of half that amplitude, 1 mm wide. Voxels inside a marker are left alone. The
// streaks of a marker are seeded from (seed, marker index), so they do not depend on the others.
// Called by VoxelisePhantom and EmbedMarkers when options.metal_streak_hu > 0.
void AddMetalStreaks(const std::vector<CtMarker>& markers,
                     double diameter_mm,
                     const CtVoxeliseOptions& options,
                     CtVolume* volume);

// The scanner effects of CtVoxeliseOptions applied after the voxels and their noise: the PSF blur
// (psf_sigma_mm), the streaks (metal_streak_hu, AddMetalStreaks), the clip (clip_hu). Called by
// VoxelisePhantom and EmbedMarkers.
void AddScannerEffects(const std::vector<CtMarker>& markers,
                       double diameter_mm,
                       const CtVoxeliseOptions& options,
                       CtVolume* volume);

// Embeds spherical markers into an existing volume (a real CT as the background): each voxel
// becomes (1 - f) v + f marker_hu + f n, where f is the fraction of the voxel's extent (as in
// VoxelisePhantom) inside any sphere, estimated by S x S x S supersampling for voxels cut by a
// surface, and n is Gaussian noise of sigma noise_hu (seeded per marker from options.seed; the
// background's own noise is kept in the (1 - f) part). A marker displaces what it overlaps.
Status EmbedMarkers(const std::vector<CtMarker>& markers,
                    double diameter_mm,
                    double marker_hu,
                    const CtVoxeliseOptions& options,
                    CtVolume* volume);

}  // namespace carmba
