// The CT anatomy's DRR (sim/ct_anatomy.h) on volumes whose line integrals are known: a water cube
// seen straight through its centre and obliquely, bone and air, the cube moving with the object,
// and the readers' errors.
#include "sim/ct_anatomy.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "scratch.h"

namespace carmba::sim {
namespace {

constexpr double kMu = 0.02;  // 1/mm, water

// A cube of 21^3 voxels of 1 mm holding `hu`: its voxel centres span 20 mm along each axis.
CtVolume Cube(float hu) {
  CtVolume v;
  v.columns = v.rows = v.slices = 21;
  v.spacing_mm = Eigen::Vector3d::Ones();
  v.slice_thickness_mm = 1;
  v.hu.assign(21 * 21 * 21, hu);
  return v;
}

// A pinhole camera whose principal point (32, 32) lies on the DRR's grid of every 2 px.
Camera Pinhole() {
  Camera c;
  c.width = c.height = 64;
  c.params = {500, 500, 32, 32, 0, 0, 0, 0, 0};
  return c;
}

// The cube centred on the object's origin, the object 500 mm in front of the source.
CtAnatomy AnatomyOf(const CtVolume& cube) {
  CtAnatomy a;
  a.volume = std::make_shared<const CtVolume>(cube);
  a.object_from_ct = {Eigen::Matrix3d::Identity(), -CtVolumeCentre(cube)};
  a.mu_water_per_mm = kMu;
  return a;
}

const Rigid3 kCamFromObject{Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, 500)};

TEST(CtAnatomy, WaterCubeAttenuatesByItsPathLength) {
  const cv::Mat g = CtAnatomyGain(AnatomyOf(Cube(0)), Pinhole(), kCamFromObject);
  ASSERT_EQ(g.type(), CV_32F);
  ASSERT_EQ(g.rows, 64);
  // Through the centre: 20 mm of water, sampled every 1 mm.
  EXPECT_NEAR(g.at<float>(32, 32), std::exp(-kMu * 20), 1e-6);
  // Obliquely (pixel 40: 8 mm off axis at 500 mm, leaving through the back face): 20 mm / cos,
  // within one sampling step of mu.
  const double length = 20 * std::hypot(1.0, 8.0 / 500);
  EXPECT_NEAR(-std::log(g.at<float>(32, 40)), kMu * length, kMu * 1.0);
  // Between grid points (pixel 41) the line integral is bilinear: between its neighbours'.
  const double l40 = -std::log(g.at<float>(32, 40)), l42 = -std::log(g.at<float>(32, 42));
  EXPECT_NEAR(-std::log(g.at<float>(32, 41)), 0.5 * (l40 + l42), 1e-6);
  // Past the cube's shadow (more than 10 mm off axis at the cube): nothing.
  EXPECT_EQ(g.at<float>(0, 0), 1.0f);
  EXPECT_EQ(g.at<float>(32, 63), 1.0f);
}

TEST(CtAnatomy, HounsfieldUnitsScaleWaterAndAirIsFree) {
  EXPECT_NEAR(CtAnatomyGain(AnatomyOf(Cube(1000)), Pinhole(), kCamFromObject).at<float>(32, 32),
              std::exp(-2 * kMu * 20),
              1e-6);
  EXPECT_EQ(CtAnatomyGain(AnatomyOf(Cube(-1000)), Pinhole(), kCamFromObject).at<float>(32, 32),
            1.0f);
  EXPECT_EQ(CtAnatomyGain(AnatomyOf(Cube(-3024)), Pinhole(), kCamFromObject).at<float>(32, 32),
            1.0f);
}

TEST(CtAnatomy, MovesWithTheObject) {
  const CtAnatomy a = AnatomyOf(Cube(0));
  // Pixel 56 looks 24 mm off axis at 500 mm: beside the cube, until the object moves 20 mm.
  EXPECT_EQ(CtAnatomyGain(a, Pinhole(), kCamFromObject).at<float>(32, 56), 1.0f);
  const Rigid3 moved{Eigen::Matrix3d::Identity(), Eigen::Vector3d(20, 0, 500)};
  const cv::Mat g = CtAnatomyGain(a, Pinhole(), moved);
  EXPECT_LT(g.at<float>(32, 56), 0.7f);
  EXPECT_EQ(g.at<float>(32, 32), 1.0f);
}

TEST(CtAnatomy, NoRaysOutsideTheFieldOfView) {
  const CtAnatomy a = AnatomyOf(Cube(0));
  const cv::Mat all = CtAnatomyGain(a, Pinhole(), kCamFromObject);
  FovCircle fov;
  fov.u = fov.v = 32;
  fov.r = 3;  // rays out to 3 + 2 grid steps = 7 px from the centre
  const cv::Mat inside = CtAnatomyGain(a, Pinhole(), kCamFromObject, &fov);
  EXPECT_EQ(inside.at<float>(32, 32), all.at<float>(32, 32));
  EXPECT_EQ(inside.at<float>(32, 34), all.at<float>(32, 34));
  EXPECT_LT(all.at<float>(32, 42), 1.0f);  // in the cube's shadow, 10 px out
  EXPECT_EQ(inside.at<float>(32, 42), 1.0f);
}

TEST(CtAnatomy, ReadingNamesWhatIsWrong) {
  const test::ScratchDir dir("ct_anatomy");
  auto absent = ReadAnatomyCt(dir.File("absent.inv3"));
  ASSERT_FALSE(absent.ok());
  EXPECT_NE(absent.status().message().find("absent.inv3"), std::string::npos)
      << absent.status().message();
  std::ofstream(dir.File("volume.raw")) << "not a CT";
  auto raw = ReadAnatomyCt(dir.File("volume.raw"));
  ASSERT_FALSE(raw.ok());
  EXPECT_NE(raw.status().message().find("expected an InVesalius project (.inv3) or a directory"),
            std::string::npos)
      << raw.status().message();
  EXPECT_FALSE(ReadAnatomyCt(dir.path()).ok());  // a directory without a CT series
}

}  // namespace
}  // namespace carmba::sim
