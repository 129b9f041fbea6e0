#include "ct/ct_fiducials.h"
#include "report/ct_fiducials_report.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <filesystem>

#include "ct/ct_phantom.h"
#include "ct/ct_simulate.h"
#include "ct/ct_test_util.h"
#include "ct/marker_detection.h"

namespace carmba {
namespace {

namespace fs = std::filesystem;
using testing::ScratchDir;
using testing::WriteText;

// Four markers of a small asymmetric object, in patient coordinates.
const std::vector<CtMarker> kMarkers = {
    {1, Eigen::Vector3d(0.2, 0.1, 0.0)},
    {2, Eigen::Vector3d(9.0, 0.3, 1.0)},
    {3, Eigen::Vector3d(1.0, 12.0, -2.0)},
    {4, Eigen::Vector3d(4.0, 5.0, 7.5)},
};

CtVolume SmallVolume(const std::vector<CtMarker>& markers, uint64_t seed = 3) {
  CtVolume v = MakeCtGeometry(64, 72, 40, 0.4, 0.6, 0, Eigen::Vector3d::UnitX(),
                              Eigen::Vector3d::UnitY(), Eigen::Vector3d(5, 6, 2.5));
  CtPhantom ph;
  ph.markers = markers;
  ph.block_min_mm = Eigen::Vector3d(-4, -4, -5);
  ph.block_max_mm = Eigen::Vector3d(14, 16, 11);
  CtVoxeliseOptions vo;
  vo.seed = seed;
  EXPECT_TRUE(VoxelisePhantom(ph, vo, &v).ok());
  return v;
}

TEST(MarkerDetection, ExtraAndMissingComponentsAreReported) {
  CtVolume v = SmallVolume(kMarkers);
  // A metal fragment of two voxels far from the markers: too small, rejected with the reason.
  v.hu[v.Index(5, 60, 30)] = 3000;
  v.hu[v.Index(6, 60, 30)] = 3000;
  MarkerDetectionOptions opt;
  auto det = DetectMarkers(v, opt);
  ASSERT_TRUE(det.ok()) << det.status().message();
  EXPECT_EQ(det->markers.size(), 4u);
  ASSERT_EQ(det->rejected.size(), 1u);
  EXPECT_NE(det->rejected[0].reason.find("too small"), std::string::npos);
  opt.expected_count = 5;
  det = DetectMarkers(v, opt);
  ASSERT_FALSE(det.ok());
  EXPECT_NE(det.status().message().find("found 4 markers"), std::string::npos);
  EXPECT_NE(det.status().message().find("expected 5"), std::string::npos);
  EXPECT_NE(det.status().message().find("rejected 1 component(s)"), std::string::npos);
  // A marker cut by the volume's border is rejected, not silently used.
  std::vector<CtMarker> edge = kMarkers;
  edge.push_back(CtMarker{5, Eigen::Vector3d(-7.3, 6, 2)});  // x index ~0
  CtVolume w = SmallVolume(edge);
  opt.expected_count = 0;
  det = DetectMarkers(w, opt);
  ASSERT_TRUE(det.ok());
  EXPECT_EQ(det->markers.size(), 4u);
  ASSERT_EQ(det->rejected.size(), 1u);
  EXPECT_NE(det->rejected[0].reason.find("border"), std::string::npos);
}

TEST(MarkerDetection, TooLowThresholdIsRefused) {
  CtVolume v = SmallVolume(kMarkers);
  MarkerDetectionOptions opt;
  opt.threshold_hu = 50;  // below the block's 100 HU
  auto det = DetectMarkers(v, opt);
  ASSERT_FALSE(det.ok());
  EXPECT_NE(det.status().message().find("threshold is too low"), std::string::npos);
}

class CtFiducialsPipeline : public ::testing::Test {
 protected:
  void SetUp() override {
    CtVolume v = SmallVolume(kMarkers);
    CtWriteOptions wo;
    wo.study_uid = "2.25.9.1";
    wo.series_uid = "2.25.9.2";
    wo.frame_of_reference_uid = "2.25.9.3";
    ASSERT_TRUE(WriteCtSeries(v, dir_.File("ct"), wo).ok());
    // The model: the markers moved rigidly (the object frame), ids 11..14, rows shuffled.
    object_from_ct_.R =
        Eigen::AngleAxisd(0.4, Eigen::Vector3d(0.2, -1, 0.5).normalized()).toRotationMatrix();
    object_from_ct_.t = Eigen::Vector3d(3, -2, 40);
    std::string csv = "# a model\nmarker,x_o,y_o,z_o\n";
    for (int a : {2, 0, 3, 1}) {
      const Eigen::Vector3d p = object_from_ct_ * kMarkers[a].centre_mm;
      csv += std::to_string(kMarkers[a].id + 10) + "," + std::to_string(p.x()) + "," +
             std::to_string(p.y()) + "," + std::to_string(p.z()) + "\n";
    }
    WriteText(dir_.File("model.csv"), csv);
  }
  ScratchDir dir_{"pipeline"};
  Rigid3 object_from_ct_;
};

// std::to_string prints 6 decimals; the centres' sampling error is ~0.003 mm.
constexpr double kCentreTolMm = 0.02;

TEST_F(CtFiducialsPipeline, ModelLabelsAndFramesAndCsvRoundTrip) {
  CtFiducialsOptions opt;
  opt.model_csv = dir_.File("model.csv");
  opt.frame = "model";
  auto r = ComputeCtFiducials(dir_.File("ct"), opt);
  ASSERT_TRUE(r.ok()) << r.status().message();
  ASSERT_TRUE(r->labelled);
  ASSERT_EQ(r->detection.markers.size(), 4u);
  for (size_t a = 0; a < 4; ++a) {
    const auto& m = r->detection.markers[a];
    EXPECT_EQ(m.id, kMarkers[a].id + 10);
    EXPECT_LT((m.centre_mm - kMarkers[a].centre_mm).norm(), kCentreTolMm);
  }
  EXPECT_LT((r->object_from_ct.R - object_from_ct_.R).norm(), 1e-3);
  ASSERT_TRUE(WriteCtFiducials(*r, dir_.File("fid.csv")).ok());
  auto rows = ReadFiducialsCsv(dir_.File("fid.csv"));
  ASSERT_TRUE(rows.ok()) << rows.status().message();
  ASSERT_EQ(rows->size(), 4u);
  for (size_t a = 0; a < 4; ++a) {
    const auto& m = r->detection.markers[a];
    const Eigen::Vector3d expected = object_from_ct_ * kMarkers[a].centre_mm;
    EXPECT_LT(((*rows)[a].p_mm - expected).norm(), kCentreTolMm);
    // The covariance is rotated into the object frame.
    const Eigen::Matrix3d C = r->object_from_ct.R * m.covariance_mm2 *
                              r->object_from_ct.R.transpose();
    EXPECT_NEAR(((*rows)[a].covariance_mm2 - C).norm() / C.norm(), 0, 1e-5);
  }
  EXPECT_TRUE(fs::exists(dir_.File("fid.md")));
  EXPECT_TRUE(fs::exists(dir_.File("fid.object_from_ct.json")));
}

TEST_F(CtFiducialsPipeline, ExtraSigmaIsAddedInQuadrature) {
  CtFiducialsOptions opt;
  auto a = ComputeCtFiducials(dir_.File("ct"), opt);
  opt.extra_sigma_mm = 0.1;
  auto b = ComputeCtFiducials(dir_.File("ct"), opt);
  ASSERT_TRUE(a.ok() && b.ok());
  const Eigen::Matrix3d diff =
      b->detection.markers[0].covariance_mm2 - a->detection.markers[0].covariance_mm2;
  EXPECT_NEAR((diff - 0.01 * Eigen::Matrix3d::Identity()).norm(), 0, 1e-12);
  EXPECT_NE(FormatFiducialsCsv(*b).find("(0.1 mm)^2 I"), std::string::npos);
  opt.extra_sigma_mm = -1;
  EXPECT_FALSE(ComputeCtFiducials(dir_.File("ct"), opt).ok());
}

TEST_F(CtFiducialsPipeline, WithoutModelIdsFollowPatientZ) {
  CtFiducialsOptions opt;
  auto r = ComputeCtFiducials(dir_.File("ct"), opt);
  ASSERT_TRUE(r.ok()) << r.status().message();
  // z: marker 3 (-2) < 1 (0) < 2 (1) < 4 (7.5).
  const int expected_source[] = {3, 1, 2, 4};
  for (size_t a = 0; a < 4; ++a) {
    EXPECT_EQ(r->detection.markers[a].id, static_cast<int>(a) + 1);
    EXPECT_LT((r->detection.markers[a].centre_mm -
               kMarkers[expected_source[a] - 1].centre_mm).norm(),
              kCentreTolMm);
  }
}

TEST(CtFiducialsCsv, BadFilesAreRefused) {
  ScratchDir dir("csv");
  const std::string header =
      "id,x_mm,y_mm,z_mm,cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz,volume_mm3,peak_hu\n";
  struct Case {
    std::string body, expected;
  };
  const std::vector<Case> cases = {
      {"1,0,0,0,1,0,0,1,0,1,4,3000\n1,1,1,1,1,0,0,1,0,1,4,3000\n", "duplicate id 1"},
      {"1,0,0,0,1,2,0,1,0,1,4,3000\n", "not positive semi-definite"},
      {"1,0,0,nan,1,0,0,1,0,1,4,3000\n", "z_mm"},
      {"", "no fiducials"},
  };
  for (const auto& c : cases) {
    WriteText(dir.File("f.csv"), "# comment\n" + header + c.body);
    auto r = ReadFiducialsCsv(dir.File("f.csv"));
    ASSERT_FALSE(r.ok()) << c.body;
    EXPECT_NE(r.status().message().find(c.expected), std::string::npos) << r.status().message();
  }
  WriteText(dir.File("g.csv"), "id,x_mm,y_mm\n1,2,3\n");
  EXPECT_FALSE(ReadFiducialsCsv(dir.File("g.csv")).ok());
}

}  // namespace
}  // namespace carmba

