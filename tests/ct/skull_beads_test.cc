// Marker detection and covariance on a real CT: steel beads embedded (partial volume, random
// sub-voxel positions, seeded) into the skull CT of Debian's invesalius-examples, in soft tissue,
// in the brain and touching bone (tests/ct/skull_beads.h), written as a DICOM series and read
// back by `ct-fiducials`'s pipeline with default detection settings. Skipped when the package is
// not installed (scripts/setup.sh installs it unless CARMBA_WITH_SKULL_CT=0).
//
// Measurement (more seeds, printed per bead): CARMBA_SKULL_SEEDS=7,8,9 and optionally
// CARMBA_SKULL_THRESHOLD_HU=2000 (a fixed threshold), CARMBA_SKULL_VERBOSE=1, and for other
// beads CARMBA_SKULL_DIAMETER_MM and CARMBA_SKULL_BEAD_HU (the default test's checks then apply
// to them too).
#include "ct/skull_beads.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>

#include "ct/ct_fiducials.h"
#include "ct/ct_invesalius.h"
#include "ct/ct_test_util.h"
#include "ct/marker_detection.h"
#include "ct/marker_labelling.h"
#include "figures.h"
#include "test_env.h"

namespace carmba {
namespace {

using testing::ScratchDir;
using testing::SkullBead;

// The 3 mm steel beads; steel on a 12-bit scanner (the simulator's default HU).
const double kBeadDiameterMm = testing::EnvOr("CARMBA_SKULL_DIAMETER_MM", 3.0);
const double kSteelHu = testing::EnvOr("CARMBA_SKULL_BEAD_HU", 3000.0);
// White noise added to the bead's own share of a voxel; the scan's noise stays in the rest
// (the skull CT's brain has a local MAD-based sigma of about 20 HU).
constexpr double kBeadNoiseHu = 20;

#define SKIP_WITHOUT_SKULL()                                                                  \
  if (!testing::SkullCt()) {                                                                 \
    GTEST_SKIP() << "the skull CT " << kInvesaliusCraniumPath                                \
                 << " is absent: apt-get install invesalius-examples (scripts/setup.sh)";    \
  }

bool Verbose() {
  const char* env = std::getenv("CARMBA_SKULL_VERBOSE");
  return env && std::string(env) == "1";
}

std::vector<uint64_t> Seeds(std::vector<uint64_t> fallback) {
  const char* env = std::getenv("CARMBA_SKULL_SEEDS");
  if (!env || !*env) return fallback;
  std::vector<uint64_t> seeds;
  std::stringstream ss(env);
  std::string s;
  while (std::getline(ss, s, ',')) seeds.push_back(std::stoull(s));
  return seeds;
}


TEST(InvesaliusVolume, ReadsTheSkullCt) {
  SKIP_WITHOUT_SKULL();
  const CtVolume& v = *testing::SkullCt();
  EXPECT_EQ(v.columns, 256);
  EXPECT_EQ(v.rows, 256);
  EXPECT_EQ(v.slices, 108);
  EXPECT_NEAR(v.spacing_mm.x(), 0.9570312, 1e-6);
  EXPECT_NEAR(v.spacing_mm.z(), 1.5, 1e-12);
  float lo = 1e9, hi = -1e9;
  for (float x : v.hu) {
    lo = std::min(lo, x);
    hi = std::max(hi, x);
  }
  EXPECT_EQ(lo, -1024);
  EXPECT_EQ(hi, 2986);
  // The file's maximum is at (z, y, x) = (0, 178, 161) (numpy on matrix.dat); rows are stored
  // bottom-up, so it is image row 255 - 178.
  EXPECT_EQ(v.At(161, 255 - 178, 0), 2986);
}

TEST(InvesaliusVolume, BadFilesAreRefused) {
  ScratchDir dir("inv3");
  testing::WriteText(dir.File("x.inv3"), "not a tar");
  auto r = ReadInvesaliusVolume(dir.File("x.inv3"));
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("x.inv3"), std::string::npos) << r.status().message();
  EXPECT_FALSE(ReadInvesaliusVolume(dir.File("absent.inv3")).ok());
}

struct BeadOutcome {
  SkullBead bead;
  bool found = false;
  Eigen::Vector3d error_mm = Eigen::Vector3d::Zero();
  double nees = 0;       // e^T C^-1 e
  double error_sigma = 0;  // sqrt(nees)
  DetectedMarker marker;
};

struct SeedOutcome {
  std::string error;  // detection refused
  std::vector<BeadOutcome> beads;
  int false_candidates = 0;
  double seconds = 0;
};

// Embeds beads for `seed`, writes the series, runs ComputeCtFiducials with `options`.
SeedOutcome RunSeed(uint64_t seed, CtFiducialsOptions options, const std::vector<SkullBead>& beads,
                    double streak_hu) {
  SeedOutcome out;
  const CtVolume vol =
      testing::SkullWithBeads(*testing::SkullCt(), beads, kBeadDiameterMm, kSteelHu,
                              kBeadNoiseHu, seed, streak_hu);
  EXPECT_FALSE(vol.hu.empty());
  ScratchDir dir("skull_" + std::to_string(seed));
  CtWriteOptions wo;
  wo.study_uid = "2.25.77." + std::to_string(seed) + ".1";
  wo.series_uid = "2.25.77." + std::to_string(seed) + ".2";
  wo.frame_of_reference_uid = "2.25.77." + std::to_string(seed) + ".3";
  wo.patient_name = "INVESALIUS^CRANIUM";
  EXPECT_TRUE(WriteCtSeries(vol, dir.File("ct"), wo).ok());
  auto r = ComputeCtFiducials(dir.File("ct"), options);
  for (const auto& b : beads) out.beads.push_back({b, false, {}, 0, 0, {}});
  if (!r.ok()) {
    out.error = r.status().message();
    return out;
  }
  out.seconds = r->read_seconds + r->detect_seconds;
  std::vector<bool> used(r->detection.markers.size(), false);
  for (auto& o : out.beads) {
    int best = -1;
    double best_d = 1.5;  // mm: half the bead's diameter
    for (size_t m = 0; m < r->detection.markers.size(); ++m) {
      const double d = (r->detection.markers[m].centre_mm - o.bead.centre_mm).norm();
      if (d < best_d) {
        best_d = d;
        best = static_cast<int>(m);
      }
    }
    if (best < 0) continue;
    used[best] = true;
    const auto& m = r->detection.markers[best];
    o.found = true;
    o.error_mm = m.centre_mm - o.bead.centre_mm;
    o.nees = o.error_mm.dot(m.covariance_mm2.ldlt().solve(o.error_mm));
    o.error_sigma = std::sqrt(o.nees);
    o.marker = m;
  }
  for (bool u : used) out.false_candidates += !u;
  if (Verbose()) {
    for (size_t m = 0; m < used.size(); ++m) {
      if (used[m]) continue;
      const auto& d = r->detection.markers[m];
      std::printf("  false candidate at (%7.2f %7.2f %7.2f), core %.1f mm^3, peak %.0f HU, fit %d "
                  "M %.0f +- %.0f b %.0f scale %.0f inner %.2f\n",
                  d.centre_mm.x(), d.centre_mm.y(), d.centre_mm.z(), d.volume_mm3, d.peak_hu,
                  d.fit_ok, d.fit_metal_hu, d.fit_metal_sigma_hu, d.fit_background_hu,
                  d.fit_scale_hu, d.fit_inner_fraction);
    }
    for (const auto& o : out.beads) {
      if (o.found) continue;
      for (const auto& c : r->detection.rejected) {
        if ((c.centroid_mm - o.bead.centre_mm).norm() > 4) continue;
        std::printf("  missed bead (%7.2f %7.2f %7.2f): component at (%7.2f %7.2f %7.2f) %s\n",
                    o.bead.centre_mm.x(), o.bead.centre_mm.y(), o.bead.centre_mm.z(),
                    c.centroid_mm.x(), c.centroid_mm.y(), c.centroid_mm.z(), c.reason.c_str());
      }
    }
  }
  return out;
}

struct Summary {
  int expected = 0, found = 0, false_candidates = 0, refused = 0;
  double sum_nees = 0, worst_sigma = 0, worst_mm = 0;
  std::string worst_kind;
};

Summary Summarise(const std::vector<SeedOutcome>& seeds, const std::string& kind = "") {
  Summary s;
  for (const auto& so : seeds) {
    if (kind.empty()) s.false_candidates += so.false_candidates;
    if (!so.error.empty() && kind.empty()) ++s.refused;
    for (const auto& b : so.beads) {
      if (!kind.empty() && b.bead.kind != kind) continue;
      ++s.expected;
      if (!b.found) continue;
      ++s.found;
      s.sum_nees += b.nees;
      s.worst_mm = std::max(s.worst_mm, b.error_mm.norm());
      if (b.error_sigma > s.worst_sigma) {
        s.worst_sigma = b.error_sigma;
        s.worst_kind = b.bead.kind;
      }
    }
  }
  return s;
}

void Print(const std::string& label, const Summary& s) {
  std::printf("%-6s found %d/%d, false candidates %d, refused %d, mean e^T C^-1 e %.2f, worst "
              "%.2f sigma (%s), worst error %.3f mm\n",
              label.c_str(), s.found, s.expected, s.false_candidates, s.refused,
              s.found ? s.sum_nees / s.found : 0.0, s.worst_sigma, s.worst_kind.c_str(),
              s.worst_mm);
}

std::vector<SeedOutcome> RunSeeds(const std::vector<uint64_t>& seeds, CtFiducialsOptions options,
                                  double streak_hu = 0) {
  if (const char* thr = std::getenv("CARMBA_SKULL_THRESHOLD_HU")) {
    options.detect.threshold_hu = std::atof(thr);
  }
  std::vector<SeedOutcome> out;
  for (uint64_t seed : seeds) {
    const auto beads = testing::PlaceSkullBeads(*testing::SkullCt(), seed, kBeadDiameterMm,
                                                /*bone=*/8, /*brain=*/5, /*soft=*/5);
    out.push_back(RunSeed(seed, options, beads, streak_hu));
    const auto& so = out.back();
    std::printf("seed %llu: %zu beads, %s%.2f s\n", static_cast<unsigned long long>(seed),
                beads.size(), so.error.empty() ? "" : ("REFUSED: " + so.error + "; ").c_str(),
                so.seconds);
    if (Verbose()) {
      for (const auto& b : so.beads) {
        std::printf("  %-5s (%7.2f %7.2f %7.2f) %s err (%6.3f %6.3f %6.3f) mm, %.2f sigma",
                    b.bead.kind.c_str(), b.bead.centre_mm.x(), b.bead.centre_mm.y(),
                    b.bead.centre_mm.z(), b.found ? "found" : "MISSED", b.error_mm.x(),
                    b.error_mm.y(), b.error_mm.z(), b.error_sigma);
        const DetectedMarker& m = b.marker;
        if (b.found && m.fit_ok) {
          const Eigen::Vector3d ef = m.fit_centre_mm - b.bead.centre_mm;
          const Eigen::Vector3d dd = m.centre_mm - m.fit_centre_mm;
          const Eigen::Matrix3d Cw = m.covariance_mm2, Cf = m.fit_covariance_mm2;
          std::printf(" | fit err %.3f mm %.2f sig (noise-only) | M %.0f +- %.0f b %.0f scale %.1f "
                      "outl %.0f n %d | delta %.3f chi2 %.1f | bg %.0f noise %.1f | +samp %.2f sig",
                      ef.norm(), std::sqrt(ef.dot(Cf.ldlt().solve(ef))), m.fit_metal_hu,
                      m.fit_metal_sigma_hu,
                      m.fit_background_hu, m.fit_scale_hu, m.fit_outlier_mass, m.fit_voxels,
                      dd.norm(), dd.dot((Cw + Cf).ldlt().solve(dd)), m.background_hu, m.noise_hu,
                      std::sqrt(ef.dot((Cf + m.covariance_sampling_mm2).ldlt().solve(ef))));
        }
        std::printf("\n");
      }
    }
  }
  Print("all", Summarise(out));
  for (const char* kind : {"soft", "brain", "bone"}) Print(kind, Summarise(out, kind));
  return out;
}

// >= 50 beads, all found, no false candidate, none refused; mean e^T C^-1 e within [2.4, 3.6] and
// none beyond 5 sigma (see below).
// `figure`: the results.md figure the run's summary is recorded as.
void ExpectEveryBeadFoundWithHonestCovariance(const std::vector<SeedOutcome>& seeds,
                                              const std::string& figure) {
  const Summary s = Summarise(seeds);
  testing::RecordFigure(figure,
                        "%d / %d beads found over %zu seeds, %d false candidates, mean e^T C^-1 e "
                        "%.2f, worst %.1f sigma",
                        s.found,
                        s.expected,
                        seeds.size(),
                        s.false_candidates,
                        s.found ? s.sum_nees / s.found : 0.0,
                        s.worst_sigma);
  EXPECT_GE(s.expected, 50);
  EXPECT_EQ(s.refused, 0);
  EXPECT_EQ(s.found, s.expected);
  EXPECT_EQ(s.false_candidates, 0);
  const double mean_nees = s.found ? s.sum_nees / s.found : 0;
  EXPECT_GE(mean_nees, 2.4);
  EXPECT_LE(mean_nees, 3.6);
  EXPECT_LT(s.worst_sigma, 5.0);
}

// The target: >= 50 beads over soft tissue, brain and bone, all found with default
// settings (only the diameter given), no false candidate, and an honest covariance: the mean of
// e^T C^-1 e (chi-square with 3 degrees of freedom: mean 3, standard error sqrt(6 / n), 0.24 at
// n = 108) within [2.4, 3.6], and no bead beyond 5 sigma (for 108 honest chi-square(3) draws
// the chance of one is about 0.2 %).
TEST(SkullBeads, DefaultSettingsFindEveryBeadWithHonestCovariance) {
  SKIP_WITHOUT_SKULL();
  CtFiducialsOptions options;
  options.detect.diameter_mm = kBeadDiameterMm;
  ExpectEveryBeadFoundWithHonestCovariance(RunSeeds(Seeds({1, 2, 3, 4, 5, 6}), options),
                                           "skull.default");
}

// The same with metal artefacts (the optional part of the issue): streaks around each bead and
// dark bands between beads in the same slice, 300 HU at a bead's surface by default
// (CARMBA_SKULL_STREAK_HU); the same targets hold.
TEST(SkullBeads, MetalStreaksKeepEveryBeadFoundAndTheCovarianceHonest) {
  SKIP_WITHOUT_SKULL();
  CtFiducialsOptions options;
  options.detect.diameter_mm = kBeadDiameterMm;
  const double streak_hu = testing::EnvOr("CARMBA_SKULL_STREAK_HU", 300.0);
  ExpectEveryBeadFoundWithHonestCovariance(RunSeeds(Seeds({1, 2, 3, 4, 5, 6}), options, streak_hu),
                                           "skull.streaks");
}

// The skull alone: teeth and dense bone (up to 2986 HU here) give no marker with the default
// settings (the old fixed 1500 HU threshold gave ~110 bead-sized components).
TEST(SkullBeads, BoneAloneGivesNoMarker) {
  SKIP_WITHOUT_SKULL();
  MarkerDetectionOptions options;
  options.diameter_mm = kBeadDiameterMm;
  auto det = DetectMarkers(*testing::SkullCt(), options);
  ASSERT_FALSE(det.ok());
  EXPECT_NE(det.status().message().find("found 0 markers"), std::string::npos)
      << det.status().message();
}

// The issue's `--model` case: a model of 6 of the beads (in an object frame) among 18
// marker-like candidates: the 6 are selected and labelled with their model ids, the other 12
// are listed as rejected.
TEST(SkullBeads, ModelSelectsItsMarkersAmongTheCandidates) {
  SKIP_WITHOUT_SKULL();
  constexpr uint64_t kSeed = 7;
  const auto beads = testing::PlaceSkullBeads(*testing::SkullCt(), kSeed, kBeadDiameterMm, 8, 5, 5);
  ASSERT_EQ(beads.size(), 18u);
  const CtVolume vol = testing::SkullWithBeads(*testing::SkullCt(), beads, kBeadDiameterMm,
                                               kSteelHu, kBeadNoiseHu, kSeed);
  ScratchDir dir("skull_model");
  CtWriteOptions wo;
  wo.study_uid = "2.25.78.1";
  wo.series_uid = "2.25.78.2";
  wo.frame_of_reference_uid = "2.25.78.3";
  ASSERT_TRUE(WriteCtSeries(vol, dir.File("ct"), wo).ok());
  Rigid3 object_from_ct;
  object_from_ct.R =
      Eigen::AngleAxisd(0.9, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
  object_from_ct.t = Eigen::Vector3d(10, 20, -30);
  // Model ids 101..106: beads 0, 3, 6, 9, 12, 15 (bone, brain and soft ones among them).
  std::string csv = "id,x_mm,y_mm,z_mm\n";
  for (int a = 0; a < 6; ++a) {
    const Eigen::Vector3d p = object_from_ct * beads[3 * a].centre_mm;
    char line[160];
    std::snprintf(line, sizeof(line), "%d,%.4f,%.4f,%.4f\n", 101 + a, p.x(), p.y(), p.z());
    csv += line;
  }
  testing::WriteText(dir.File("model.csv"), csv);
  CtFiducialsOptions options;
  options.detect.diameter_mm = kBeadDiameterMm;
  options.model_csv = dir.File("model.csv");
  auto r = ComputeCtFiducials(dir.File("ct"), options);
  ASSERT_TRUE(r.ok()) << r.status().message();
  ASSERT_EQ(r->detection.markers.size(), 6u);
  EXPECT_EQ(r->candidates, 18);
  for (int a = 0; a < 6; ++a) {
    const auto& m = r->detection.markers[a];
    EXPECT_EQ(m.id, 101 + a);
    EXPECT_LT((m.centre_mm - beads[3 * a].centre_mm).norm(), 0.3) << "model id " << m.id;
  }
  int set_aside = 0;
  for (const auto& c : r->detection.rejected) {
    set_aside += c.reason.find("does not fit the model") != std::string::npos;
  }
  EXPECT_EQ(set_aside, 12);
}

}  // namespace
}  // namespace carmba
