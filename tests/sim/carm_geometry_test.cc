// Sign conventions of the C-arm geometry (camera/carm_geometry.h): DICOM positioner angles in the
// LPS patient frame -> cam_from_world.
#include "camera/carm_geometry.h"

#include <gtest/gtest.h>

#include <cmath>

#include "camera/camera_model.h"

namespace carmba::sim {
namespace {

// Pure rotations and translations of doubles: agreement to rounding error.
constexpr double kTolMm = 1e-9;
// Projections through UnprojectToNormalized-free pinhole maths: rounding error on ~2000 px focal.
constexpr double kTolPx = 1e-6;

Camera ThesisCamera(double k1) {
  Camera c;
  c.width = c.height = 408;
  c.params = {2061.389, 2254.646, 203.655, 205.117, k1, 0.0, 0.0, 0.0, 0.0};
  return c;
}

Eigen::Vector2d Project(const Camera& cam, const Rigid3& cam_from_world, const Eigen::Vector3d& p) {
  const Eigen::Vector3d q = cam_from_world * p;
  double uv[2] = {0, 0};
  EXPECT_TRUE(ProjectCamPoint(cam.params.data(), q.data(), uv));
  return {uv[0], uv[1]};
}

// Beam direction (camera z) in the world frame.
Eigen::Vector3d Beam(const Rigid3& cam_from_world) { return cam_from_world.R.row(2).transpose(); }

TEST(CarmGeometry, ApViewLooksAnteriorWithHeadUp) {
  CarmGeometry g;  // primary = secondary = 0
  const Rigid3 T = CamFromWorld(g);
  EXPECT_NEAR((Beam(T) - Eigen::Vector3d(0, -1, 0)).norm(), 0, kTolMm);
  const Camera cam = ThesisCamera(0);
  const Eigen::Vector2d head = Project(cam, T, {0, 0, 50});  // superior
  const Eigen::Vector2d left = Project(cam, T, {50, 0, 0});  // patient left
  EXPECT_LT(head.y(), cam.params[kCy]);                      // the head is at the top of the image
  EXPECT_NEAR(head.x(), cam.params[kCx], kTolPx);
  // Seen from the source (behind the patient), the patient's left is on the image's left.
  EXPECT_LT(left.x(), cam.params[kCx]);
  EXPECT_NEAR(left.y(), cam.params[kCy], kTolPx);
}

TEST(CarmGeometry, Lao90LooksAlongLeftRightAxis) {
  CarmGeometry g;
  g.primary_angle_deg = 90;  // LAO 90: detector at the patient's left
  const Rigid3 T = CamFromWorld(g);
  EXPECT_NEAR((Beam(T) - Eigen::Vector3d(1, 0, 0)).norm(), 0, kTolMm);
  // Points along the patient's left-right axis through the isocentre all project to the
  // principal point.
  const Camera cam = ThesisCamera(0);
  for (double x : {-80.0, -20.0, 0.0, 35.0, 90.0}) {
    const Eigen::Vector2d uv = Project(cam, T, {x, 0, 0});
    EXPECT_NEAR(uv.x(), cam.params[kCx], kTolPx) << x;
    EXPECT_NEAR(uv.y(), cam.params[kCy], kTolPx) << x;
  }
  // The source is on the patient's right.
  const Eigen::Vector3d source = T.Inverse().t;
  EXPECT_NEAR((source - Eigen::Vector3d(-g.sod_mm, 0, 0)).norm(), 0, kTolMm);
  g.primary_angle_deg = -90;  // RAO 90
  EXPECT_NEAR((Beam(CamFromWorld(g)) - Eigen::Vector3d(-1, 0, 0)).norm(), 0, kTolMm);
}

TEST(CarmGeometry, CranialTiltsBeamTowardsHead) {
  CarmGeometry g;
  g.secondary_angle_deg = 30;  // cranial
  Eigen::Vector3d b = Beam(CamFromWorld(g));
  EXPECT_NEAR(b.z(), std::sin(M_PI / 6), kTolMm);
  EXPECT_NEAR(b.y(), -std::cos(M_PI / 6), kTolMm);
  g.secondary_angle_deg = -20;  // caudal
  b = Beam(CamFromWorld(g));
  EXPECT_NEAR(b.z(), -std::sin(20 * M_PI / 180), kTolMm);
  // Combined: z_cam = (sin a cos b, -cos a cos b, sin b).
  g.primary_angle_deg = 40;
  g.secondary_angle_deg = 25;
  const double a = 40 * M_PI / 180, s = 25 * M_PI / 180;
  b = Beam(CamFromWorld(g));
  EXPECT_NEAR(
      (b - Eigen::Vector3d(std::sin(a) * std::cos(s), -std::cos(a) * std::cos(s), std::sin(s)))
          .norm(),
      0,
      kTolMm);
}

TEST(CarmGeometry, IsocentreProjectsToPrincipalPointAtAnyAngle) {
  const Camera cam = ThesisCamera(-2.5);  // distortion leaves the principal point fixed
  CarmGeometry g;
  g.isocenter_mm = Eigen::Vector3d(12, -30, 250);
  for (double a : {-120.0, -45.0, 0.0, 10.0, 90.0, 179.0}) {
    for (double s : {-40.0, 0.0, 35.0}) {
      for (double rot : {0.0, 17.0}) {
        g.primary_angle_deg = a;
        g.secondary_angle_deg = s;
        g.detector_rotation_deg = rot;
        const Rigid3 T = CamFromWorld(g);
        const Eigen::Vector2d uv = Project(cam, T, g.isocenter_mm);
        EXPECT_NEAR(uv.x(), cam.params[kCx], kTolPx);
        EXPECT_NEAR(uv.y(), cam.params[kCy], kTolPx);
        EXPECT_NEAR((T * g.isocenter_mm).z(), g.sod_mm, kTolMm);
        EXPECT_NEAR((T.R * T.R.transpose() - Eigen::Matrix3d::Identity()).norm(), 0, 1e-12);
        EXPECT_NEAR(T.R.determinant(), 1.0, 1e-12);
      }
    }
  }
}

TEST(CarmGeometry, AxisOffsetMovesIsocentreOffThePrincipalPoint) {
  const Camera cam = ThesisCamera(0);
  CarmGeometry g;
  g.axis_offset_mm = Eigen::Vector2d(2.0, -1.0);
  const Eigen::Vector2d uv = Project(cam, CamFromWorld(g), g.isocenter_mm);
  // The isocentre sits at (-dx, -dy) from the central ray, at depth sod.
  EXPECT_NEAR(uv.x(), cam.params[kCx] - cam.params[kFx] * 2.0 / g.sod_mm, kTolPx);
  EXPECT_NEAR(uv.y(), cam.params[kCy] + cam.params[kFy] * 1.0 / g.sod_mm, kTolPx);
}

TEST(CarmGeometry, DetectorRotationTurnsImageContentBackwards) {
  const Camera cam = ThesisCamera(0);
  CarmGeometry g;
  const Eigen::Vector3d head(0, 0, 50);  // at the top of the image without rotation
  g.detector_rotation_deg = 90;          // the u axis turns to where v pointed
  const Eigen::Vector2d uv = Project(cam, CamFromWorld(g), head);
  // Content turns by -90 deg in the (u right, v down) image: "up" becomes "left".
  EXPECT_LT(uv.x(), cam.params[kCx] - 100);
  EXPECT_NEAR(uv.y(), cam.params[kCy], kTolPx);
}

TEST(CarmGeometry, CameraFromDetector) {
  DetectorSpec d;
  d.width_px = 512;
  d.height_px = 400;
  d.pitch_x_mm = 0.4;
  d.pitch_y_mm = 0.5;
  d.principal_offset_px = Eigen::Vector2d(3, -2);
  std::string error;
  ASSERT_TRUE(d.Check(&error)) << error;
  const Camera c = CameraFromDetector(d, 1100);
  EXPECT_DOUBLE_EQ(c.params[kFx], 2750);
  EXPECT_DOUBLE_EQ(c.params[kFy], 2200);
  EXPECT_DOUBLE_EQ(c.params[kCx], 255.5 + 3);
  EXPECT_DOUBLE_EQ(c.params[kCy], 199.5 - 2);
  d.pitch_x_mm = -1;
  EXPECT_FALSE(d.Check(&error));
}

TEST(CarmGeometry, CheckRejectsBadGeometry) {
  std::string error;
  CarmGeometry g;
  EXPECT_TRUE(g.Check(&error));
  g.sod_mm = 1200;  // beyond the detector
  EXPECT_FALSE(g.Check(&error));
  g = CarmGeometry();
  g.sid_mm = -5;
  EXPECT_FALSE(g.Check(&error));
  g = CarmGeometry();
  g.primary_angle_deg = NAN;
  EXPECT_FALSE(g.Check(&error));
}

TEST(Rigid3, RvecRoundTripAndJson) {
  const Eigen::Vector3d r(0.3, -0.2, 1.1), t(1, 2, 3);
  const Rigid3 p = Rigid3::FromRvec(r, t);
  EXPECT_NEAR((p.Rvec() - r).norm(), 0, 1e-12);
  const nlohmann::json j = RigidToJson(p);
  EXPECT_NEAR(j["R"][1][2].get<double>(), p.R(1, 2), 1e-15);
  EXPECT_NEAR(j["t_mm"][2].get<double>(), 3.0, 1e-15);
  const Rigid3 q = p * p.Inverse();
  EXPECT_NEAR((q.R - Eigen::Matrix3d::Identity()).norm() + q.t.norm(), 0, 1e-12);
}

}  // namespace
}  // namespace carmba::sim