namespace carmba {
namespace {

// Slices with gaps, farther apart than half the marker's diameter (the real CT's every third
// slice): a warning naming the slices and the diameter, in the result and the CSV; contiguous
// slices or gaps at up to half the diameter give none.
TEST(CtFiducialsWarnings, FewSlicesThroughAMarkerAreNamed) {
  auto geometry = [](double step, double thickness) {
    return MakeCtGeometry(8,
                          8,
                          8,
                          0.88,
                          step,
                          thickness,
                          Eigen::Vector3d::UnitX(),
                          Eigen::Vector3d::UnitY(),
                          Eigen::Vector3d::Zero());
  };
  EXPECT_TRUE(SliceSamplingWarnings(geometry(1.25, 1.25), 6).empty());  // contiguous
  EXPECT_TRUE(SliceSamplingWarnings(geometry(5, 5), 6).empty());        // thick, contiguous
  EXPECT_TRUE(SliceSamplingWarnings(geometry(2.5, 1.25), 6).empty());   // every second
  const auto w = SliceSamplingWarnings(geometry(3.75, 1.25), 6);        // every third
  ASSERT_EQ(w.size(), 1u);
  EXPECT_NE(w[0].find("slices 1.25 mm thick every 3.75 mm"), std::string::npos) << w[0];
  EXPECT_NE(w[0].find("6 mm marker"), std::string::npos) << w[0];
  CtFiducialsResult r;
  r.warnings = w;
  EXPECT_NE(FormatFiducialsCsv(r).find("\n# warning: slices 1.25 mm"), std::string::npos);
}

// A gantry-tilted acquisition: slices stacked along a direction that is not the slice normal
// (ImagePositionPatient steps have an in-plane component). The reader recovers the step from the
// positions and the centres come out right in patient coordinates.
TEST(CtFiducialsSheared, GantryTiltedSeriesGivesTheSameCentres) {
  ScratchDir dir("shear");
  CtVolume v = MakeCtGeometry(64, 72, 40, 0.4, 0.6, 0, Eigen::Vector3d::UnitX(),
                              Eigen::Vector3d::UnitY(), Eigen::Vector3d(5, 6, 2.5));
  const double tilt = 12.0 * M_PI / 180;
  // Step 0.6 mm along the normal plus 0.6 tan(12 deg) mm along the column direction.
  const Eigen::Vector3d step = Eigen::Vector3d(0, std::tan(tilt), 1) * 0.6;
  v.axes.col(2) = step.normalized();
  v.spacing_mm.z() = step.norm();
  v.slice_thickness_mm = 0.6;
  v.origin_mm = Eigen::Vector3d(5, 6, 2.5) - v.PatientFromIndexLinear() *
                                                 Eigen::Vector3d(31.5, 35.5, 19.5);
  CtPhantom ph;
  ph.markers = kMarkers;
  ph.block_min_mm = Eigen::Vector3d(-4, -4, -5);
  ph.block_max_mm = Eigen::Vector3d(14, 16, 11);
  ASSERT_TRUE(VoxelisePhantom(ph, CtVoxeliseOptions(), &v).ok());
  CtWriteOptions wo;
  wo.study_uid = "2.25.8.1";
  wo.series_uid = "2.25.8.2";
  wo.frame_of_reference_uid = "2.25.8.3";
  ASSERT_TRUE(WriteCtSeries(v, dir.File("ct"), wo).ok());
  auto r = ComputeCtFiducials(dir.File("ct"), CtFiducialsOptions());
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_NEAR((r->geometry.axes.col(2) - v.axes.col(2)).norm(), 0, 1e-6);
  ASSERT_EQ(r->detection.markers.size(), 4u);
  const int source[] = {3, 1, 2, 4};  // by patient z
  for (size_t a = 0; a < 4; ++a) {
    EXPECT_LT((r->detection.markers[a].centre_mm - kMarkers[source[a] - 1].centre_mm).norm(),
              kCentreTolMm);
  }
}

}  // namespace
}  // namespace carmba
