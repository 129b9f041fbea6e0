// RTK's ThreeDCircularGeometry (XML version 3) from carmba's per-view geometry, and back.
//
// RTK (RTK documentation/docs/Geometry.md, src/rtkThreeDCircularProjectionGeometry*.cxx) maps
// its fixed frame (here: the CT frame, mm; RTK's isocentre is the CT origin) to DETECTOR mm:
//   M = [1 0 sx-px; 0 1 sy-py; 0 0 1] . [-SDD 0 0 0; 0 -SDD 0 0; 0 0 1 -SID] . T(-sx,-sy,0) . Rrtk
//   Rrtk = Rz(-InPlane) . Rx(-OutOfPlane) . Ry(-Gantry)    (right-handed elementary rotations)
// with the source at (sx, sy, SID) in the rotated frame and the detector plane at
// z = SID - SDD: the detector's u axis is the rotated x, its v axis the rotated y, and the rays
// run along -z. That is a camera with x right, y UP and z towards the source (OpenGL-like), while
// carmba's camera has y DOWN and z towards the detector; the two differ by a rotation of 180
// degrees about x:  Rrtk = diag(1, -1, -1) R  (R of cam_from_ct).
//
// CONVERSION (exact, both ways). With the view's P = K [R | t] (export/view_geometry.h), the
// source S = -R^T t and a chosen SDD:
//   (sx, sy, SID) = Rrtk S                         (SID = depth of the CT origin along the axis)
//   detector pitch  d_u = SDD / fx,  d_v = SDD / fy   (mm per undistorted pixel)
//   detector mm     x_d = d_u (u - (W-1)/2),  y_d = d_v ((H-1)/2 - v)
//     i.e. the RTK projection image is the undistorted image FLIPPED UPSIDE DOWN (its row j is
//     row H-1-j of carmba's image), with spacing (d_u, d_v), origin (-(W-1)/2 d_u, -(H-1)/2 d_v)
//     and identity direction (rtk_detector.json says so for each export);
//   principal point (cx, cy) -> (ppx, ppy) = (d_u (cx - (W-1)/2), d_v ((H-1)/2 - cy)),
//     ProjectionOffsetX = sx - ppx, ProjectionOffsetY = sy - ppy;
//   the angles from Rrtk (ZXY Euler angles; RTK's own decomposition of a matrix does the same),
//     wrapped to [0, 360) as RTK stores them.
// Then M = -A P with A = [d_u 0 -d_u (W-1)/2; 0 -d_v d_v (H-1)/2; 0 0 1] (px -> detector mm), the
// minus sign because RTK's third row is z_rotated - SID = -depth.
//
// fx != fy: RTK's geometry is in detector mm with one SDD per projection (square in mm), but its
// projection IMAGES may have different spacings along u and v (ITK images carry a spacing per
// axis). carmba puts the anisotropy there: d_u = SDD / fx, d_v = SDD / fy, exactly, no residual.
// One projection stack has one spacing, so all views must share (fx / fy) and the image size;
// views whose fx differ get their own SDD = d_u fx (d_u from the first view). A set whose views
// differ in fx / fy by more than 1e-9 (relative) or in image size is refused with an error
// naming the view.
#pragma once

#include <string>
#include <vector>

#include "export/view_geometry.h"
#include "util/status.h"

namespace carmba {

// One RTK projection: its nine parameters (mm, degrees) and its matrix (CT mm -> detector mm).
struct RtkProjection {
  std::string id;  // carmba's view id (written as an XML comment)
  double sid_mm = 0, sdd_mm = 0;
  double gantry_deg = 0, out_of_plane_deg = 0, in_plane_deg = 0;
  double source_offset_x_mm = 0, source_offset_y_mm = 0;
  double projection_offset_x_mm = 0, projection_offset_y_mm = 0;
  Matrix34 matrix = Matrix34::Zero();
};

// The projection images' layout for RTK (one stack).
struct RtkDetector {
  int width = 0, height = 0;         // px
  double spacing_u_mm = 0, spacing_v_mm = 0;
  // origin = (-(W-1)/2 d_u, -(H-1)/2 d_v); rows flipped (see the header comment).
  double origin_u_mm() const { return -0.5 * (width - 1) * spacing_u_mm; }
  double origin_v_mm() const { return -0.5 * (height - 1) * spacing_v_mm; }
};

// RTK's matrix from the nine parameters (the formula above; RTK's AddProjectionInRadians).
Matrix34 RtkMatrix(const RtkProjection& p);

// The RTK projections of a geometry set with `sdd_mm` for the first view (see fx != fy above).
// Errors: a mirrored CT frame, views of different image sizes or fx / fy.
StatusOr<std::vector<RtkProjection>> RtkFromGeometry(const GeometrySet& set,
                                                     double sdd_mm,
                                                     RtkDetector* detector);

// Back to pixels of the undistorted image: P = -A^-1 M (scaled like ProjectionMatrix).
Matrix34 PixelMatrixFromRtk(const Matrix34& rtk_matrix, const RtkDetector& detector);

// The XML file (version 3, as RTK's writer lays it out: SDD once at the top when all views share
// it, the rest per projection, numbers with 17 significant digits).
std::string RtkGeometryXml(const std::vector<RtkProjection>& projections);

// Reads an RTK ThreeDCircularGeometry XML file (version 2 or 3; elements at the top apply to
// every projection until a projection sets its own, as in RTK's reader). Like RTK's reader,
// recomputes each matrix from the parameters and refuses a file where an entry differs by more
// than 0.001. Errors name the file and the element.
StatusOr<std::vector<RtkProjection>> ReadRtkGeometryXml(const std::string& path);

// rtk_detector.json: size, spacing, origin, direction, the row flip and the views in order.
nlohmann::json RtkDetectorJson(const RtkDetector& detector,
                               const std::vector<RtkProjection>& projections);

}  // namespace carmba
