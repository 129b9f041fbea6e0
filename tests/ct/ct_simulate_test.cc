#include "ct/ct_simulate.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "ct/ct_phantom.h"
#include "ct/ct_test_util.h"
#include "ct/ct_volume.h"

namespace carmba {
namespace {

namespace fs = std::filesystem;
using testing::ScratchDir;
using testing::WriteText;

// Stored values are rounded to integers with slope 1: the read-back differs by at most 0.5 HU
// (plus float rounding).
constexpr double kRoundTripTolHu = 0.5 + 1e-3;
// Positions are written as DICOM decimal strings of up to 16 characters.
constexpr double kGeometryTolMm = 1e-6;

const char* kSceneMarkersYaml =
    "id,x_mm,y_mm,z_mm\n"
    "1,0.3,-0.2,0.1\n"
    "2,6.0,1.0,-2.0\n";

std::string SmallScene(const std::string& ct_extra, int slices = 24) {
  return "kind: ct\nseed: 7\nmarkers:\n  csv: markers.csv\n  diameter_mm: 2\nct:\n"
         "  columns: 48\n  rows: 40\n  pixel_spacing_mm: 0.5\n  slice_spacing_mm: 0.75\n"
         "  centre_mm: [3, 0, 0]\n  slices: " +
         std::to_string(slices) + "\n" + ct_extra;
}

TEST(CtSimulate, SeriesReadsBackAsTheVolumeAndGeometryThatWentIn) {
  for (double tilt : {0.0, 20.0}) {
    ScratchDir dir("roundtrip");
    WriteText(dir.File("markers.csv"), kSceneMarkersYaml);
    WriteText(dir.File("scene.yaml"),
              SmallScene("  tilt_deg: " + std::to_string(tilt) + "\n  rescale_slope: 0.5\n" +
                         "  rescale_intercept: -1000\n"));
    YamlMap scene = YamlMap::Load(dir.File("scene.yaml"));
    CtScene parsed;
    ASSERT_TRUE(ParseCtScene(scene, &parsed).ok());
    CtVolume expected = parsed.geometry;
    ASSERT_TRUE(VoxelisePhantom(parsed.phantom, parsed.voxelise, &expected).ok());

    YamlMap scene2 = YamlMap::Load(dir.File("scene.yaml"));
    nlohmann::json truth;
    const Status s = SimulateCtScene(scene2, dir.File("out"), &truth);
    ASSERT_TRUE(s.ok()) << s.message();
    ASSERT_EQ(truth["markers"].size(), 2u);
    EXPECT_DOUBLE_EQ(truth["markers"][1]["x_mm"].get<double>(), 6.0);

    auto read = ReadCtSeries(dir.File("out/ct"));
    ASSERT_TRUE(read.ok()) << read.status().message();
    EXPECT_EQ(read->columns, 48);
    EXPECT_EQ(read->rows, 40);
    EXPECT_EQ(read->slices, 24);
    EXPECT_NEAR((read->origin_mm - expected.origin_mm).norm(), 0, kGeometryTolMm);
    EXPECT_NEAR((read->axes - expected.axes).norm(), 0, kGeometryTolMm);
    EXPECT_NEAR((read->spacing_mm - expected.spacing_mm).norm(), 0, kGeometryTolMm);
    EXPECT_EQ(read->series_uid, truth["ct"]["series_uid"].get<std::string>());
    ASSERT_EQ(read->hu.size(), expected.hu.size());
    double max_diff = 0;
    for (size_t i = 0; i < expected.hu.size(); ++i) {
      max_diff = std::max(max_diff, std::abs(double(read->hu[i]) - expected.hu[i]));
    }
    // slope 0.5: rounding to the nearest stored step of 0.5 HU.
    EXPECT_LE(max_diff, 0.5 * kRoundTripTolHu) << "tilt " << tilt;
  }
}

TEST(CtSimulate, SameSeedSameSeriesOtherSeedOtherNoise) {
  ScratchDir dir("seed");
  WriteText(dir.File("markers.csv"), kSceneMarkersYaml);
  WriteText(dir.File("scene.yaml"), SmallScene(""));
  CtScene a, b;
  YamlMap ya = YamlMap::Load(dir.File("scene.yaml"));
  YamlMap yb = YamlMap::Load(dir.File("scene.yaml"));
  ASSERT_TRUE(ParseCtScene(ya, &a).ok());
  ASSERT_TRUE(ParseCtScene(yb, &b).ok());
  CtVolume va = a.geometry, vb = b.geometry;
  ASSERT_TRUE(VoxelisePhantom(a.phantom, a.voxelise, &va).ok());
  ASSERT_TRUE(VoxelisePhantom(b.phantom, b.voxelise, &vb).ok());
  EXPECT_EQ(va.hu, vb.hu);
  b.voxelise.seed = 8;
  ASSERT_TRUE(VoxelisePhantom(b.phantom, b.voxelise, &vb).ok());
  EXPECT_NE(va.hu, vb.hu);
}

TEST(CtSimulate, PartialVolumeMatchesTheSphereVolume) {
  // Noiseless, no block: sum over voxels of (HU - air) / (metal - air) * voxel volume is the
  // sphere's volume up to the supersampling's quantisation.
  ScratchDir dir("pv");
  WriteText(dir.File("markers.csv"), kSceneMarkersYaml);
  WriteText(dir.File("scene.yaml"),
            SmallScene("  noise_hu: 0\n  supersampling: 12\n") + "block:\n  enabled: false\n");
  YamlMap y = YamlMap::Load(dir.File("scene.yaml"));
  CtScene s;
  ASSERT_TRUE(ParseCtScene(y, &s).ok());
  CtVolume v = s.geometry;
  ASSERT_TRUE(VoxelisePhantom(s.phantom, s.voxelise, &v).ok());
  double sum = 0;
  for (float h : v.hu) sum += (h - s.phantom.air_hu) / (s.phantom.marker_hu - s.phantom.air_hu);
  const double volume = sum * v.VoxelVolumeMm3();
  const double expected = 2 * 4.0 / 3.0 * M_PI;  // two spheres of radius 1 mm
  constexpr double kRelTol = 0.01;               // 12^3 sub-samples per boundary voxel
  EXPECT_NEAR(volume / expected, 1.0, kRelTol);
}

struct BadScene {
  std::string text;
  std::string expected_error;
};

TEST(CtSimulate, BadScenesAreRejectedWithOneLineErrors) {
  const std::vector<BadScene> cases = {
      {SmallScene("  colour: red\n"), "ct.colour"},
      {SmallScene("", 3), "does not lie wholly inside the CT volume"},
      {SmallScene("  slice_thickness_mm: -1\n"), "ct.slice_thickness_mm"},
      {SmallScene("  orientation: [1, 0, 0, 1, 0, 0]\n"), "orthogonal"},
      {SmallScene("  tilt_deg: 95\n"), "ct.tilt_deg"},
      {SmallScene("  metal_streak_hu: -5\n"), "ct.metal_streak_hu"},
      {"kind: xray\nmarkers:\n  csv: markers.csv\n", "expected 'ct'"},
      {"kind: ct\n", "markers"},
      {"kind: ct\nmarkers:\n  csv: missing.csv\n", "missing.csv"},
      {"kind: ct\nmarkers:\n  csv: markers.csv\n  columns: [x_ct, y_ct, z_ct]\n", "x_ct"},
  };
  for (const auto& c : cases) {
    ScratchDir dir("bad");
    WriteText(dir.File("markers.csv"), kSceneMarkersYaml);
    WriteText(dir.File("scene.yaml"), c.text);
    YamlMap y = YamlMap::Load(dir.File("scene.yaml"));
    nlohmann::json truth;
    const Status s = SimulateCtScene(y, dir.File("out"), &truth);
    ASSERT_FALSE(s.ok()) << c.text;
    EXPECT_NE(s.message().find(c.expected_error), std::string::npos) << s.message();
    EXPECT_EQ(s.message().find('\n'), std::string::npos) << s.message();
    EXPECT_FALSE(fs::exists(dir.File("out/ct"))) << c.text;
  }
}

// The metal streak model on an empty volume: nothing inside a marker, streaks along lines through
// it (point-symmetric about a voxel-centred marker), bounded by the amplitude (16 lines can add
// up only where they cross, at the marker), seeded; a second marker in the slice adds a dark band
// between the two.
TEST(CtSimulate, MetalStreaksAreLinesThroughTheMarkersAndBandsBetweenThem) {
  CtVolume v;
  v.columns = v.rows = 161;
  v.slices = 3;
  v.spacing_mm = Eigen::Vector3d(0.5, 0.5, 1.0);
  v.hu.assign(static_cast<size_t>(v.columns) * v.rows * v.slices, 0.f);
  const Eigen::Vector3d c = v.PatientFromIndex(Eigen::Vector3d(80, 80, 1));
  CtVoxeliseOptions o;
  o.metal_streak_hu = 300;
  o.seed = 5;
  CtVolume one = v;
  AddMetalStreaks({CtMarker{1, c}}, 3.0, o, &one);
  double max_abs = 0, asym = 0;
  int changed = 0;
  for (int j = 0; j < v.rows; ++j) {
    for (int i = 0; i < v.columns; ++i) {
      const double x = one.At(i, j, 1);
      const double d = std::hypot((i - 80) * 0.5, (j - 80) * 0.5);
      if (d <= 1.5) {
        EXPECT_EQ(x, 0.f) << i << " " << j;  // inside the marker
      }
      max_abs = std::max(max_abs, std::abs(x));
      changed += x != 0;
      asym = std::max(asym, std::abs(x - one.At(160 - i, 160 - j, 1)));
    }
  }
  EXPECT_GT(changed, 1000);
  EXPECT_GT(max_abs, 100);
  EXPECT_LT(max_abs, 16 * 300);
  EXPECT_LT(asym, 1e-3);
  // Slices 0 and 2 are 1 mm from the centre: cut with chord fraction sqrt(1 - (1/1.5)^2) < 1.
  double max0 = 0;
  for (int j = 0; j < v.rows; ++j) {
    for (int i = 0; i < v.columns; ++i) max0 = std::max(max0, std::abs(1.0 * one.At(i, j, 0)));
  }
  EXPECT_GT(max0, 0);
  EXPECT_LT(max0, max_abs);
  CtVolume again = v;
  AddMetalStreaks({CtMarker{1, c}}, 3.0, o, &again);
  EXPECT_EQ(again.hu, one.hu);
  // Two markers 20 mm apart along x: what the pair adds beyond each one's own lines (the
  // second's alone: a first marker far outside the volume keeps its seeding index) is the dark
  // band between them, half the amplitude on the line joining them, nothing off its end.
  const Eigen::Vector3d c2 = v.PatientFromIndex(Eigen::Vector3d(120, 80, 1));
  const Eigen::Vector3d far = v.PatientFromIndex(Eigen::Vector3d(80, 80, 500));
  CtVolume two = v, second = v;
  AddMetalStreaks({CtMarker{1, c}, CtMarker{2, c2}}, 3.0, o, &two);
  AddMetalStreaks({CtMarker{1, far}, CtMarker{2, c2}}, 3.0, o, &second);
  auto band = [&](int i, int j) { return two.At(i, j, 1) - one.At(i, j, 1) - second.At(i, j, 1); };
  EXPECT_NEAR(band(100, 80), -150, 1e-3);
  EXPECT_NEAR(band(100, 82), -150 * std::exp(-0.5), 1e-3);  // 1 mm off the line
  EXPECT_NEAR(band(140, 80), 0, 1e-3);                        // beyond the second marker
}

TEST(CtSimulate, RefusesToOverwriteANonEmptySeriesDirectory) {
  ScratchDir dir("exists");
  WriteText(dir.File("markers.csv"), kSceneMarkersYaml);
  WriteText(dir.File("scene.yaml"), SmallScene(""));
  fs::create_directories(dir.File("out/ct"));
  WriteText(dir.File("out/ct/old.dcm"), "x");
  YamlMap y = YamlMap::Load(dir.File("scene.yaml"));
  nlohmann::json truth;
  const Status s = SimulateCtScene(y, dir.File("out"), &truth);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("not empty"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace carmba
