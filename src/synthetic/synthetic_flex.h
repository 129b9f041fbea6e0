// A synthetic joint problem on a FLEXING C-arm (issue 14), for the engine's tests, Monte Carlo
// checks and the flex study: the geometry of synthetic/synthetic_joint.h (5x5 plate at ~700 mm with
// tilts up to 30 deg, the thesis's 9-marker object), but every view has C-arm angles and its own
// true intrinsics from a CarmFlex (camera/carm_flex.h). Plate views are taken at a few calibrated
// orientations, `plate_views_per_orientation` each; object views at and between them. The problem
// comes with ONE shared group whose initial intrinsics are the truth at (0, 0); apply an
// intrinsics model (analysis/flex_models.h) before solving. Deterministic for (geometry_seed,
// seed).
#pragma once

#include <array>
#include <cstdint>
#include <utility>
#include <vector>

#include "synthetic/synthetic_joint.h"
#include "camera/carm_flex.h"

namespace carmba {
namespace ba {

struct SyntheticFlexSpec {
  std::array<double, kNumIntrinsics> intrinsics{2000, 2010, 205, 200, 0.08, 0, 0, 0, 0};
  std::array<bool, kNumIntrinsics> free{true, true, true, true, true, false, false, false, false};
  CarmFlex flex = CarmFlex::Typical();
  // (primary, secondary) deg of the plate views' orientation groups.
  std::vector<std::pair<double, double>> plate_orientations_deg{
      {-90, 0}, {-45, 0}, {0, 0}, {45, 0}, {90, 0}, {0, -25}, {0, 25}};
  int plate_views_per_orientation = 6;
  // Object views: at calibrated orientations and between them.
  std::vector<std::pair<double, double>> object_orientations_deg{
      {0, 0}, {45, 0}, {-22.5, 0}, {67.5, 0}, {20, 12}};
  double sigma_plate_px = 0.05;
  double sigma_object_px = 0.2;
  double sigma_ct_mm = 0.2;
  uint64_t geometry_seed = 1;
};

struct SyntheticFlex {
  BaProblem problem;  // one shared group (truth at (0, 0)), views with angles
  std::vector<std::array<double, kNumIntrinsics>> true_intrinsics;  // per view
  std::vector<Pose6> true_poses;                                    // per view
  std::vector<bool> between;  // per view: an object view at an angle without plate views
};

SyntheticFlex MakeSyntheticFlex(const SyntheticFlexSpec& spec, uint64_t seed);

}  // namespace ba
}  // namespace carmba
