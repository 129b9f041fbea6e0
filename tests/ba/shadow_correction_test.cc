// The cone-beam shadow-centre offset (ba/shadow_correction.h): the closed form against the
// silhouette of the sphere traced ray by ray, and the engine's correction on pose problems whose
// observations are shadow centres (large spheres near the source, where it matters).
#include "ba/shadow_correction.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <iostream>
#include <random>
#include <string>

#include "ba/bundle_adjuster.h"
#include "camera/camera_model.h"
#include "figures.h"
#include "geometry/random_vector.h"
#include "geometry/rotation.h"

namespace carmba {
namespace ba {
namespace {

// The centre of the silhouette's image: the tangent cone's generators through the lens model,
// and the ellipse's centre as the midpoint of its extremes along the radial and tangential
// directions (for an ellipse (min + max) / 2 along any direction is its centre's coordinate).
// With distortion the outline is not an exact ellipse: the midpoints are then of the distorted
// outline, a reference to within the distortion's curvature over the blob.
Eigen::Vector2d SilhouetteCentrePx(const double* intr, const Eigen::Vector3d& c, double r) {
  const Eigen::Vector3d n = c.normalized();
  const Eigen::Vector3d u = n.cross(Eigen::Vector3d::UnitZ()).norm() > 1e-12
                                ? n.cross(Eigen::Vector3d::UnitZ()).normalized()
                                : Eigen::Vector3d::UnitX();
  const Eigen::Vector3d w = n.cross(u);
  const double sa = r / c.norm(), ca = std::sqrt(1 - sa * sa);
  Eigen::Vector2d p0;
  EXPECT_TRUE(ProjectCamPoint(intr, c.data(), p0.data()));
  const Eigen::Vector2d centre_uv(intr[kCx], intr[kCy]);
  Eigen::Vector2d radial = (p0 - centre_uv).normalized();
  if (!radial.allFinite()) radial = Eigen::Vector2d::UnitX();
  const Eigen::Vector2d tangential(-radial.y(), radial.x());
  double lo_r = 1e300, hi_r = -1e300, lo_t = 1e300, hi_t = -1e300;
  constexpr int kSteps = 200000;
  for (int k = 0; k < kSteps; ++k) {
    const double phi = 2 * M_PI * k / kSteps;
    const Eigen::Vector3d d = ca * n + sa * (std::cos(phi) * u + std::sin(phi) * w);
    Eigen::Vector2d q;
    EXPECT_TRUE(ProjectCamPoint(intr, d.data(), q.data()));
    lo_r = std::min(lo_r, q.dot(radial));
    hi_r = std::max(hi_r, q.dot(radial));
    lo_t = std::min(lo_t, q.dot(tangential));
    hi_t = std::max(hi_t, q.dot(tangential));
  }
  return 0.5 * (lo_r + hi_r) * radial + 0.5 * (lo_t + hi_t) * tangential;
}

TEST(SphereShadowOffset, ClosedFormEqualsTheTracedSilhouette) {
  const double pinhole[9] = {3000, 3000, 511.5, 511.5, 0, 0, 0, 0, 0};
  std::mt19937_64 rng(41);
  std::uniform_real_distribution<double> U(-1, 1);
  double largest = 0, worst = 0;
  for (int t = 0; t < 20; ++t) {
    const double depth = 450 + 150 * (U(rng) + 1);
    const Eigen::Vector2d xy = RandomVector<2>(U, rng) * 0.15 * depth;
    const Eigen::Vector3d c(xy[0], xy[1], depth);
    const double r = 1.5 + 2 * (U(rng) + 1);
    Eigen::Vector2d p;
    ASSERT_TRUE(ProjectCamPoint(pinhole, c.data(), p.data()));
    const Eigen::Vector2d offset = SphereShadowOffsetPx(pinhole, c, r);
    const Eigen::Vector2d traced = SilhouetteCentrePx(pinhole, c, r) - p;
    worst = std::max(worst, (offset - traced).cwiseAbs().maxCoeff());
    EXPECT_NEAR(offset.x(), traced.x(), 2e-6) << t;
    EXPECT_NEAR(offset.y(), traced.y(), 2e-6) << t;
    // Outward, along the radial line.
    EXPECT_GT(offset.dot(p - Eigen::Vector2d(511.5, 511.5)), 0);
    largest = std::max(largest, offset.norm());
  }
  std::cout << "closed form against the traced silhouette: largest offset " << largest
            << " px, largest difference " << worst << " px\n";
  testing::RecordFigure("shadow.traced_difference", "%.0e", worst);
  EXPECT_GT(largest, 0.01);  // the test covers offsets that matter (> 0.1 sigma of 0.03 px)
  // On the axis, for no radius, behind the source or around it: no offset.
  EXPECT_EQ(SphereShadowOffsetPx(pinhole, {0, 0, 500}, 3).norm(), 0);
  EXPECT_EQ(SphereShadowOffsetPx(pinhole, {40, 30, 500}, 0).norm(), 0);
  EXPECT_EQ(SphereShadowOffsetPx(pinhole, {40, 30, -500}, 3).norm(), 0);
  EXPECT_EQ(SphereShadowOffsetPx(pinhole, {1, 1, 2}, 3).norm(), 0);
}

// The area centroid (px) of the sphere's shadow through the lens model, by quadrature over the
// tangent cone's interior in its own coordinates (angle psi from its axis, azimuth phi): each
// direction through the lens, weighted by the pixel area it covers. Independent of the closed form.
Eigen::Vector2d ShadowAreaCentroidPx(const double* intr, const Eigen::Vector3d& c, double r) {
  const Eigen::Vector3d n = c.normalized();
  const Eigen::Vector3d u = n.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d w = n.cross(u);
  const double alpha = std::asin(r / c.norm());
  auto pixel = [&](double psi, double phi) {
    const Eigen::Vector3d d =
        std::cos(psi) * n + std::sin(psi) * (std::cos(phi) * u + std::sin(phi) * w);
    Eigen::Vector2d q;
    EXPECT_TRUE(ProjectCamPoint(intr, d.data(), q.data()));
    return q;
  };
  constexpr int kPsi = 300, kPhi = 256;
  const double dpsi = alpha / kPsi, dphi = 2 * M_PI / kPhi, h = 1e-7;
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  double area = 0;
  for (int i = 0; i < kPsi; ++i) {
    const double psi = (i + 0.5) * dpsi;
    for (int j = 0; j < kPhi; ++j) {
      const double phi = j * dphi;
      Eigen::Matrix2d J;
      J.col(0) = (pixel(psi + h, phi) - pixel(psi - h, phi)) / (2 * h);
      J.col(1) = (pixel(psi, phi + h) - pixel(psi, phi - h)) / (2 * h);
      const double da = std::abs(J.determinant()) * dpsi * dphi;
      sum += pixel(psi, phi) * da;
      area += da;
    }
  }
  return sum / area;
}

TEST(SphereShadowOffset, ThroughTheLensModel) {
  // Strong barrel distortion with tangential terms: the lens's curvature over the shadow moves
  // its centroid by as much as the cone does. The closed form (ellipse centre through the lens
  // plus the second-order curvature and area terms) against the quadrature.
  const double lens[9] = {3000, 3010, 500, 520, -0.3, 0.1, 4e-4, -3e-4, 0};
  double min_rel = 1e9, max_rel = 0;
  std::string pinhole_vs_lens;
  for (const Eigen::Vector3d& c : {Eigen::Vector3d(60, -45, 500), Eigen::Vector3d(-80, 70, 600)}) {
    Eigen::Vector2d p;
    ASSERT_TRUE(ProjectCamPoint(lens, c.data(), p.data()));
    const Eigen::Vector2d offset = SphereShadowOffsetPx(lens, c, 4.0);
    const Eigen::Vector2d reference = ShadowAreaCentroidPx(lens, c, 4.0) - p;
    std::cout << "offset " << offset.transpose() << " px, quadrature " << reference.transpose()
              << " px\n";
    EXPECT_LT((offset - reference).norm(), 0.02 * reference.norm());
    // The lens matters: the same camera without distortion gives a several times larger offset
    // (the barrel's compression towards the rim pulls the centroid back in).
    const double same_pinhole[9] = {3000, 3010, 500, 520, 0, 0, 0, 0, 0};
    std::cout << "without the distortion: " << SphereShadowOffsetPx(same_pinhole, c, 4.0).norm()
              << " px; relative difference from the quadrature "
              << (offset - reference).norm() / reference.norm() << "\n";
    EXPECT_GT((SphereShadowOffsetPx(same_pinhole, c, 4.0) - reference).norm(),
              3 * reference.norm());
    const double rel = (offset - reference).norm() / reference.norm();
    min_rel = std::min(min_rel, rel), max_rel = std::max(max_rel, rel);
    if (pinhole_vs_lens.empty()) {
      char b[100];
      std::snprintf(b,
                    sizeof b,
                    "%.4f px cone offset back to %.4f px",
                    SphereShadowOffsetPx(same_pinhole, c, 4.0).norm(),
                    reference.norm());
      pinhole_vs_lens = b;
    }
  }
  testing::RecordFigure("shadow.lens_quadrature", "%.2f-%.2f %%", 100 * min_rel, 100 * max_rel);
  testing::RecordFigure("shadow.lens_pulls_back", "%s", pinhole_vs_lens.c_str());
  // Without distortion the quadrature is the ellipse's centre.
  const double pinhole[9] = {3000, 3000, 500, 520, 0, 0, 0, 0, 0};
  const Eigen::Vector3d c(60, -45, 500);
  Eigen::Vector2d p;
  ASSERT_TRUE(ProjectCamPoint(pinhole, c.data(), p.data()));
  EXPECT_LT(
      (SphereShadowOffsetPx(pinhole, c, 4.0) - (ShadowAreaCentroidPx(pinhole, c, 4.0) - p)).norm(),
      1e-4);
}

// A pose problem: `n` markers of radius r in a 120 mm cluster 380 mm from the source, seen in
// 3 views at 2000 px focal length, with the shadow centres observed (+ noise of `sigma`).
struct ShadowScene {
  BaProblem problem;
  std::vector<Pose6> truth;
};

ShadowScene MakeScene(double r, double sigma, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0, 1);
  ShadowScene s;
  IntrinsicsGroup grp;
  grp.initial = {2000, 2000, 511.5, 511.5, 0, 0, 0, 0, 0};
  grp.free.fill(false);
  grp.width = grp.height = 1024;
  s.problem.groups.push_back(grp);
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < 10; ++i) {
    pts.emplace_back(60 * std::cos(0.7 * i), 55 * std::sin(1.3 * i), 25 * std::cos(2.1 * i));
    s.problem.markers.push_back({i, pts.back(), 1e-6 * Eigen::Matrix3d::Identity()});
  }
  s.problem.markers_free = false;
  for (int v = 0; v < 3; ++v) {
    Pose6 pose;
    pose << 0.3 * v - 0.3, 0.2, 0.1 * v, 20.0 * (v - 1), -15, 380;
    s.truth.push_back(pose);
    BaView view;
    view.id = "v" + std::to_string(v);
    view.kind = ViewKind::kObject;
    view.sigma_px = sigma;
    const Eigen::Matrix3d R = RotationOf(pose.data());
    for (int i = 0; i < 10; ++i) {
      const Eigen::Vector3d pc = R * pts[i] + pose.tail<3>();
      Eigen::Vector2d uv;
      EXPECT_TRUE(ProjectCamPoint(grp.initial.data(), pc.data(), uv.data()));
      uv += SphereShadowOffsetPx(grp.initial.data(), pc, r) + sigma * RandomVector<2>(g, rng);
      view.point_ids.push_back(i);
      view.uv_px.push_back(uv);
    }
    Pose6 init = pose;
    init.tail<3>() += Eigen::Vector3d(2, -1, 5);
    view.initial = init;
    s.problem.views.push_back(view);
  }
  return s;
}

TEST(ShadowCorrection, TheEngineRemovesTheBiasOfLargeSpheres) {
  // 10 mm spheres at 380 mm with 0.01 px noise: offsets of up to ~0.5 px, tens of sigma.
  const ShadowScene s = MakeScene(5.0, 0.01, 7);
  BaOptions o;
  BaProblem without = s.problem;  // radius unknown: the biased solve
  auto biased = SolveBundleAdjustment(without, o);
  ASSERT_TRUE(biased.ok()) << biased.status().message();
  EXPECT_FALSE(biased->shadow.evaluated);
  BaProblem with = s.problem;
  with.marker_radius_mm = 5.0;
  auto corrected = SolveBundleAdjustment(with, o);
  ASSERT_TRUE(corrected.ok()) << corrected.status().message();
  ASSERT_TRUE(corrected->shadow.evaluated);
  EXPECT_TRUE(corrected->shadow.applied);
  EXPECT_EQ(corrected->shadow.num_observations, 30);
  EXPECT_GT(corrected->shadow.max_sigma, 5);
  std::cout << "shadow offsets: max " << corrected->shadow.max_px << " px ("
            << corrected->shadow.max_sigma << " sigma), rms " << corrected->shadow.rms_px
            << " px; sigma0 biased " << biased->sigma0 << ", corrected " << corrected->sigma0
            << "\n";
  // Biased: the shadows look like a nearer object (a larger cluster): tz too small by many
  // sigmas, while the residuals do not show it (the offsets are nearly a radial scaling, which
  // a pose absorbs). Corrected: within 3 sigma of the truth.
  double biased_min = 1e9, biased_max = 0, corrected_max = 0;
  for (int v = 0; v < 3; ++v) {
    const int b = corrected->layout->view_block(v);
    const Eigen::MatrixXd C = corrected->Covariance({b});
    const double tz_c = corrected->block(b)[5], tz_b = biased->block(b)[5];
    const double sz = std::sqrt(C(5, 5));
    std::cout << "view " << v << ": tz error biased " << (tz_b - s.truth[v][5]) / sz
              << " sigma, corrected " << (tz_c - s.truth[v][5]) / sz << " sigma\n";
    biased_min = std::min(biased_min, std::abs(tz_b - s.truth[v][5]) / sz);
    biased_max = std::max(biased_max, std::abs(tz_b - s.truth[v][5]) / sz);
    corrected_max = std::max(corrected_max, std::abs(tz_c - s.truth[v][5]) / sz);
    EXPECT_GT(std::abs(tz_b - s.truth[v][5]) / sz, 10);
    EXPECT_LT(std::abs(tz_c - s.truth[v][5]) / sz, 3);
  }
  testing::RecordFigure("shadow.tz_biased", "%.0f-%.0f", biased_min, biased_max);
  testing::RecordFigure("shadow.tz_corrected", "%.1f", corrected_max);
  testing::RecordFigure("shadow.sigma0_biased", "%.2f", biased->sigma0);
  EXPECT_LT(biased->sigma0, 1.5);  // what makes the bias dangerous: nothing in the fit says so
  EXPECT_LT(corrected->sigma0, 1.5);
  // Switched off, the same problem gives the biased answer.
  o.shadow_correction = false;
  auto off = SolveBundleAdjustment(with, o);
  ASSERT_TRUE(off.ok());
  EXPECT_FALSE(off->shadow.evaluated);
  EXPECT_NEAR(off->block(off->layout->view_block(0))[5],
              biased->block(biased->layout->view_block(0))[5],
              1e-9);
}

TEST(ShadowCorrection, RigViewsUseTheirComposedPose) {
  // The same scene with each view's pose split into a held cam_from_rig and a free rig: the
  // offsets are evaluated at the composed pose, so the corrected answer is the same.
  const ShadowScene s = MakeScene(5.0, 0.01, 11);
  BaProblem plain = s.problem;
  plain.marker_radius_mm = 5.0;
  BaProblem rigged = plain;
  for (size_t v = 0; v < rigged.views.size(); ++v) {
    BaView& view = rigged.views[v];
    view.cam_from_rig << 0.2, -0.1 * v, 0.3, 5.0 * v, -3, 10;
    const Eigen::Matrix3d Rc = RotationOf(view.cam_from_rig.data()),
                          Rp = RotationOf(view.initial.data());
    const Eigen::AngleAxisd aa(Rc.transpose() * Rp);
    BaRig rig;
    rig.id = "r" + std::to_string(v);
    rig.initial.head<3>() = aa.angle() * aa.axis();
    rig.initial.tail<3>() = Rc.transpose() * (view.initial.tail<3>() - view.cam_from_rig.tail<3>());
    rigged.rigs.push_back(rig);
    view.rig = static_cast<int>(v);
  }
  auto a = SolveBundleAdjustment(plain, BaOptions());
  auto b = SolveBundleAdjustment(rigged, BaOptions());
  ASSERT_TRUE(a.ok()) << a.status().message();
  ASSERT_TRUE(b.ok()) << b.status().message();
  ASSERT_TRUE(a->shadow.applied);
  ASSERT_TRUE(b->shadow.applied);
  EXPECT_NEAR(a->shadow.max_px, b->shadow.max_px, 1e-9);
  EXPECT_NEAR(a->shadow.rms_px, b->shadow.rms_px, 1e-9);
  for (size_t v = 0; v < plain.views.size(); ++v) {
    const double* pa = a->block(a->layout->view_block(static_cast<int>(v)));
    const double* rb = b->block(b->layout->view_block(static_cast<int>(v)));
    const Eigen::Matrix3d Rc = RotationOf(rigged.views[v].cam_from_rig.data());
    const Eigen::Vector3d t =
        Rc * Eigen::Vector3d(rb[3], rb[4], rb[5]) + rigged.views[v].cam_from_rig.tail<3>();
    EXPECT_NEAR(t.z(), pa[5], 1e-6) << v;
    EXPECT_NEAR(t.x(), pa[3], 1e-6) << v;
  }
}

TEST(ShadowCorrection, SmallSpheresAreEvaluatedButNotCorrected) {
  // 1 mm spheres with 0.05 px noise: offsets below 0.1 sigma.
  BaProblem p = MakeScene(0.5, 0.05, 8).problem;
  p.marker_radius_mm = 0.5;
  auto r = SolveBundleAdjustment(p, BaOptions());
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE(r->shadow.evaluated);
  EXPECT_FALSE(r->shadow.applied);
  EXPECT_LT(r->shadow.max_sigma, kShadowCorrectionMinSigma);
  EXPECT_GT(r->shadow.max_px, 0);
}

TEST(ShadowCorrection, AnAbsurdRadiusIsAnError) {
  BaProblem p = MakeScene(0.5, 0.05, 9).problem;
  for (double bad : {-1.0, std::nan(""), 500.0}) {
    p.marker_radius_mm = bad;
    auto r = SolveBundleAdjustment(p, BaOptions());
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.status().message().find("sphere radius"), std::string::npos)
        << r.status().message();
  }
}

}  // namespace
}  // namespace ba
}  // namespace carmba
