// The nominal view of a DICOM X-ray frame (io/dicom_view.h): one DICOM file per sign of each
// positioner angle, written and read back through io/dicom_xray.h, checked against the physical
// meaning of the sign (PS3.3 C.8.7.5.1.2: +primary = LAO, +secondary = cranial), and the nominal
// focal lengths from SID and Imager Pixel Spacing (row\column).
#include "io/dicom_view.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "io/dicom_xray.h"
#include "scratch.h"
#include "sim/xray_render.h"
#include "sim/xray_scene.h"
#include "util/image_codecs.h"

namespace carmba::sim {
namespace {

namespace fs = std::filesystem;

// Rotations are built from cos / sin of the angles: exact to rounding.
constexpr double kTol = 1e-9;

// Writes one 16 x 12 frame with these tags, reads it back and returns its nominal view.
NominalDicomView ViewFromFile(const XrayFrameGeometry& g, const std::string& orientation = "") {
  const test::ScratchDir dir("dicom_view");
  const std::string path = dir.File("view.dcm");
  DicomXrayWriteOptions o;
  o.geometry = g;
  o.patient_orientation = orientation;
  EXPECT_TRUE(WriteDicomXray(path, {cv::Mat(12, 16, CV_16UC1, cv::Scalar(100))}, o).ok());
  auto image = ReadDicomXray(path);
  fs::remove(path);
  EXPECT_TRUE(image.ok()) << image.status().message();
  EXPECT_EQ(image->patient_orientation, orientation);
  auto view = NominalViewFromDicom(image->geometry[0], 16, 12, path, image->patient_orientation);
  EXPECT_TRUE(view.ok()) << view.status().message();
  return *view;
}

XrayFrameGeometry Geometry(double primary_deg, double secondary_deg) {
  XrayFrameGeometry g;
  g.primary_angle_deg = primary_deg;
  g.secondary_angle_deg = secondary_deg;
  g.sid_mm = 1000;
  g.sod_mm = 600;
  g.pixel_spacing_row_mm = 0.25;
  g.pixel_spacing_col_mm = 0.2;
  return g;
}

// The beam (camera z) and the source position, in the patient frame (LPS, origin = isocentre).
Eigen::Vector3d BeamOfView(const Rigid3& cam_from_patient) {
  return cam_from_patient.R.transpose() * Eigen::Vector3d::UnitZ();
}
Eigen::Vector3d Source(const Rigid3& cam_from_patient) { return cam_from_patient.Inverse().t; }

TEST(DicomView, ZeroZeroIsAnteroPosterior) {
  const NominalDicomView v = ViewFromFile(Geometry(0, 0));
  ASSERT_TRUE(v.cam_from_patient.has_value());
  // BeamOfView from the posterior source to the anterior detector: -y in LPS.
  EXPECT_LT((BeamOfView(*v.cam_from_patient) - Eigen::Vector3d(0, -1, 0)).norm(), kTol);
  EXPECT_LT((Source(*v.cam_from_patient) - Eigen::Vector3d(0, 600, 0)).norm(), 1e-9 * 600);
  // The isocentre is on the optical axis, SOD in front of the source.
  EXPECT_LT(((*v.cam_from_patient) * Eigen::Vector3d::Zero() - Eigen::Vector3d(0, 0, 600)).norm(),
            1e-9 * 600);
  // Image x = patient right (-x in LPS), image y = feet (-z).
  EXPECT_LT((v.cam_from_patient->R.transpose().col(0) - Eigen::Vector3d(-1, 0, 0)).norm(), kTol);
  EXPECT_LT((v.cam_from_patient->R.transpose().col(1) - Eigen::Vector3d(0, 0, -1)).norm(), kTol);
  EXPECT_TRUE(v.missing.empty());
}

TEST(DicomView, PositivePrimaryIsLao) {
  const NominalDicomView v = ViewFromFile(Geometry(30, 0));
  ASSERT_TRUE(v.cam_from_patient.has_value());
  const Eigen::Vector3d beam = BeamOfView(*v.cam_from_patient);
  // The detector at the patient's left-anterior: the beam goes towards +x (left) and -y
  // (anterior); the source sits right-posterior.
  EXPECT_LT((beam - Eigen::Vector3d(std::sin(M_PI / 6), -std::cos(M_PI / 6), 0)).norm(), kTol);
  EXPECT_LT(Source(*v.cam_from_patient).x(), -299);
}

TEST(DicomView, NegativePrimaryIsRao) {
  const NominalDicomView v = ViewFromFile(Geometry(-90, 0));
  ASSERT_TRUE(v.cam_from_patient.has_value());
  // RAO 90: the detector at the patient's right, the beam along -x (left to right).
  EXPECT_LT((BeamOfView(*v.cam_from_patient) - Eigen::Vector3d(-1, 0, 0)).norm(), kTol);
  EXPECT_GT(Source(*v.cam_from_patient).x(), 599);
}

TEST(DicomView, PositiveSecondaryIsCranial) {
  const NominalDicomView v = ViewFromFile(Geometry(0, 20));
  ASSERT_TRUE(v.cam_from_patient.has_value());
  const Eigen::Vector3d beam = BeamOfView(*v.cam_from_patient);
  // The detector tilted towards the head: the beam gains +z (superior), the source is caudal.
  const double b = 20 * M_PI / 180;
  EXPECT_LT((beam - Eigen::Vector3d(0, -std::cos(b), std::sin(b))).norm(), kTol);
  EXPECT_LT(Source(*v.cam_from_patient).z(), -200);
}

TEST(DicomView, NegativeSecondaryIsCaudal) {
  const NominalDicomView v = ViewFromFile(Geometry(0, -20));
  ASSERT_TRUE(v.cam_from_patient.has_value());
  EXPECT_LT(BeamOfView(*v.cam_from_patient).z(), -0.34);
  EXPECT_GT(Source(*v.cam_from_patient).z(), 200);
}

// Combined angles: the closed form of carm_geometry.h, z_cam = (sin a cos b, -cos a cos b, sin b).
TEST(DicomView, CombinedAnglesFollowTheClosedForm) {
  const double a = 25, b = -35;
  const NominalDicomView v = ViewFromFile(Geometry(a, b));
  ASSERT_TRUE(v.cam_from_patient.has_value());
  const double ar = a * M_PI / 180, br = b * M_PI / 180;
  const Eigen::Vector3d expected(
      std::sin(ar) * std::cos(br), -std::cos(ar) * std::cos(br), std::sin(br));
  EXPECT_LT((BeamOfView(*v.cam_from_patient) - expected).norm(), kTol);
}

// Imager Pixel Spacing is "row spacing\column spacing": fx = SID / column spacing.
TEST(DicomView, NominalFocalLengthsFromSidAndImagerPixelSpacing) {
  const NominalDicomView v = ViewFromFile(Geometry(0, 0));
  ASSERT_TRUE(v.camera.has_value());
  EXPECT_DOUBLE_EQ(v.camera->params[0], 1000 / 0.2);   // fx
  EXPECT_DOUBLE_EQ(v.camera->params[1], 1000 / 0.25);  // fy
  EXPECT_DOUBLE_EQ(v.camera->params[2], 7.5);          // cx = (16 - 1) / 2
  EXPECT_DOUBLE_EQ(v.camera->params[3], 5.5);          // cy = (12 - 1) / 2
  EXPECT_EQ(v.camera->width, 16);
  EXPECT_EQ(v.camera->height, 12);
}

// Patient Orientation (0020,0020) against the nominal pose: at 0 / 0 the image seen from the
// source has x = patient right, y = feet ("R\F"); at LAO 90, x = anterior ("A\F"); an axis
// more than 25 deg from every patient axis (LAO 45) is not checked.
TEST(DicomView, PatientOrientationCheckedAgainstTheNominalPose) {
  EXPECT_TRUE(ViewFromFile(Geometry(0, 0), "R\\F").warnings.empty());
  EXPECT_TRUE(ViewFromFile(Geometry(90, 0), "A\\F").warnings.empty());
  const NominalDicomView mirrored = ViewFromFile(Geometry(0, 0), "L\\F");
  ASSERT_EQ(mirrored.warnings.size(), 1u);
  EXPECT_NE(mirrored.warnings[0].find("image x points L in Patient Orientation (0020,0020) "
                                      "'L\\F', R in the nominal pose"),
            std::string::npos)
      << mirrored.warnings[0];
  const NominalDicomView upside_down = ViewFromFile(Geometry(0, 0), "L\\H");
  EXPECT_EQ(upside_down.warnings.size(), 2u);
  // LAO 45: image x is between R and A; only y (feet) is checked.
  EXPECT_TRUE(ViewFromFile(Geometry(45, 0), "P\\F").warnings.empty());
  EXPECT_EQ(ViewFromFile(Geometry(45, 0), "P\\H").warnings.size(), 1u);
  // Without the tag nothing is checked.
  EXPECT_TRUE(ViewFromFile(Geometry(0, 0)).warnings.empty());
}

TEST(DicomView, AbsentTagsLeaveTheirPartOutAndAreListed) {
  XrayFrameGeometry g = Geometry(10, 0);
  g.sod_mm.reset();
  g.pixel_spacing_row_mm.reset();
  g.pixel_spacing_col_mm.reset();
  const NominalDicomView v = ViewFromFile(g);
  EXPECT_FALSE(v.cam_from_patient.has_value());
  EXPECT_FALSE(v.camera.has_value());
  ASSERT_EQ(v.missing.size(), 2u);
  EXPECT_EQ(v.missing[0], "Distance Source to Patient (0018,1111)");
  EXPECT_EQ(v.missing[1], "Imager Pixel Spacing (0018,1164)");
}

// Without SOD, SID / Estimated Radiographic Magnification Factor (0018,1114) stands in for it.
TEST(DicomView, MagnificationFactorGivesTheSodWhenItIsAbsent) {
  XrayFrameGeometry g = Geometry(0, 0);
  g.sod_mm.reset();
  g.magnification = 1.6;  // 1000 / 1.6 = 625 mm
  const NominalDicomView v = ViewFromFile(g);
  ASSERT_TRUE(v.cam_from_patient.has_value());
  EXPECT_NEAR(Source(*v.cam_from_patient).y(), 625, 1e-9);
  EXPECT_TRUE(v.missing.empty());
  g.magnification = 0.8;
  auto bad = NominalViewFromDicom(g, 16, 12, "m.dcm");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("m.dcm: Estimated Radiographic Magnification Factor "
                                        "(0018,1114) 0.800000, expected > 1"),
            std::string::npos)
      << bad.status().message();
}

TEST(DicomView, InconsistentDistancesAndAnglesAreErrors) {
  XrayFrameGeometry g = Geometry(0, 0);
  g.sod_mm = 1000;
  auto v = NominalViewFromDicom(g, 16, 12, "x.dcm#frame2");
  ASSERT_FALSE(v.ok());
  EXPECT_NE(v.status().message().find("x.dcm#frame2: Distance Source to Patient (0018,1111)"),
            std::string::npos)
      << v.status().message();
  g = Geometry(0, 95);
  v = NominalViewFromDicom(g, 16, 12, "y.dcm");
  ASSERT_FALSE(v.ok());
  EXPECT_NE(v.status().message().find("expected [-90, 90]"), std::string::npos)
      << v.status().message();
}

// `carmba simulate` with output format dcm: the thesis pose scene's views written as XA files;
// their tags give back the truth's cam_from_world and the scene's fx, fy. The scene's isocentre is
// the world origin and its views have no detector rotation, but its central ray is offset from
// the isocentre by axis_offset_mm (-28.7, 11.1), which no XA tag carries: the nominal translation
// lacks exactly that offset (t_truth = t_nominal - (dx, dy, 0)).
TEST(DicomView, SimulatedXaFilesGiveBackTheTruePoseAndFocalLengths) {
  auto scene = LoadXrayScene(std::string(CARMBA_SOURCE_DIR) + "/configs/scenes/thesis_pose.yaml");
  ASSERT_TRUE(scene.ok()) << scene.status().message();
  scene->format = "dcm";
  scene->render.supersampling = 1;  // the pixels do not matter here
  const test::ScratchDir scratch("sim_dcm");  // removed when it goes
  const std::string& dir = scratch.path();
  nlohmann::json truth;
  ASSERT_TRUE(scene->views[0].carm.isocenter_mm.isZero());
  const Eigen::Vector2d offset = scene->views[0].carm.axis_offset_mm;
  ASSERT_GT(offset.norm(), 1);  // the part the tags miss is there to be seen
  const Status s = SimulateXrayScene(*scene, dir, &truth);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(truth["views"].size(), scene->views.size());
  for (const auto& tv : truth["views"]) {
    const std::string file = dir + "/" + tv["file"].get<std::string>();
    ASSERT_EQ(file.substr(file.size() - 4), ".dcm");
    auto image = ReadDicomXray(file);
    ASSERT_TRUE(image.ok()) << image.status().message();
    EXPECT_EQ(image->frames[0].cols, scene->camera.width);
    auto view = NominalViewFromDicom(
        image->geometry[0], image->frames[0].cols, image->frames[0].rows, file);
    ASSERT_TRUE(view.ok()) << view.status().message();
    ASSERT_TRUE(view->cam_from_patient && view->camera) << file;
    const auto& R = tv["cam_from_world"]["R"];
    const auto& t = tv["cam_from_world"]["t_mm"];
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(view->cam_from_patient->R(r, c), R[r][c].get<double>(), kTol) << file;
      }
      const double missing = r < 2 ? offset(r) : 0.0;
      EXPECT_NEAR(view->cam_from_patient->t(r) - missing, t[r].get<double>(), 1e-9 * 1000) << file;
    }
    // Imager Pixel Spacing is written with 12 significant digits.
    EXPECT_NEAR(view->camera->params[0] / scene->camera.params[0], 1, 1e-11) << file;
    EXPECT_NEAR(view->camera->params[1] / scene->camera.params[1], 1, 1e-11) << file;
  }
  fs::remove_all(dir);
}

