// Synthetic pose problems with ground truth, for Monte Carlo tests, benchmarks and studies (the
// fixtures of src/synthetic/ are not part of the core library).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <utility>
#include <vector>

#include "problem/pose_solver.h"

namespace carmba {

// A synthetic problem with ground truth, for Monte Carlo tests and studies: the markers of
// `spec.markers` (object frame, mm), views at C-arm angles rotating about the object's axis,
// observations projected through `spec.camera` with Gaussian pixel noise sigma_px, marker
// measurements with Gaussian CT noise sigma_ct_mm. Deterministic for a seed.
struct SyntheticPoseSpec {
  Camera camera;
  std::vector<Eigen::Vector3d> markers;          // true positions, object frame
  std::vector<double> view_angles_deg = {0, 10, 30, 50, 90};
  double source_to_object_mm = 700;              // distance of the object centre from the source
  Eigen::Vector3d rotation_axis = Eigen::Vector3d(0, 1, 0);  // C-arm axis in the first camera
  Eigen::Vector3d base_rvec = Eigen::Vector3d(0.3, -0.4, 0.2);
  std::vector<std::pair<int, int>> pairs = {{0, 1}, {0, 4}, {2, 3}};  // view indices
};
Problem MakeSyntheticPoseProblem(const SyntheticPoseSpec& spec,
                                 double sigma_px,
                                 double sigma_ct_mm,
                                 uint64_t seed);

// The 9 markers of the thesis's object (Table 5.1, object frame), for synthetic problems.
std::vector<Eigen::Vector3d> ThesisMarkers();

}  // namespace carmba
