// FitBlobPair (detect/blob_pair_fit.h): two touching dark blobs rendered on a sloped background
// with Poisson-like noise, 8-bit: both centres within their covariances over seeded trials (NEES
// per dof), one blob or a faint second one refused with the reason. And the marker detector's
// ring-noise floor: beads beside skin edges clipped at 255 in a real radiograph get a covariance.
#include "detect/blob_pair_fit.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>
#include <random>

#include "detect/marker_blobs.h"
#include "geometry/random_vector.h"
#include "util/image_codecs.h"

namespace carmba {
namespace {

// A sphere's shadow (chord length through a ball of radius R px, blurred by the focal spot),
// attenuating by `depth` at its centre, on background `bg` with a slope; noise sigma ~ sqrt(I).
cv::Mat RenderPair(const std::vector<cv::Point2d>& centres,
                   double R,
                   double depth,
                   double bg,
                   std::mt19937* rng,
                   double noise_scale = 0.25) {
  cv::Mat f(64, 64, CV_32F);
  for (int y = 0; y < f.rows; ++y) {
    for (int x = 0; x < f.cols; ++x) {
      double atten = 0;
      for (const cv::Point2d& c : centres) {
        // 4 x 4 sub-samples per pixel.
        for (int sy = 0; sy < 4; ++sy) {
          for (int sx = 0; sx < 4; ++sx) {
            const double dx = x - 0.375 + 0.25 * sx - c.x, dy = y - 0.375 + 0.25 * sy - c.y;
            const double q = 1 - (dx * dx + dy * dy) / (R * R);
            if (q > 0) atten += std::sqrt(q) / 16;
          }
        }
      }
      f.at<float>(y, x) = static_cast<float>((bg + 0.3 * x) * std::exp(-depth * atten));
    }
  }
  cv::GaussianBlur(f, f, cv::Size(5, 5), 0.7);
  std::normal_distribution<double> n01(0, 1);
  for (int y = 0; y < f.rows; ++y) {
    for (int x = 0; x < f.cols; ++x) {
      float& v = f.at<float>(y, x);
      v = static_cast<float>(
          std::round(std::clamp(v + noise_scale * std::sqrt(v) * n01(*rng), 0.0, 255.0)));
    }
  }
  return f;
}

TEST(BlobPairFit, TouchingBlobsSeparatedWithinTheirCovariances) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  double nees = 0;
  int n = 0, refused = 0;
  for (int trial = 0; trial < 60; ++trial) {
    const Eigen::Vector2d da = RandomVector<2>(u, rng), db = RandomVector<2>(u, rng);
    const cv::Point2d a(28 + da[0], 32 + da[1]), b(36 + db[0], 31 + db[1]);  // 8 px apart
    const cv::Mat f = RenderPair({a, b}, 3.0, 0.9, 150, &rng);
    std::string why;
    const auto fit = FitBlobPair(f, 0.5 * (a + b), 6.0, 0.15, 1.0, &why);
    if (!fit) {
      ++refused;
      continue;
    }
    for (const MarkerBlob& blob : fit->blobs) {
      const cv::Point2d truth = cv::norm(blob.uv_px - a) < cv::norm(blob.uv_px - b) ? a : b;
      const cv::Vec2d e(blob.uv_px.x - truth.x, blob.uv_px.y - truth.y);
      nees += (e.t() * blob.covariance_px2.inv() * e)[0];
      n += 2;
      EXPECT_LT(cv::norm(blob.uv_px - truth), 0.3) << trial;
    }
  }
  std::printf("blob pairs: %d refused, centre NEES per dof %.2f\n", refused, nees / n);
  EXPECT_EQ(refused, 0);
  // The Gaussian model of a sphere's shadow is not exact: its misfit is in the residual variance.
  EXPECT_GT(nees / n, 0.3);
  EXPECT_LT(nees / n, 3.0);
}

TEST(BlobPairFit, OneBlobOrAFaintSecondIsRefused) {
  std::mt19937 rng(8);
  std::string why;
  EXPECT_FALSE(
      FitBlobPair(RenderPair({{32, 32}}, 3.0, 0.9, 150, &rng), {32, 32}, 6.0, 0.15, 1.0, &why));
  EXPECT_FALSE(why.empty());
  EXPECT_FALSE(FitBlobPair(
      RenderPair({{28, 32}, {36, 32}}, 3.0, 0.05, 150, &rng), {32, 32}, 6.0, 0.15, 1.0, &why));
  EXPECT_NE(why.find("fainter"), std::string::npos) << why;
}

TEST(MarkerBlobs, EveryBeadOfARealRadiographHasACovariance) {
  // Frame 99 of the Autoscoper wrist set, camera 2: beads next to skin edges clipped at 255 had a
  // zero covariance (the ring's noise measured as 0) before the floor.
  const std::string path = std::string(CARMBA_SOURCE_DIR) +
                           "/data/real/autoscoper-wrist/images/cam02/xr_rad_uln_cam02_UND.0099.tif";
  const cv::Mat image = carmba::ImRead(path, cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(image.empty()) << path;
  MarkerBlobOptions o;
  o.diameter_px = {4.4, 9.2};
  o.min_contrast = 0.15;
  const MarkerBlobDetection d = DetectMarkerBlobs(image, o);
  ASSERT_TRUE(d.ok) << d.reason;
  ASSERT_GE(d.blobs.size(), 10u);
  for (const MarkerBlob& b : d.blobs) {
    EXPECT_GT(b.covariance_px2(0, 0), 1e-6) << b.uv_px;
    EXPECT_GT(cv::determinant(b.covariance_px2), 0) << b.uv_px;
  }
}

}  // namespace
}  // namespace carmba
