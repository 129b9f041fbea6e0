// Synthetic calibration observations: a grid seen by a known camera from random tilted poses,
// with seeded Gaussian pixel noise. Used by the tests, the Monte Carlo checks and the benchmark
// (the simulator renders images; this projects with the camera model only).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "camera/camera_model.h"
#include "detect/observations.h"
#include "geometry/pose.h"

namespace carmba {

struct SyntheticViewsOptions {
  int num_views = 16;
  double noise_sigma_px = 0.3;
  double max_tilt_deg = 30;        // plate tilt, uniform in [min, max] about a random in-plane axis
  double min_tilt_deg = 5;
  double distance_min_mm = 650;    // plate centre distance from the source
  double distance_max_mm = 850;
  double max_offset_fraction = 0.6;  // plate centre offset from the axis, fraction of the half FOV
  uint64_t seed = 1;
};

// Returns observations of every grid point in every view (views with a point outside the image
// are redrawn). `cam_from_plate` (optional) receives the true poses.
ObservationSet MakeSyntheticViews(const std::array<double, kNumIntrinsics>& intrinsics,
                                  int width,
                                  int height,
                                  const GridSpec& grid,
                                  const SyntheticViewsOptions& options,
                                  std::vector<Pose6>* cam_from_plate = nullptr);

// Re-draws the noise of `clean` (noise-free observations) with a new seed.
ObservationSet AddNoise(const ObservationSet& clean, double sigma_px, uint64_t seed);

}  // namespace carmba
