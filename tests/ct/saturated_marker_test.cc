// Saturated metal (ct/marker_detection.h 8.) on simulated CTs with a real scanner's effects
// (ct/ct_phantom.h): steel far above a 3071 HU clip, a Gaussian PSF (blooming), metal streaks,
// a plastic holder touching the sphere, a diameter known only roughly. Monte Carlo over the
// sphere's sub-voxel position, the noise and the streaks' directions: every sphere found, its
// centre's normalised squared error e^T C^-1 e consistent with the covariance. Contiguous slices
// and every other slice (the odd or even half of a real series).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "ct/ct_phantom.h"
#include "ct/ct_simulate.h"
#include "ct/marker_detection.h"
#include "figures.h"
#include "geometry/random_vector.h"
#include "test_env.h"

namespace carmba {
namespace {

struct Case {
  const char* name;
  const char* key;  // its figures in src/docs/results.md: saturated.KEY_found, _nees, _rms
  double psf_mm, streak_hu, holder_offset_mm, nominal_diameter_mm;
  // Between slices of 1.25 mm thickness: 1.25 (contiguous), 2.5 (every other slice, as the odd or
  // the even half of a series: the half-level edge across slices is interpolated over 2.5 mm).
  double slice_step_mm = 1.25;
  double marker_hu = 8000;  // steel, far above the clip
  double max_rms_mm = 0.15;  // bound on the centre error's RMS (mm)
  double min_nees = 0.3;     // lower bound on the NEES per dof (the upper is 2)
};

// Every sphere is found, contiguous or with gaps between the slices (without the axial radius's
// allowance for the slice step, 46, 42 and 17 of 60 were found every other slice at 20000 HU, at
// 3 mm and at 3.75 mm steps: the rest refused as "not a ball"). NEES per dof: 0.8-1.7 contiguous.
// With gaps the covariance covers both the simulated sampling term and the sector jackknife
// (ct/marker_detection.h 8.): 0.73, 0.84, 0.15, 0.31 and 0.51 on the five cases with gaps (the
// simulated term alone: 0.91, 1.03, 0.31, 0.32, 0.53; the analytic term alone: 1.34, 2.80, 0.40,
// 0.80, 0.62); on seeds not used while developing it (CARMBA_SATURATED_SEED=1234 and
// CARMBA_SATURATED_NOISE_SEED=90000: src/docs/results.md). Conservative where blur or a larger step
// smooths what a sharp simulated ball does not, and most with streaks across 3 mm steps (about 2.6x
// in sigma), where a streak moves one sector's edge: that case's lower bound is 0.1, the next two's
// 0.2.
std::vector<Case> Cases() {
  return {
      Case{"clip only", "clip", 0.0, 0, 100, 5.5},
      Case{"clip + blooming", "blooming", 0.5, 0, 100, 6},
      Case{"clip + blooming + streaks", "streaks", 0.5, 300, 100, 6},
      Case{"all + holder touching", "holder", 0.5, 300, 1.0, 7},
      Case{"all, every other slice", "gaps_2_5", 0.5, 300, 100, 6, 2.5, 8000, 0.35},
      Case{"clip only, 20000 HU, every other slice",
           "gaps_2_5_20000",
           0.0,
           0,
           100,
           5.5,
           2.5,
           20000,
           0.35},
      Case{"blooming + streaks, 12000 HU, 3 mm steps",
           "gaps_3",
           0.3,
           150,
           100,
           6,
           3.0,
           12000,
           0.5,
           0.1},
      Case{"more blooming, 5000 HU, 2 mm steps", "gaps_2", 0.7, 300, 100, 6, 2.0, 5000, 0.5, 0.2},
      Case{"clip only, 30000 HU, 3.75 mm steps",
           "gaps_3_75",
           0.0,
           0,
           100,
           5.5,
           3.75,
           30000,
           0.5,
           0.2}};
}

TEST(SaturatedMarker, FoundWithAConsistentCovarianceUnderClipBloomingStreaksAndHolder) {
  constexpr double kDiameterMm = 5.5, kClipHu = 3071;
  for (const Case& c : Cases()) {
    constexpr int kTrials = 60;
    // The spheres' positions and the CT noise: other seeds through the environment.
    std::mt19937_64 rng(testing::EnvOr<uint64_t>("CARMBA_SATURATED_SEED", 7));
    const int noise_seed = testing::EnvOr("CARMBA_SATURATED_NOISE_SEED", 500);
    std::uniform_real_distribution<double> u(-1, 1);
    int found = 0;
    double nees = 0, sq = 0, chi2_estimators = 0;
    for (int t = 0; t < kTrials; ++t) {
      CtPhantom ph;
      ph.marker_diameter_mm = kDiameterMm;
      ph.marker_hu = c.marker_hu;
      CtMarker mk;
      mk.id = 1;
      mk.centre_mm = RandomVector<3>(u, rng);
      ph.markers = {mk};
      // The holder: a plastic block whose top face is holder_offset_mm above the sphere's centre
      // (1 mm: the sphere sits in it, touching; 100: the block encloses it).
      ph.block_min_mm = Eigen::Vector3d(-14, -14, -14);
      ph.block_max_mm =
          Eigen::Vector3d(14, 14, std::min(14.0, mk.centre_mm.z() + c.holder_offset_mm));
      const int slices = static_cast<int>(std::lround(27.5 / c.slice_step_mm));
      CtVolume vol = MakeCtGeometry(40, 40, slices, 0.878906, c.slice_step_mm, 1.25,
                                    Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(),
                                    Eigen::Vector3d::Zero());
      CtVoxeliseOptions vo;
      vo.noise_hu = 20;
      vo.seed = noise_seed + t;
      vo.psf_sigma_mm = c.psf_mm;
      vo.metal_streak_hu = c.streak_hu;
      vo.clip_hu = kClipHu;
      ASSERT_TRUE(VoxelisePhantom(ph, vo, &vol).ok());
      MarkerDetectionOptions opt;
      opt.diameter_mm = c.nominal_diameter_mm;
      opt.expected_count = 1;
      auto det = DetectMarkers(vol, opt);
      if (!det.ok()) {
        std::printf("%s trial %d: %s\n", c.name, t, det.status().message().c_str());
        continue;
      }
      ++found;
      const auto& m = det->markers[0];
      EXPECT_EQ(det->clip_hu, kClipHu);
      EXPECT_TRUE(m.saturated);
      const Eigen::Vector3d e = m.centre_mm - mk.centre_mm;
      nees += e.dot(m.covariance_mm2.inverse() * e);
      sq += e.squaredNorm();
      const Eigen::Vector3d d = m.centroid_mm - m.surface_centre_mm;
      chi2_estimators +=
          d.dot((m.centroid_covariance_mm2 + m.surface_covariance_mm2).inverse() * d);
    }
    nees /= std::max(found, 1);
    chi2_estimators /= std::max(found, 1);
    std::printf("%s: found %d of %d; centre error rms %.4f mm; NEES per dof %.2f; centroid vs "
                "surface chi2 per dof %.2f\n",
                c.name, found, kTrials, std::sqrt(sq / std::max(found, 1)), nees / 3,
                chi2_estimators / 3);
    const std::string key = std::string("saturated.") + c.key;
    testing::RecordFigure(key + "_found", "%d/%d", found, kTrials);
    testing::RecordFigure(key + "_nees", "%.2f", nees / 3);
    testing::RecordFigure(key + "_rms", "%.2f", std::sqrt(sq / std::max(found, 1)));
    EXPECT_EQ(found, kTrials) << c.name;
    EXPECT_GT(nees / 3, c.min_nees) << c.name;
    EXPECT_LT(nees / 3, 2.0) << c.name;
    EXPECT_LT(std::sqrt(sq / std::max(found, 1)), c.max_rms_mm) << c.name;
  }
}

}  // namespace
}  // namespace carmba
