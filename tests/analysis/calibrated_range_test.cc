// Answers that leave the calibrated range say so (analysis/calibrated_range.h): object views at
// C-arm angles the smooth model's plate views did not cover, and object views far nearer than the
// plate views; views inside the range say nothing.
#include <gtest/gtest.h>

#include "analysis/calibrated_range.h"
#include "analysis/flex_models.h"
#include "synthetic/synthetic_joint.h"
#include "synthetic/synthetic_flex.h"

namespace carmba {
namespace analysis {
namespace {

bool Names(const std::vector<std::string>& warnings, const std::string& view) {
  for (const auto& w : warnings) {
    if (w.find("'" + view + "'") != std::string::npos) return true;
  }
  return false;
}

TEST(CalibratedRange, ObjectViewsOutsideTheSmoothModelsAnglesAreNamed) {
  // A C-arm calibrated along its orbit only (every plate view at secondary 0), object views at
  // secondary 0 and +-15 deg.
  ba::SyntheticFlexSpec spec;
  spec.plate_orientations_deg = {{-90, 0}, {-45, 0}, {0, 0}, {45, 0}, {90, 0}};
  spec.plate_views_per_orientation = 4;
  spec.object_orientations_deg = {{0, 0}, {45, 0}, {20, 15}, {0, -15}, {120, 0}};
  ba::SyntheticFlex sf = ba::MakeSyntheticFlex(spec, 3);
  ba::SmoothBasis basis;
  basis.secondary_degree = 0;
  ASSERT_TRUE(ApplyIntrinsicsModel(IntrinsicsModel::kSmooth, basis, &sf.problem).ok());
  auto r = ba::SolveBundleAdjustment(sf.problem, ba::BaOptions());
  ASSERT_TRUE(r.ok()) << r.status().message();
  const auto w = CalibratedRangeWarnings(sf.problem, *r);
  int outside = 0;
  for (const auto& v : sf.problem.views) {
    if (v.kind != ba::ViewKind::kObject) continue;
    const bool expect = v.secondary_deg != 0 || v.primary_deg > 90;
    EXPECT_EQ(Names(w, v.id), expect) << v.id;
    outside += expect;
  }
  EXPECT_EQ(outside, 3);
  ASSERT_FALSE(w.empty());
  EXPECT_NE(w[0].find("outside the calibrated angles of the smooth intrinsics model (plate views "
                      "at primary -90..90 deg, secondary 0..0 deg)"),
            std::string::npos)
      << w[0];
}

TEST(CalibratedRange, ObjectViewsFarNearerThanThePlateAreNamed) {
  for (const double distance : {700.0, 420.0}) {
    ba::SyntheticJointSpec spec;
    spec.object_distance_mm = distance;
    const ba::SyntheticJoint sj = ba::MakeSyntheticJoint(spec, ba::NoiseSwitches(), 11);
    auto r = ba::SolveBundleAdjustment(sj.problem, ba::BaOptions());
    ASSERT_TRUE(r.ok()) << r.status().message();
    const auto w = CalibratedRangeWarnings(sj.problem, *r);
    int named = 0;
    for (const auto& v : sj.problem.views)
      named += v.kind == ba::ViewKind::kObject && Names(w, v.id);
    if (distance == 700.0) {
      EXPECT_TRUE(w.empty()) << w.front();
    } else {
      EXPECT_EQ(named, 7);
      EXPECT_NE(w.front().find("much nearer than the plate views that calibrated it"),
                std::string::npos)
          << w.front();
    }
  }
}

}  // namespace
}  // namespace analysis
}  // namespace carmba
