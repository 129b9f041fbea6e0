// X-ray rendering: Beer-Lambert line integrals, blob centroids vs projected centres, noise,
// determinism, image round trips.
#include "sim/xray_render.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "camera/camera_model.h"
#include "scratch.h"
#include "sim/phantom.h"
#include "util/image_codecs.h"

namespace carmba::sim {
namespace {

// Render values are float32 grey levels: relative rounding about 1e-7.
constexpr double kTolRelative = 1e-5;
// The task's requirement on the dark-blob centroid of a sphere in a noiseless render.
constexpr double kCentroidTolPx = 0.05;

Camera MakeCamera(int size, double f, double k1) {
  Camera c;
  c.width = c.height = size;
  c.params = {f, 1.09 * f, 0.5 * (size - 1) + 1.3, 0.5 * (size - 1) - 0.8, k1, 0.0, 0.0, 0.0, 0.0};
  return c;
}

RenderOptions Noiseless(int ss) {
  RenderOptions o;
  o.supersampling = ss;
  o.white_level = 200;
  o.circular_fov = false;
  return o;
}

// Intensity-weighted centroid of the dark blob around `guess`: weights = local background minus
// grey level, background = median of an annulus outside the blob.
Eigen::Vector2d BlobCentroid(const cv::Mat& gray, const Eigen::Vector2d& guess, double r_px) {
  const int r_in = static_cast<int>(std::ceil(r_px + 3)), r_out = r_in + 4;
  std::vector<float> ring;
  for (int v = -r_out; v <= r_out; ++v) {
    for (int u = -r_out; u <= r_out; ++u) {
      const double d = std::hypot(u, v);
      if (d >= r_in && d <= r_out) {
        ring.push_back(gray.at<float>(static_cast<int>(std::lround(guess.y())) + v,
                                      static_cast<int>(std::lround(guess.x())) + u));
      }
    }
  }
  std::nth_element(ring.begin(), ring.begin() + ring.size() / 2, ring.end());
  const double bg = ring[ring.size() / 2];
  double sw = 0, su = 0, sv = 0;
  const int u0 = static_cast<int>(std::lround(guess.x())),
            v0 = static_cast<int>(std::lround(guess.y()));
  for (int v = v0 - r_in; v <= v0 + r_in; ++v) {
    for (int u = u0 - r_in; u <= u0 + r_in; ++u) {
      const double w = std::max(0.0, bg - gray.at<float>(v, u));
      sw += w;
      su += w * u;
      sv += w * v;
    }
  }
  return {su / sw, sv / sw};
}

TEST(XrayRender, SlabAndSphereLineIntegrals) {
  const Camera cam = MakeCamera(101, 1500, 0.0);
  const auto materials = DefaultMaterials();
  Phantom ph;
  BoxPrimitive slab;
  slab.half_size_mm = Eigen::Vector3d(500, 500, 10);  // 20 mm of water
  slab.mu_per_mm = materials.at("water");
  ph.boxes.push_back(slab);
  SpherePrimitive ball;
  ball.radius_mm = 2;
  ball.mu_per_mm = materials.at("steel");
  ball.host_box = 0;
  ph.spheres.push_back(ball);
  // Slab normal along the optical axis, ball at the centre, 800 mm from the source.
  const PlacedPhantom placed{&ph, Rigid3::FromRvec(Eigen::Vector3d::Zero(), {0, 0, 800})};
  auto img = RenderXray(cam, {placed}, Noiseless(1));
  ASSERT_TRUE(img.ok()) << img.status().message();
  // The central ray of the principal point crosses 20 mm, of which 4 mm are steel.
  const double expected_centre = 200 * std::exp(-(slab.mu_per_mm * (20 - 4) + ball.mu_per_mm * 4));
  const Eigen::Vector2d pp(cam.params[kCx], cam.params[kCy]);
  // Principal point (cx, cy) is not a pixel centre: sample the analytic value at the pixel
  // nearest to it and compute its exact path lengths.
  const int u = static_cast<int>(std::lround(pp.x())), v = static_cast<int>(std::lround(pp.y()));
  double xy[2];
  const double uv[2] = {static_cast<double>(u), static_cast<double>(v)};
  ASSERT_TRUE(UnprojectToNormalized(cam.params.data(), uv, xy));
  const Eigen::Vector3d d = Eigen::Vector3d(xy[0], xy[1], 1).normalized();
  const double slab_len = 20 / d.z();
  const double b = d.dot(Eigen::Vector3d(0, 0, 800));
  const double chord = 2 * std::sqrt(4 - (800 * 800 - b * b));
  const double expected =
      200 * std::exp(-(slab.mu_per_mm * (slab_len - chord) + ball.mu_per_mm * chord));
  EXPECT_NEAR(img->at<float>(v, u), expected, kTolRelative * expected);
  EXPECT_NEAR(expected, expected_centre, 0.05 * expected_centre);  // sanity: nearly central
  // A corner pixel misses the ball: only the slab, obliquely.
  const double uv0[2] = {0, 0};
  ASSERT_TRUE(UnprojectToNormalized(cam.params.data(), uv0, xy));
  const double len0 = 20 * std::sqrt(xy[0] * xy[0] + xy[1] * xy[1] + 1);
  EXPECT_NEAR(img->at<float>(0, 0), 200 * std::exp(-slab.mu_per_mm * len0), 200 * kTolRelative);
}

TEST(XrayRender, MetalIsDarkOnBrightAndFovIsCircular) {
  const Camera cam = MakeCamera(128, 1200, -1.0);
  auto plate =
      MakePlatePhantom(PlateSpec{3, 3, 10.0, 3.0, 5.0, 5.0, "steel", "pmma"}, DefaultMaterials());
  ASSERT_TRUE(plate.ok());
  Rigid3 pose = Rigid3::FromRvec(Eigen::Vector3d::Zero(), {-10, -10, 700});
  RenderOptions o = Noiseless(2);
  o.circular_fov = true;
  o.outside_fov_gray = 7;
  auto img = RenderXray(cam, {{&*plate, pose}}, o);
  ASSERT_TRUE(img.ok()) << img.status().message();
  auto uv = ProjectSphereCenters(cam, {&*plate, pose});
  ASSERT_TRUE(uv.ok());
  const float centre = img->at<float>(static_cast<int>(std::lround((*uv)[4].y())),
                                      static_cast<int>(std::lround((*uv)[4].x())));
  const float plate_bg = img->at<float>(static_cast<int>(std::lround((*uv)[4].y())) + 8,
                                        static_cast<int>(std::lround((*uv)[4].x())));
  EXPECT_LT(centre, 0.2 * plate_bg);  // 3 mm of steel transmits ~6 %
  EXPECT_GT(plate_bg, 150);
  EXPECT_FLOAT_EQ(img->at<float>(0, 0), 7.0f);  // corner outside the circle
}

// The centroid of a rendered sphere's dark blob is the projection of its centre, to 0.05 px, in
// a noiseless render of a tilted plate with strong barrel and pincushion distortion. Prints the
// largest perspective bias found.
TEST(XrayRender, BlobCentroidMatchesProjectedCentre) {
  // Barrel; pincushion; pincushion with k2 and tangential terms (as calib_7x6_pincushion).
  for (int variant = 0; variant < 3; ++variant) {
    const double k1 = variant == 0 ? -2.5 : 3.0;
    Camera cam = MakeCamera(408, 2061.389, k1);
    if (variant == 2) {
      cam.params[kK2] = 20.0;
      cam.params[kP1] = 0.0005;
      cam.params[kP2] = -0.0003;
    }
    auto plate = MakePlatePhantom(PlateSpec{5, 5, 20.0, 3.06, 5.0, 10.0, "steel", "pmma"},
                                  DefaultMaterials());
    ASSERT_TRUE(plate.ok());
    const Rigid3 pose = Rigid3::FromRvec(Eigen::Vector3d(0.35, -0.3, 0.2), {-38, -42, 720});
    RenderOptions o = Noiseless(5);
    auto img = RenderXray(cam, {{&*plate, pose}}, o);
    ASSERT_TRUE(img.ok()) << img.status().message();
    auto uv = ProjectSphereCenters(cam, {&*plate, pose});
    ASSERT_TRUE(uv.ok());
    double worst = 0;
    for (size_t k = 0; k < uv->size(); ++k) {
      const Eigen::Vector3d c = pose * plate->spheres[k].center_mm;
      const double r_px = SphereImageRadius(cam, c, plate->spheres[k].radius_mm, (*uv)[k]);
      const Eigen::Vector2d centroid = BlobCentroid(*img, (*uv)[k], r_px);
      const double err = (centroid - (*uv)[k]).norm();
      worst = std::max(worst, err);
      EXPECT_LT(err, kCentroidTolPx) << "variant " << variant << " sphere " << k;
    }
    std::printf("distortion %s: largest |blob centroid - projected centre| = %.4f px\n",
                variant == 0   ? "k1 -2.5"
                : variant == 1 ? "k1 +3"
                               : "k1 3 k2 20 p1 5e-4 p2 -3e-4",
                worst);
  }
}

// Perspective bias of a large sphere far off-axis (no distortion): the blob centroid is pushed
// outwards, away from the principal point, as the projected ellipse's centre is.
TEST(XrayRender, PerspectiveBiasOfLargeOffAxisSphere) {
  const Camera cam = MakeCamera(408, 2061.389, 0.0);
  Phantom ph;
  SpherePrimitive s;
  s.radius_mm = 5;
  s.mu_per_mm = 0.94;
  ph.spheres.push_back(s);
  const Rigid3 pose = Rigid3::FromRvec(Eigen::Vector3d::Zero(), {45, 0, 600});
  auto img = RenderXray(cam, {{&ph, pose}}, Noiseless(5));
  ASSERT_TRUE(img.ok());
  auto uv = ProjectSphereCenters(cam, {&ph, pose});
  ASSERT_TRUE(uv.ok());
  const double r_px = SphereImageRadius(cam, pose.t, s.radius_mm, (*uv)[0]);
  const Eigen::Vector2d c = BlobCentroid(*img, (*uv)[0], r_px);
  const double bias = c.x() - (*uv)[0].x();
  // The silhouette is an ellipse whose centre lies outwards of the projected centre by
  //   f * ((tan(theta + alpha) + tan(theta - alpha)) / 2 - tan(theta)),
  // theta the off-axis angle of the centre, alpha = asin(r / distance) the cone's half-angle.
  const double theta = std::atan2(45.0, 600.0), alpha = std::asin(5.0 / std::hypot(45.0, 600.0));
  const double ellipse_bias =
      cam.params[kFx] *
      (0.5 * (std::tan(theta + alpha) + std::tan(theta - alpha)) - std::tan(theta));
  std::printf(
      "10 mm sphere 45 mm off-axis at 600 mm: centroid - projection = %+.4f px (u), silhouette "
      "ellipse centre offset %+.4f px\n",
      bias,
      ellipse_bias);
  // The attenuation-weighted centroid is not exactly the ellipse centre, and the centroid
  // estimator itself is good to a few thousandths of a pixel at 5x5 supersampling.
  constexpr double kBiasAgreementPx = 0.003;
  EXPECT_NEAR(bias, ellipse_bias, kBiasAgreementPx);
  EXPECT_NEAR(c.y(), (*uv)[0].y(), 0.01);
}

TEST(XrayRender, FieldOfViewEdgeFallsOffLinearly) {
  const Camera cam = MakeCamera(101, 1000, 0.0);
  Phantom empty;
  RenderOptions o = Noiseless(1);
  o.circular_fov = true;
  o.fov_radius_px = 40;
  o.fov_edge_px = 10;
  auto img = RenderXray(cam, {{&empty, Rigid3()}}, o);
  ASSERT_TRUE(img.ok());
  // Along the row through the FOV centre (50, 50): full white up to r = 30, half at r = 35.
  EXPECT_FLOAT_EQ(img->at<float>(50, 50 + 30), 200.0f);
  EXPECT_NEAR(img->at<float>(50, 50 + 35), 100.0, 1e-3);
  EXPECT_NEAR(img->at<float>(50, 50 - 38), 40.0, 1e-3);
  EXPECT_FLOAT_EQ(img->at<float>(50, 50 + 45), 0.0f);
}

// The intensifier's fall-off profile and the heel gradient follow the formula of the header
// (step 3) on an empty, noise-free field.
TEST(XrayRender, VignettingProfileAndHeelGradient) {
  const Camera cam = MakeCamera(101, 1000, 0.0);
  Phantom empty;
  RenderOptions o = Noiseless(1);
  o.circular_fov = true;
  o.fov_radius_px = 40;  // centre (50, 50)
  o.vignetting = 0.22;
  o.vignetting_power = 3;
  o.heel = 0.08;
  o.heel_direction_deg = 90;  // brighter towards +y (down)
  auto img = RenderXray(cam, {{&empty, Rigid3()}}, o);
  ASSERT_TRUE(img.ok()) << img.status().message();
  auto expect = [&](int u, int v) {
    const double r = std::hypot(u - 50.0, v - 50.0) / 40.0;
    return 200.0 * (1 - 0.22 * std::pow(r, 3)) * (1 + 0.08 * (v - 50.0) / 40.0);
  };
  for (const auto& [u, v] :
       std::vector<std::pair<int, int>>{{50, 50}, {80, 50}, {50, 85}, {50, 15}, {70, 70}}) {
    EXPECT_NEAR(img->at<float>(v, u), expect(u, v), kTolRelative * 200) << u << ", " << v;
  }
  // +-8 % at the rim along the heel direction (the fall-off the same on both sides).
  EXPECT_NEAR(img->at<float>(90, 50) / img->at<float>(10, 50), 1.08 / 0.92, 1e-5);
  o.vignetting_power = 0.1;
  EXPECT_FALSE(RenderXray(cam, {{&empty, Rigid3()}}, o).ok());
  o.vignetting_power = 2;
  o.heel = 0.6;
  EXPECT_FALSE(RenderXray(cam, {{&empty, Rigid3()}}, o).ok());
}

// Veiling glare spreads a fraction g of the light over the field: an opaque object's shadow is
// lifted to about g times the surrounding level, a uniform field (away from the FOV rim) keeps
// its level, and outside the FOV nothing is added.
TEST(XrayRender, VeilingGlareLiftsShadowsAndKeepsUniformFields) {
  const Camera cam = MakeCamera(161, 1000, 0.0);
  Phantom ph;
  SpherePrimitive s;
  s.radius_mm = 4;  // ~7 px radius at 600 mm
  s.mu_per_mm = 50;  // opaque
  ph.spheres.push_back(s);
  const Rigid3 pose = Rigid3::FromRvec({0, 0, 0}, {0, 0, 600});
  RenderOptions o = Noiseless(2);
  o.circular_fov = true;
  o.fov_radius_px = 75;
  auto plain = RenderXray(cam, {{&ph, pose}}, o);
  o.glare_fraction = 0.2;
  o.glare_sigma_px = 30;
  auto glared = RenderXray(cam, {{&ph, pose}}, o);
  ASSERT_TRUE(plain.ok() && glared.ok()) << glared.status().message();
  const int uc = static_cast<int>(std::lround(cam.params[2])),
            vc = static_cast<int>(std::lround(cam.params[3]));
  EXPECT_LT(plain->at<float>(vc, uc), 1e-3);
  // The shadow's centre: g times the spread light, a little less than g * 200 (the FOV's edge
  // and the shadow itself are in the kernel).
  EXPECT_GT(glared->at<float>(vc, uc), 0.6 * 0.2 * 200);
  EXPECT_LT(glared->at<float>(vc, uc), 0.2 * 200);
  // The open field 35 px from the shadow keeps its level to a few percent (the shadow and the
  // rim take a little of the spread light).
  EXPECT_NEAR(glared->at<float>(vc, uc + 35), plain->at<float>(vc, uc + 35), 0.06 * 200);
  EXPECT_EQ(glared->at<float>(0, 0), 0.0f);  // outside the FOV
  o.glare_fraction = 0.95;
  EXPECT_FALSE(RenderXray(cam, {{&ph, pose}}, o).ok());
}

TEST(XrayRender, QuantumNoiseHasPoissonVariance) {
  const Camera cam = MakeCamera(200, 1500, 0.0);
  Phantom empty;
  RenderOptions o = Noiseless(1);
  o.photons_per_pixel = 400;  // grey variance = white^2 / N = 100
  o.seed = 42;
  auto img = RenderXray(cam, {{&empty, Rigid3()}}, o);
  ASSERT_TRUE(img.ok());
  cv::Scalar mean, stddev;
  cv::meanStdDev(*img, mean, stddev);
  EXPECT_NEAR(mean[0], 200, 0.2);
  // 40000 samples: the sample variance is within 2 % of the truth with >99 % probability.
  EXPECT_NEAR(stddev[0] * stddev[0], 100, 5);
  // Blur reduces it.
  o.blur_sigma_px = 1.0;
  auto blurred = RenderXray(cam, {{&empty, Rigid3()}}, o);
  ASSERT_TRUE(blurred.ok());
  cv::meanStdDev(*blurred, mean, stddev);
  EXPECT_LT(stddev[0], 5);
}

TEST(XrayRender, DeterministicPerSeed) {
  const Camera cam = MakeCamera(96, 1000, -1.0);
  auto plate =
      MakePlatePhantom(PlateSpec{2, 3, 10.0, 3.0, 4.0, 5.0, "steel", "pmma"}, DefaultMaterials());
  ASSERT_TRUE(plate.ok());
  const Rigid3 pose = Rigid3::FromRvec({0.1, 0.2, 0.3}, {-10, -5, 600});
  RenderOptions o = Noiseless(2);
  o.photons_per_pixel = 1000;
  o.read_noise_gray = 1;
  o.blur_sigma_px = 0.5;
  o.seed = 5;
  auto a = RenderXray(cam, {{&*plate, pose}}, o);
  auto b = RenderXray(cam, {{&*plate, pose}}, o);
  o.seed = 6;
  auto c = RenderXray(cam, {{&*plate, pose}}, o);
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  EXPECT_EQ(cv::norm(*a, *b, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(*a, *c, cv::NORM_INF), 0.0);
}

TEST(XrayRender, ImagesWrittenAndReadBackAreIdentical) {
  const Camera cam = MakeCamera(120, 1200, -1.5);
  auto plate =
      MakePlatePhantom(PlateSpec{3, 3, 12.0, 3.0, 5.0, 5.0, "steel", "pmma"}, DefaultMaterials());
  ASSERT_TRUE(plate.ok());
  RenderOptions o = Noiseless(3);
  o.circular_fov = true;
  o.photons_per_pixel = 2000;
  o.seed = 3;
  auto gray = RenderXray(cam, {{&*plate, Rigid3::FromRvec({0.2, 0, 0}, {-12, -12, 650})}}, o);
  ASSERT_TRUE(gray.ok());
  const test::ScratchDir scratch("sim_roundtrip");
  const std::string& dir = scratch.path();
  for (const auto& [ext, bits] :
       std::vector<std::pair<std::string, int>>{{"png", 8}, {"png", 16}, {"pgm", 8}, {"pgm", 16}}) {
    cv::Mat scaled = bits == 16 ? cv::Mat(*gray * 250.0) : *gray;
    const cv::Mat out = ToOutputImage(scaled, bits);
    ASSERT_EQ(out.depth(), bits == 16 ? CV_16U : CV_8U);
    const std::string path = dir + "/img" + std::to_string(bits) + "." + ext;
    ASSERT_TRUE(WriteImage(path, out).ok());
    const cv::Mat back = carmba::ImRead(path, cv::IMREAD_UNCHANGED);
    ASSERT_EQ(back.type(), out.type()) << path;
    EXPECT_EQ(cv::norm(back, out, cv::NORM_INF), 0.0) << path;
    // The written grey is the float grey rounded and saturated.
    const double written = bits == 16 ? out.at<uint16_t>(60, 60) : out.at<uint8_t>(60, 60);
    EXPECT_EQ(written,
              std::min(bits == 16 ? 65535.0 : 255.0,
                       std::round(static_cast<double>(scaled.at<float>(60, 60)))));
  }
  EXPECT_FALSE(WriteImage(dir + "/x.jpg", ToOutputImage(*gray, 8)).ok());
}

TEST(XrayRender, RejectsBadOptionsAndGeometry) {
  const Camera cam = MakeCamera(64, 800, 0.0);
  Phantom ph;
  SpherePrimitive s;
  s.radius_mm = 5;
  s.mu_per_mm = 1;
  ph.spheres.push_back(s);
  RenderOptions o = Noiseless(1);
  o.supersampling = 0;
  EXPECT_FALSE(RenderXray(cam, {{&ph, Rigid3()}}, o).ok());
  o = Noiseless(1);
  o.vignetting = 1.5;
  EXPECT_FALSE(RenderXray(cam, {{&ph, Rigid3()}}, o).ok());
  // A sphere around the source.
  auto r = RenderXray(cam, {{&ph, Rigid3::FromRvec({0, 0, 0}, {0, 0, 2})}}, Noiseless(1));
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("in front of the source"), std::string::npos);
}

TEST(XrayRender, BackgroundFromRealDicomFrame) {
  const std::string dcm = "/usr/share/doc/libgdcm3.0/examples/00191113.dcm";
  if (!std::filesystem::exists(dcm)) GTEST_SKIP() << dcm << " not installed";
  auto gain = LoadBackgroundGain(dcm, 64, 64, 0.5, 0.6);
  ASSERT_TRUE(gain.ok()) << gain.status().message();
  double lo, hi;
  cv::minMaxLoc(*gain, &lo, &hi);
  EXPECT_GE(lo, 0.5 - 1e-6);
  EXPECT_LE(hi, 1.0 + 1e-6);
  EXPECT_GT(hi - lo, 0.1);  // real anatomy has contrast
  EXPECT_FALSE(LoadBackgroundGain("/nonexistent.dcm", 64, 64, 0.5, 1).ok());
  EXPECT_FALSE(LoadBackgroundGain(dcm, 64, 64, 1.5, 1).ok());
  // Another part of the frame by its crop centre: the default is the central square; an off-centre
  // one differs; one beyond the frame's edge takes the square at that edge; outside [0, 1] is an
  // error.
  auto centre = LoadBackgroundGain(dcm, 64, 64, 0.5, 0.6, cv::Point2d(0.5, 0.5));
  auto corner = LoadBackgroundGain(dcm, 64, 64, 0.5, 0.6, cv::Point2d(0.2, 0.8));
  auto edge = LoadBackgroundGain(dcm, 64, 64, 0.5, 0.6, cv::Point2d(0.0, 1.0));
  auto inside = LoadBackgroundGain(dcm, 64, 64, 0.5, 0.6, cv::Point2d(0.3, 0.7));
  ASSERT_TRUE(centre.ok() && corner.ok() && edge.ok() && inside.ok());
  EXPECT_EQ(cv::norm(*centre, *gain, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(*corner, *gain, cv::NORM_INF), 0.05);
  EXPECT_EQ(cv::norm(*edge, *inside, cv::NORM_INF), 0.0);  // 0.6 of the side: 0.3 is the edge
  EXPECT_FALSE(LoadBackgroundGain(dcm, 64, 64, 0.5, 0.6, cv::Point2d(1.2, 0.5)).ok());
  // Corrupt files: one error, and nothing printed by GDCM or libpng.
  const test::ScratchDir scratch("sim_background");
  const std::string& dir = scratch.path();
  {
    std::ifstream in(dcm, std::ios::binary);
    std::string head(3000, '\0');
    in.read(&head[0], head.size());
    std::ofstream(dir + "/truncated.dcm", std::ios::binary) << head;
    std::ofstream(dir + "/truncated.png", std::ios::binary) << "\x89PNG\r\n\x1a\n" << head;
  }
  for (const std::string name : {"truncated.dcm", "truncated.png"}) {
    testing::internal::CaptureStderr();
    auto bad = LoadBackgroundGain(dir + "/" + name, 64, 64, 0.5, 1);
    const std::string printed = testing::internal::GetCapturedStderr();
    ASSERT_FALSE(bad.ok()) << name;
    EXPECT_NE(bad.status().message().find(name), std::string::npos);
    EXPECT_EQ(printed, "") << name;
  }
}

}  // namespace
}  // namespace carmba::sim
