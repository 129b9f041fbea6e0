// The real CT in data/real/ggn-phantom-ct (GE Revolution Apex, a phantom with four metal spheres
// of about 5.5 mm, clipped at 3071 HU, with streaks, holder rings, metal tails and a pin; see
// data/real/README.md): the spheres found with default options and a roughly known diameter,
// and their centres checked without ground truth -- the odd and the even slices, and two
// independent estimators (the clipped centroid and the surface fit), agree within their
// covariances.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "ct/ct_volume.h"
#include "ct/marker_detection.h"
#include "figures.h"

namespace carmba {
namespace {

const std::string kSeries = std::string(CARMBA_SOURCE_DIR) + "/data/real/ggn-phantom-ct/series";
constexpr int kSpheres = 4;

const CtVolume& RealCt() {
  static const CtVolume* volume = [] {
    auto v = ReadCtSeries(kSeries);
    EXPECT_TRUE(v.ok()) << v.status().message();
    return new CtVolume(v.ok() ? std::move(v).value() : CtVolume());
  }();
  return *volume;
}

MarkerDetectionOptions Options(double diameter_mm, int expected) {
  MarkerDetectionOptions o;  // defaults otherwise
  o.diameter_mm = diameter_mm;
  o.expected_count = expected;
  return o;
}

// Every n-th slice from `first`: a series of n x 1.25 mm steps with the same slice thickness.
CtVolume EveryNthSlice(const CtVolume& v, int n, int first) {
  CtVolume s = v;
  s.slices = (v.slices - first + n - 1) / n;
  s.origin_mm = v.PatientFromIndex(Eigen::Vector3d(0, 0, first));
  s.spacing_mm.z() = n * v.spacing_mm.z();
  s.slice_thickness_mm = v.slice_thickness_mm;
  s.hu.assign(v.hu.begin(), v.hu.begin() + static_cast<size_t>(v.columns) * v.rows * s.slices);
  const size_t plane = static_cast<size_t>(v.columns) * v.rows;
  for (int k = 0; k < s.slices; ++k) {
    std::copy(v.hu.begin() + (first + n * k) * plane,
              v.hu.begin() + (first + n * k + 1) * plane,
              s.hu.begin() + k * plane);
  }
  return s;
}

// The marker of `d` nearest to `p` within 3 mm, or null.
const DetectedMarker* NearestWithin3Mm(const MarkerDetection& d, const Eigen::Vector3d& p) {
  const DetectedMarker* best = nullptr;
  for (const auto& m : d.markers) {
    if ((m.centre_mm - p).norm() < 3.0 &&
        (!best || (m.centre_mm - p).norm() < (best->centre_mm - p).norm()))
      best = &m;
  }
  return best;
}

double Chi2(const Eigen::Vector3d& d, const Eigen::Matrix3d& C) { return d.dot(C.ldlt().solve(d)); }

TEST(RealCt, FindsTheFourSpheresWithDefaultOptions) {
  const CtVolume& v = RealCt();
  ASSERT_GT(v.slices, 0);
  auto det = DetectMarkers(v, Options(6.0, kSpheres));
  ASSERT_TRUE(det.ok()) << det.status().message();
  EXPECT_EQ(det->clip_hu, 3071);  // read from the data
  EXPECT_GT(det->clipped_voxels, 400);
  for (const auto& m : det->markers) {
    std::printf("sphere (%.3f, %.3f, %.3f) mm, radii %.2f / %.2f mm, rays %d/%d, rms %.3f mm, "
                "sd %.3f %.3f %.3f mm, centroid - surface %.3f mm (chi2 %.2f)\n",
                m.centre_mm.x(), m.centre_mm.y(), m.centre_mm.z(), m.surface_radii_mm.x(),
                m.surface_radii_mm.y(), m.surface_inliers, m.surface_rays, m.surface_rms_mm,
                std::sqrt(m.covariance_mm2(0, 0)), std::sqrt(m.covariance_mm2(1, 1)),
                std::sqrt(m.covariance_mm2(2, 2)), (m.centroid_mm - m.surface_centre_mm).norm(),
                m.contamination_chi2);
    EXPECT_TRUE(m.saturated);
    // About 5.5 mm spheres, bloomed: the half-level edge a little outside.
    EXPECT_GT(m.surface_radii_mm.minCoeff(), 2.4);
    EXPECT_LT(m.surface_radii_mm.maxCoeff(), 3.6);
    EXPECT_LT(std::sqrt(m.covariance_mm2.trace()), 0.3);
  }
  // The pin is rejected as not a ball.
  bool pin = false;
  for (const auto& r : det->rejected) {
    std::printf("rejected (%.1f, %.1f, %.1f): %s\n", r.centroid_mm.x(), r.centroid_mm.y(),
                r.centroid_mm.z(), r.reason.c_str());
    pin = pin || r.reason.find("not a ball") != std::string::npos;
  }
  EXPECT_TRUE(pin);
}

TEST(RealCt, ExpectingFiveNamesTheFourSpheresAndThePin) {
  auto det = DetectMarkers(RealCt(), Options(6.0, 5));
  ASSERT_FALSE(det.ok());
  EXPECT_NE(det.status().message().find("found 4 markers"), std::string::npos)
      << det.status().message();
  EXPECT_NE(det.status().message().find("not a ball"), std::string::npos)
      << det.status().message();
}

// The diameter need only be roughly known: 5 .. 8 mm give the same centres within their sigmas.
TEST(RealCt, ARoughDiameterGivesTheSameCentres) {
  auto ref = DetectMarkers(RealCt(), Options(6.0, kSpheres));
  ASSERT_TRUE(ref.ok()) << ref.status().message();
  for (double d : {5.0, 7.0, 8.0}) {
    auto det = DetectMarkers(RealCt(), Options(d, kSpheres));
    ASSERT_TRUE(det.ok()) << "diameter " << d << ": " << det.status().message();
    for (const auto& m : det->markers) {
      double nearest = 1e9;
      for (const auto& r : ref->markers)
        nearest = std::min(nearest, (r.centre_mm - m.centre_mm).norm());
      std::printf("diameter %.0f mm: centre %.4f mm from the 6 mm one\n", d, nearest);
      EXPECT_LT(nearest, 3 * std::sqrt(m.covariance_mm2.trace()));
    }
  }
}

// The odd and the even slices: two series of 2.5 mm steps (1.25 mm thick slices) from disjoint
// data. Each of the four spheres found in the full series is looked up in both halves (any
// count: in the sparse halves a piece of the pin may pass as a ball, and a sphere may be lost).
// Measured: 3 of 4 spheres in both halves (the fourth lost in the even one), their centres
// 0.89-0.95 mm apart, mostly along z. With the simulated sampling term alone the covariances
// said NEES per dof 6.88: the real spheres are not the spheroids the edge fit assumes (helical
// scanning distorts metal), so with every second slice the fit sees a lopsided shape. The sector
// jackknife (ct/marker_detection.h 8.) measures that from each half's own edge: NEES per dof 1.97,
// asserted in the 0.3-3 band; and the spheres are found in both halves within 1.6 mm (a
// voxel diagonal of the sparse series).
TEST(RealCt, OddAndEvenSlicesFindTheSpheresWithinAVoxel) {
  const CtVolume& v = RealCt();
  auto full = DetectMarkers(v, Options(6.0, kSpheres));
  auto even = DetectMarkers(EveryNthSlice(v, 2, 0), Options(6.0, 0));
  auto odd = DetectMarkers(EveryNthSlice(v, 2, 1), Options(6.0, 0));
  ASSERT_TRUE(full.ok()) << full.status().message();
  ASSERT_TRUE(even.ok()) << even.status().message();
  ASSERT_TRUE(odd.ok()) << odd.status().message();
  double chi2 = 0, min_apart = 1e9, max_apart = 0;
  int both = 0;
  for (const auto& f : full->markers) {
    const DetectedMarker* e = NearestWithin3Mm(*even, f.centre_mm);
    const DetectedMarker* o = NearestWithin3Mm(*odd, f.centre_mm);
    if (!e || !o) {
      std::printf("sphere (%.2f, %.2f, %.2f): %s%s\n",
                  f.centre_mm.x(),
                  f.centre_mm.y(),
                  f.centre_mm.z(),
                  e ? "" : "not in the even slices ",
                  o ? "" : "not in the odd slices");
      continue;
    }
    ++both;
    const Eigen::Vector3d d = e->centre_mm - o->centre_mm;
    const double c = Chi2(d, e->covariance_mm2 + o->covariance_mm2);
    std::printf("even - odd (%.3f, %.3f, %.3f) mm = %.3f mm, chi2 %.2f (3 dof); sd even %.3f odd "
                "%.3f mm\n",
                d.x(), d.y(), d.z(), d.norm(), c, std::sqrt(e->covariance_mm2.trace()),
                std::sqrt(o->covariance_mm2.trace()));
    EXPECT_LT(d.norm(), 1.6);
    chi2 += c;
    min_apart = std::min(min_apart, d.norm());
    max_apart = std::max(max_apart, d.norm());
  }
  std::printf(
      "odd/even: %d of %d spheres in both halves; NEES per dof %.2f (even %zu markers, odd "
      "%zu)\n",
      both,
      kSpheres,
      both ? chi2 / (3 * both) : 0.0,
      even->markers.size(),
      odd->markers.size());
  EXPECT_GE(both, 3);
  testing::RecordFigure("realct.odd_even_found", "%d of %d", both, kSpheres);
  testing::RecordFigure("realct.odd_even_apart", "%.2f-%.2f mm", min_apart, max_apart);
  testing::RecordFigure("realct.odd_even_nees", "%.2f", both ? chi2 / (3 * both) : 0.0);
  if (both > 0) {
    EXPECT_GE(chi2 / (3 * both), 0.3);
    EXPECT_LE(chi2 / (3 * both), 3.0);
  }
}

// Every third slice (3.75 mm steps, 1.25 mm thick: gaps of 2.5 mm, one or two slices through a
// sphere): three disjoint series, each sphere compared between every two of them that found it.
// Measured: 4 pairs, 1.35-2.79 mm apart, NEES per dof 8.5: beyond what the covariance holds --
// with so few slices the fit sees too little of a real (not spheroidal) sphere, which neither the
// simulated sampling term nor the sector jackknife captures. The test asserts what holds (at
// least 3 sphere pairs found) and records the rest for src/docs/results.md, which says it.
TEST(RealCt, EveryThirdSliceFindsSpheresInTwoOfTheThreeSeries) {
  const CtVolume& v = RealCt();
  auto full = DetectMarkers(v, Options(6.0, kSpheres));
  ASSERT_TRUE(full.ok()) << full.status().message();
  std::vector<MarkerDetection> thirds;
  for (int first = 0; first < 3; ++first) {
    auto d = DetectMarkers(EveryNthSlice(v, 3, first), Options(6.0, 0));
    thirds.push_back(d.ok() ? *d : MarkerDetection());
  }
  double chi2 = 0, min_apart = 1e9, max_apart = 0;
  int pairs = 0;
  for (const auto& f : full->markers) {
    for (int a = 0; a < 3; ++a) {
      for (int b = a + 1; b < 3; ++b) {
        const DetectedMarker* ma = NearestWithin3Mm(thirds[a], f.centre_mm);
        const DetectedMarker* mb = NearestWithin3Mm(thirds[b], f.centre_mm);
        if (!ma || !mb) continue;
        const Eigen::Vector3d d = ma->centre_mm - mb->centre_mm;
        chi2 += Chi2(d, ma->covariance_mm2 + mb->covariance_mm2);
        min_apart = std::min(min_apart, d.norm());
        max_apart = std::max(max_apart, d.norm());
        ++pairs;
      }
    }
  }
  std::printf("every third slice: %d pairs, %.2f-%.2f mm apart, NEES per dof %.2f\n",
              pairs,
              min_apart,
              max_apart,
              pairs ? chi2 / (3 * pairs) : 0.0);
  testing::RecordFigure("realct.thirds_pairs", "%d", pairs);
  testing::RecordFigure("realct.thirds_apart", "%.2f-%.2f mm", min_apart, max_apart);
  testing::RecordFigure("realct.thirds_nees", "%.1f", pairs ? chi2 / (3 * pairs) : 0.0);
  EXPECT_GE(pairs, 3);
}

TEST(RealCt, CentroidAndSurfaceFitAgreeWithinTheirCovariances) {
  auto det = DetectMarkers(RealCt(), Options(6.0, kSpheres));
  ASSERT_TRUE(det.ok()) << det.status().message();
  double chi2 = 0, min_apart = 1e9, max_apart = 0;
  for (const auto& m : det->markers) {
    const Eigen::Vector3d d = m.centroid_mm - m.surface_centre_mm;
    min_apart = std::min(min_apart, d.norm());
    max_apart = std::max(max_apart, d.norm());
    const double c = Chi2(d, m.centroid_covariance_mm2 + m.surface_covariance_mm2);
    std::printf("centroid - surface (%.3f, %.3f, %.3f) mm, chi2 %.2f; sd centroid %.3f, "
                "surface %.3f mm\n",
                d.x(), d.y(), d.z(), c, std::sqrt(m.centroid_covariance_mm2.trace()),
                std::sqrt(m.surface_covariance_mm2.trace()));
    chi2 += c;
  }
  const double per_dof = chi2 / (3 * kSpheres);
  std::printf("centroid/surface NEES per dof %.2f over %d spheres\n", per_dof, kSpheres);
  testing::RecordFigure("realct.estimators_apart", "%.2f-%.2f mm", min_apart, max_apart);
  testing::RecordFigure("realct.estimators_nees", "%.2f", per_dof);
  EXPECT_GE(per_dof, 0.3);
  EXPECT_LE(per_dof, 3.0);
}

}  // namespace
}  // namespace carmba
