// Per-view projection geometry for other tools (CBCT reconstruction, DRR rendering): the 3x4
// projection matrix of each view from the patient / CT frame (mm) to pixels of the UNDISTORTED
// image, and `geometry.json`, the file `carmba solve` writes beside result.json.
//
// THE UNDISTORTED IMAGE (what the matrices project into): the same width x height as the
// original image and the same pixel convention (camera/camera_model.h: pixel (0,0) is the centre
// of the top-left pixel, u right, v down); an ideal pinhole with the view's fx, fy, cx, cy and no
// distortion. `carmba undistort` resamples an original image onto it (export/undistort.h): the
// undistorted pixel (u, v) takes the original image's value at the distorted projection of the
// ray x = (u - cx) / fx, y = (v - cy) / fy.
//
// THE MATRIX: with cam_from_ct = (R, t) (p_in_cam = R p_in_ct + t) and K = [fx 0 cx; 0 fy cy;
// 0 0 1],
//     P = K [R | t]            (3x4; [u v 1]^T ~ P [X Y Z 1]^T, X Y Z in CT mm)
// scaled as is: its last row is [r3^T, tz] with |r3| = 1, so w = P.row(2) X is the depth of X
// along the principal axis (mm), positive in front of the source. A problem whose object frame is
// the CT frame mirrored (pose problems with `handedness: mirrored`: p_in_object = diag(1,-1,1)
// p_in_ct) gets P = K [R | t] diag(1, -1, 1, 1): a valid projection matrix for CT points, but one
// whose rotation part is improper, which RTK's and plastimatch's parameterisations cannot carry
// (their exports refuse it).
//
// INTRINSICS PER VIEW: every view carries its own Camera. The front ends fill it from their
// intrinsics source (pose problems: the problem's camera; joint problems: the view's intrinsics
// group), so a per-view calibration plugs in without changing the exports.
//
// geometry.json (version 1):
//   { "format": "carmba-geometry", "version": 1,
//     "frame": "...",                       // what the world frame is (the CT / patient frame)
//     "image": "...",                       // the undistorted-image convention above, in words
//     "reference_point_ct_mm": [x, y, z],   // optional: e.g. the fiducials' centroid (the
//                                           // plastimatch export's isocentre; see below)
//     "views": [ { "id": "...",
//                  "camera": {camera.json of this view: image_size, fx, fy, cx, cy, distortion},
//                  "cam_from_ct": {"rvec": [...], "t_mm": [...]},
//                  "ct_mirrored": false,
//                  "sid_mm": 1000,                   // optional: nominal source-detector distance
//                  "P": [[...4], [...4], [...4]],    // px from CT mm (derived; checked on reading)
//                  "source_ct_mm": [...], "principal_axis_ct": [...] } ] }   // derived
// On reading, P is recomputed from camera and cam_from_ct and must agree to 1e-9 relative.
#pragma once

#include <Eigen/Dense>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "camera/camera.h"
#include "geometry/pose.h"
#include "util/status.h"

namespace carmba {

using Matrix34 = Eigen::Matrix<double, 3, 4>;

struct ViewGeometry {
  std::string id;
  Camera camera;                  // this view's intrinsics (P uses fx fy cx cy; the rest is
                                  // what `carmba undistort` removes)
  Pose6 cam_from_ct = Pose6::Zero();  // rvec (rad), t (mm)
  bool ct_mirrored = false;       // the solve's object frame is the CT frame with y negated
  std::optional<double> sid_mm;   // nominal source-to-detector distance, when known
};

struct GeometrySet {
  std::string frame = "CT / patient frame of the fiducials (mm)";
  std::optional<Eigen::Vector3d> reference_point_ct_mm;
  std::vector<ViewGeometry> views;
};

// P = K [R | t] (mirrored: times diag(1,-1,1,1)); see the header comment.
Matrix34 ProjectionMatrix(const ViewGeometry& view);
// The X-ray source (centre of projection) in the CT frame, mm: -R^T t (mirrored: y negated).
Eigen::Vector3d SourceInCt(const ViewGeometry& view);
// The principal axis (unit, from the source towards the detector) in the CT frame.
Eigen::Vector3d PrincipalAxisInCt(const ViewGeometry& view);
// A view with `camera` whose source is at `source_ct_mm` and whose principal axis passes through
// `target_ct_mm`, its image x axis horizontal in the CT frame (perpendicular to CT z; to CT y when
// looking along z) and then rolled by `roll_rad` about the axis. (Synthetic geometries, tests.)
ViewGeometry ViewLookingAt(const std::string& id,
                           const Camera& camera,
                           const Eigen::Vector3d& source_ct_mm,
                           const Eigen::Vector3d& target_ct_mm,
                           double roll_rad);

// Projects a CT point (mm) with P; false if it is not in front of the source.
bool ProjectWithMatrix(const Matrix34& P, const Eigen::Vector3d& p_ct, Eigen::Vector2d* uv);

// The isocentre used where a tool wants one (plastimatch drr's -o): the reference point when
// the set has one, else the least-squares intersection of the views' principal axes. Error: no
// reference point and fewer than two views, or axes too close to parallel (the intersection is
// ill-conditioned: smallest eigenvalue of sum (I - a a^T) below 1e-3).
StatusOr<Eigen::Vector3d> GeometryIsocentre(const GeometrySet& set);

nlohmann::json GeometryToJson(const GeometrySet& set);
// Reads geometry.json. Errors name the file and the key (views[2].camera.fx ...), an
// inconsistent P (an edited file) included.
StatusOr<GeometrySet> ReadGeometryJson(const std::string& path);

// Largest absolute difference of two matrices, each first divided by its own Frobenius norm
// (projection matrices are defined up to scale; both here carry the same scale convention).
double RelativeMatrixDifference(const Matrix34& a, const Matrix34& b);

}  // namespace carmba
