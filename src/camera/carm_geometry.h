// C-arm geometry, for the simulator and the nominal views of DICOM XA frames (io/dicom_view.h):
// from the quantities users and DICOM use (SID, source-to-isocentre distance, detector pitch,
// positioner angles) to a carmba camera and `cam_from_world`.
//
// FRAMES
//   * World = the DICOM patient frame LPS: x towards the patient's Left, y towards Posterior,
//     z towards Superior (head). The patient lies supine, head first; mm.
//   * Camera = carmba's camera frame (camera/camera_model.h): origin at the X-ray source (focal
//     spot), z from the source towards the detector, x right and y down in the image AS SEEN FROM
//     THE SOURCE (the raw detector image, not a display that may be mirrored).
//
// POSITIONER ANGLES (DICOM PS3.3 C.8.7.5, XA Positioner Module)
//   * primary_angle_deg  (0018,1510): rotation about the patient's long axis. 0 = AP (source
//     posterior, detector anterior, beam along -y = anterior). LAO is positive: the detector
//     moves to the patient's LEFT, so at LAO +90 the beam runs along +x (right to left); RAO is
//     negative (RAO 90: beam along -x).
//   * secondary_angle_deg (0018,1511): cranial is positive: the detector tilts towards the
//     patient's head, so the beam gains a +z (superior) component; caudal is negative.
//   Beam direction (camera z axis in world):
//       z_cam = ( sin(a) cos(b), -cos(a) cos(b), sin(b) ),   a = primary, b = secondary.
//   At a = b = 0 the camera axes are x_cam = -x_world (patient right), y_cam = -z_world (feet):
//   the patient's head is at the top of the image and, seen from the source (from behind the
//   patient), the patient's right on the right.
//   The full rotation is
//       world_from_cam_R = Rz_world(a) * R0 * Rx_cam(b) * Rz_cam(detector_rotation)
//   with R0 = [x0 y0 z0] = [(-1,0,0) (0,0,-1) (0,-1,0)] (columns), Rz_world(a) a rotation by +a
//   about the patient's superior axis, Rx_cam(b) a rotation by +b about the camera x axis and
//   Rz_cam(g) a rotation by +g about the beam (a positive in-plane detector rotation turns the
//   detector's u axis towards its v axis; image content turns the other way).
//
// SOURCE AND ISOCENTRE
//   The C-arm rotates about its isocentre, `isocenter_mm` (world). The central ray passes at
//   `axis_offset_mm` = (dx, dy) (camera x, y; 0 for an ideal C-arm) from the isocentre; the
//   source sits `sod_mm` before it along the beam:
//       source_in_world = isocenter + world_from_cam_R * (dx, dy, -sod)
//   and the detector plane is at z_cam = sid_mm. So cam_from_world: p_in_cam = R^T (p - source).
//   With zero axis offset the isocentre lies on the optical axis, so it projects to the
//   principal point (cx, cy).
//
// INTRINSICS FROM THE DETECTOR
//   fx = sid / pitch_x, fy = sid / pitch_y (px), cx = (width - 1)/2 + principal_offset_px[0],
//   cy = (height - 1)/2 + principal_offset_px[1] (pixel (0,0) is the centre of the top-left pixel).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <nlohmann/json.hpp>
#include <string>

#include "camera/camera.h"
#include "geometry/pose.h"
#include "util/status.h"

namespace carmba {

// The name of a C-arm orientation (positioner angles in degrees, rounded): "p+045 s-025".
std::string OrientationName(double primary_deg, double secondary_deg);

// {"R": 3x3 row-major (list of 3 rows), "rvec": [rad x3], "t_mm": [x3]}.
nlohmann::json RigidToJson(const Rigid3& pose);

struct CarmGeometry {
  double sid_mm = 1000.0;              // source-to-image (detector) distance
  double sod_mm = 620.0;               // source-to-isocentre distance, 0 < sod < sid
  double primary_angle_deg = 0.0;      // LAO +, RAO - (DICOM 0018,1510)
  double secondary_angle_deg = 0.0;    // cranial +, caudal - (DICOM 0018,1511)
  double detector_rotation_deg = 0.0;  // in-plane rotation about the beam
  Eigen::Vector3d isocenter_mm = Eigen::Vector3d::Zero();    // isocentre in world (LPS)
  Eigen::Vector2d axis_offset_mm = Eigen::Vector2d::Zero();  // central ray offset (camera x, y)

  // Finite values, 0 < sod_mm < sid_mm, |secondary| <= 90.
  bool Check(std::string* error) const;
};

// THE one conversion from C-arm positioner geometry to a camera pose (see the header comment).
Rigid3 CamFromWorld(const CarmGeometry& geometry);

// A flat detector / image-intensifier output described physically.
struct DetectorSpec {
  int width_px = 0;
  int height_px = 0;
  double pitch_x_mm = 0.0;  // pixel size at the detector plane (mm/px)
  double pitch_y_mm = 0.0;
  Eigen::Vector2d principal_offset_px = Eigen::Vector2d::Zero();  // from the image centre
  bool Check(std::string* error) const;
};

// Camera (no distortion) of a detector at distance `sid_mm` from the source.
Camera CameraFromDetector(const DetectorSpec& detector, double sid_mm);

}  // namespace carmba