// The simulator's background (sim/xray_render.h LoadBackgroundGain) reads DICOM through
// io/dicom_xray.h: the first frame by default, frame N of `file.dcm#frameN`; the same gain as
// from the frame saved as PNG (OpenCV's path).
TEST(DicomBackground, FrameOfAMultiFrameFileAsFromPng) {
  const test::ScratchDir scratch("dicom_bg");  // removed when it goes
  const std::string& dir = scratch.path();
  std::vector<cv::Mat> frames;
  for (int k = 0; k < 2; ++k) {
    cv::Mat m(40, 50, CV_16UC1);
    for (int r = 0; r < m.rows; ++r) {
      for (int c = 0; c < m.cols; ++c) {
        m.at<uint16_t>(r, c) = static_cast<uint16_t>(k == 0 ? 100 + 20 * r : 3000 - 40 * c);
      }
    }
    frames.push_back(m);
    ASSERT_TRUE(carmba::ImWrite(dir + "/f" + std::to_string(k + 1) + ".png", m));
  }
  const std::string dcm = dir + "/bg.dcm";
  ASSERT_TRUE(WriteDicomXray(dcm, frames, DicomXrayWriteOptions()).ok());
  auto same = [](const StatusOr<cv::Mat>& a, const StatusOr<cv::Mat>& b) {
    EXPECT_TRUE(a.ok() && b.ok()) << a.status().message() << b.status().message();
    return a.ok() && b.ok() && cv::norm(*a, *b, cv::NORM_INF) == 0;
  };
  EXPECT_TRUE(same(LoadBackgroundGain(dcm, 32, 32, 0.5, 0.8),
                   LoadBackgroundGain(dir + "/f1.png", 32, 32, 0.5, 0.8)));
  EXPECT_TRUE(same(LoadBackgroundGain(dcm + "#frame2", 32, 32, 0.5, 0.8),
                   LoadBackgroundGain(dir + "/f2.png", 32, 32, 0.5, 0.8)));
  EXPECT_FALSE(same(LoadBackgroundGain(dcm + "#frame2", 32, 32, 0.5, 0.8),
                    LoadBackgroundGain(dir + "/f1.png", 32, 32, 0.5, 0.8)));
  auto beyond = LoadBackgroundGain(dcm + "#frame3", 32, 32, 0.5, 0.8);
  ASSERT_FALSE(beyond.ok());
  EXPECT_NE(beyond.status().message().find("bg.dcm#frame3: no such frame"), std::string::npos)
      << beyond.status().message();
  fs::remove_all(dir);
}

}  // namespace
}  // namespace carmba::sim
