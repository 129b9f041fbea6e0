// The marker detector's blob centre against the physically exact renderer (sim/xray_render.h:
// every sub-pixel ray's chord through the sphere from the point source), noise-free: it follows
// the centre of the sphere's cone-beam shadow outline (ba/shadow_correction.h), not the
// projection of the sphere's centre. Random spheres (seeded), 1.5-6 mm, 450-750 mm from the
// source, 150-480 px from the principal point.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <random>
#include <string>

#include "ba/shadow_correction.h"
#include "camera/camera_model.h"
#include "detect/marker_blobs.h"
#include "figures.h"
#include "sim/xray_render.h"
#include "test_env.h"

namespace carmba {
namespace {

struct CentreErrors {
  int n = 0;
  double radial_to_projection = 0;  // mean, px
  double radial_to_outline = 0;     // mean, px
  double rms_to_outline = 0;        // px per coordinate
};

// One sphere per image: a 224 x 224 window whose principal point may lie outside it (up to one
// image size, the camera's plausible range), so the sphere is far off-axis while the render
// stays small.
CentreErrors Measure(double diameter_mm, uint64_t seed, int spheres) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0, 1);
  CentreErrors e;
  double sum2 = 0;
  for (int t = 0; t < spheres; ++t) {
    const double f = 2500 + 1000 * U(rng), depth = 450 + 300 * U(rng);
    Eigen::Vector2d at;  // px from the principal point
    do {
      const double rho = 150 + 330 * U(rng), phi = 2 * M_PI * U(rng);
      at = Eigen::Vector2d(rho * std::cos(phi), rho * std::sin(phi));
    } while (at.cwiseAbs().maxCoeff() > 330);
    Camera cam;
    cam.width = cam.height = 224;
    cam.params = {
        f, f, 111.5 - at.x() + (U(rng) - 0.5), 111.5 - at.y() + (U(rng) - 0.5), 0, 0, 0, 0, 0};
    sim::Phantom ph;
    sim::SpherePrimitive s;
    s.center_mm = Eigen::Vector3d(at.x() * depth / f, at.y() * depth / f, depth);
    s.radius_mm = diameter_mm / 2;
    s.mu_per_mm = 0.94;  // steel
    ph.spheres.push_back(s);
    sim::RenderOptions ro;
    ro.supersampling = 6;
    ro.circular_fov = false;
    ro.white_level = 200;
    auto image = sim::RenderXray(cam, {{&ph, Rigid3()}}, ro);
    EXPECT_TRUE(image.ok()) << image.status().message();
    if (!image.ok()) continue;
    MarkerBlobOptions mo;
    mo.diameter_mm = diameter_mm;
    mo.px_per_mm = f / depth;
    mo.fov.auto_fov_mask = false;
    const MarkerBlobDetection det = DetectMarkerBlobs(*image, mo);
    EXPECT_EQ(det.blobs.size(), 1u) << det.reason;
    if (det.blobs.size() != 1) continue;
    Eigen::Vector2d projected;
    EXPECT_TRUE(ProjectCamPoint(cam.params.data(), s.center_mm.data(), projected.data()));
    const Eigen::Vector2d outline =
        projected + ba::SphereShadowOffsetPx(cam.params.data(), s.center_mm, s.radius_mm);
    const Eigen::Vector2d found(det.blobs[0].uv_px.x, det.blobs[0].uv_px.y);
    const Eigen::Vector2d radial = at.normalized();
    e.radial_to_projection += (found - projected).dot(radial);
    e.radial_to_outline += (found - outline).dot(radial);
    sum2 += (found - outline).squaredNorm();
    ++e.n;
  }
  e.radial_to_projection /= e.n;
  e.radial_to_outline /= e.n;
  e.rms_to_outline = std::sqrt(sum2 / (2.0 * e.n));
  return e;
}

TEST(ShadowCentre, DetectedCentresFollowTheShadowOutlineNotTheProjection) {
  const uint64_t seed = testing::EnvOr<uint64_t>("CARMBA_SHADOW_SEED", 2026);
  const int n = testing::EnvOr<int>("CARMBA_SHADOW_SPHERES", 20);
  for (double d : {6.0, 3.0, 1.5}) {
    const CentreErrors e = Measure(d, seed + static_cast<uint64_t>(10 * d), n);
    std::cout << d << " mm spheres (" << e.n << "): mean radial error against the projected centre "
              << e.radial_to_projection << " px, against the shadow outline's centre "
              << e.radial_to_outline << " px; RMS against the outline " << e.rms_to_outline
              << " px per coordinate\n";
    const std::string size = d == 6.0 ? "6" : d == 3.0 ? "3" : "1_5";
    testing::RecordFigure("shadow.centre_projected_" + size, "%+.4f", e.radial_to_projection);
    testing::RecordFigure("shadow.centre_outline_" + size, "%+.4f", e.radial_to_outline);
    ASSERT_EQ(e.n, n);
    // The goal: |mean radial bias| < 0.003 px once the offset is accounted for. Small blobs
    // (1.5 mm: ~7 px) have a noise-free pixel-phase error of ~0.009 px RMS that averages out
    // over directions (100 spheres, seeds 123456 and 999: mean -0.00003 and -0.0010 px); with
    // n spheres the mean is then known to its standard error, and the bound is the larger of the
    // goal and 4 standard errors.
    const double standard_error = e.rms_to_outline / std::sqrt(static_cast<double>(e.n));
    EXPECT_LT(std::abs(e.radial_to_outline), std::max(0.003, 4 * standard_error)) << d;
    if (d == 6.0) {
      // Large spheres: the uncorrected bias is several times that (what the correction is for).
      EXPECT_GT(e.radial_to_projection, 0.006);
    }
  }
}

}  // namespace
}  // namespace carmba
