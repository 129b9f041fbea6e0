// A synthetic joint problem with ground truth (ba/problem.h), for the engine's tests, the Monte
// Carlo checks of covariance and error budget, benchmarks and studies: one C-arm with true
// OPENCV5 intrinsics, plate views of a sphere grid at random tilts and distances, object views of
// the thesis's 9-marker object at C-arm rotations, CT marker measurements.
//
// Each noise source can be switched on alone (the budget's Monte Carlo): plate pixel noise,
// object pixel noise, CT localisation noise, plate manufacturing noise (the true plate differs
// from the nominal grid; only meaningful with plate.free), intrinsics prior noise (the prior's
// mean differs from the truth by a draw from its covariance), considered calibration noise (the
// held intrinsics differ from the truth by a draw from their covariance). Initial values are the
// truth: the Monte Carlo measures the estimator, not the initialiser. Deterministic for a seed: the
// geometry comes from `spec.geometry_seed`, the noise from `seed`.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "ba/problem.h"

namespace carmba {
namespace ba {

struct SyntheticJointSpec {
  std::array<double, kNumIntrinsics> intrinsics{2000, 2010, 205, 200, 0.08, 0, 0, 0, 0};
  std::array<bool, kNumIntrinsics> free{true, true, true, true, true, true, false, false, false};
  int width = 408, height = 408;
  int plate_rows = 5, plate_cols = 5;
  double plate_spacing_mm = 20;
  int num_plate_views = 20;
  double plate_distance_mm = 700;   // source to plate centre (+-10 %)
  double plate_max_tilt_deg = 30;
  std::vector<double> object_angles_deg{0, 10, 30, 50, 90, -20, 70};
  double object_distance_mm = 700;
  double sigma_plate_px = 0.05;
  double sigma_object_px = 0.2;
  double sigma_ct_mm = 0.2;
  bool plate_free = false;
  double sigma_plate_mm = 0.01;     // manufacturing tolerance (with plate_free)
  bool intrinsics_prior = false;    // a prior on fx, fy, cx, cy
  std::array<double, 4> prior_sigma{5, 5, 2, 2};  // px
  // Considered calibration: held intrinsics (`free` false) with this covariance
  // (IntrinsicsGroup::consider_*); with the calibration noise on, the values they are held at
  // are the truth plus a draw from it (an earlier calibration's error). Drawn after all else.
  std::vector<int> consider_indices;
  Eigen::MatrixXd consider_covariance;
  // > 1: each object observation gets its own 2x2 pixel covariance (BaView::obs_covariance_px2):
  // sigma_object_px^2 R diag(ratio, 1/ratio) R^T with a random orientation R per observation
  // (from the geometry seed), and pixel noise drawn from it.
  double object_px_anisotropy = 1.0;
  uint64_t geometry_seed = 1;
};

struct NoiseSwitches {
  bool plate_px = true, object_px = true, ct = true, plate_mfg = true, prior = true,
       calibration = true;
  static NoiseSwitches Only(Source s);
};

struct SyntheticJoint {
  BaProblem problem;                               // initial values = truth
  std::array<double, kNumIntrinsics> true_intrinsics{};
  std::vector<Pose6> true_poses;                   // per view, problem order
  std::vector<Eigen::Vector3d> true_markers;       // problem.markers order
  std::vector<std::pair<int, int>> pairs;          // object-view index pairs for validation
};

SyntheticJoint MakeSyntheticJoint(const SyntheticJointSpec& spec,
                                  const NoiseSwitches& noise,
                                  uint64_t seed);

// The 9 markers of the thesis's object (Table 5.1, object frame, mm).
std::vector<Eigen::Vector3d> ThesisObjectMarkers();

}  // namespace ba
}  // namespace carmba
