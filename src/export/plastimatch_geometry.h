// plastimatch's projection-matrix files and `plastimatch drr` arguments from carmba's per-view
// geometry (plastimatch 1.9.4, Debian 12's package; src/plastimatch/reconstruct/proj_matrix.cxx,
// proj_image.cxx, fdk.cxx, drr.cxx, cli/pcmd_drr.cxx).
//
// THE FILE (what `plastimatch drr` writes beside each DRR and `plastimatch fdk` reads beside each
// projection image, <name>.txt next to <name>.raw / .pfm), whitespace-separated numbers:
//   ic[0] ic[1]                 image centre, px: ic[0] along the image rows (u, columns),
//                               ic[1] down the image (v, rows); pixel (0,0) is the centre of the
//                               first pixel (fdk samples pixel round(v), round(u))
//   matrix (3 rows of 4)        u = ic[0] + m0.X / m2.X,  v = ic[1] + m1.X / m2.X  (X in CT mm)
//   sad                         source to isocentre, mm
//   sid                         source to detector, mm
//   nrm (3)                     the third extrinsic row: the unit vector from the source towards
//                               the isocentre (plastimatch's writer prints it so; fdk reads it)
//   "Extrinsic" + 4x4, "Intrinsic" + 3x4   (written for people; fdk reads only the lines above)
// with matrix = Intrinsic . Extrinsic, Extrinsic = [prt; pdn; -nrm_drr | translation], prt the
// panel's right (u) and pdn its down (v) direction, its third row giving the depth from the source,
// and Intrinsic = diag(1/ps_u, 1/ps_v, 1/sid) (ps = detector pitch in mm). This is carmba's camera
// frame exactly (x = u right, y = v down, z from source to detector): with P = K [R | t],
//   Extrinsic = [R | t],  ps_u = sid / fx,  ps_v = sid / fy,  ic = (cx, cy),
//   matrix = diag(fx, fy, 1) [R | t] / sid,  so  [1 0 ic0; 0 1 ic1; 0 0 1] . matrix = P / sid.
// Pixels may be non-square (ps_u != ps_v): fx != fy is carried exactly, per view. plastimatch
// reads the file with fscanf("%g") into a float: about 7 significant digits (1e-4 px here).
//
// `plastimatch drr` (measured on 1.9.4 with off-centre, non-square, anisotropic detectors; its
// --help says "row col" but every pair is (u, v)):
//   -r "W H"      detector pixels; the raw / pfm output has H rows of W floats, row 0 at --vup
//   -z "W*ps_u H*ps_v"   detector size in mm
//   -c "cx cy"    the principal point, px
//   -o "x y z"    isocentre (CT mm): on the principal axis, here the foot of the geometry's
//                 reference point (view_geometry.h GeometryIsocentre) on it
//   -n "x y z"    unit vector from the isocentre towards the source (= -z_cam)
//   --vup "x y z" towards the detector's top row (= -y_cam)
//   --sad  depth of the isocentre from the source;  --sid  the chosen source-detector distance
// It places the source at o + sad n and the detector centre at source - sid n; the ray of pixel
// (r, c) passes through (c - cx) ps_u prt + (r - cy) ps_v pdn on the detector: carmba's pinhole.
// The CT volume is read in its DICOM patient coordinates (plastimatch's "DICOM coordinates").
#pragma once

#include <string>
#include <vector>

#include "export/view_geometry.h"
#include "util/status.h"

namespace carmba {

struct PlastimatchProjMat {
  std::string id;
  double ic[2] = {0, 0};
  Matrix34 matrix = Matrix34::Zero();
  double sad_mm = 0, sid_mm = 0;
  Eigen::Vector3d nrm = Eigen::Vector3d::Zero();   // source -> isocentre (file line 7)
  Eigen::Matrix4d extrinsic = Eigen::Matrix4d::Identity();
  Matrix34 intrinsic = Matrix34::Zero();
  // For `plastimatch drr`:
  int width = 0, height = 0;
  Eigen::Vector3d isocentre_ct_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d vup = Eigen::Vector3d::Zero();
};

// One file per view; `sid_mm` is the source-detector distance used for the pitch (any positive
// value gives the same rays). Errors: a mirrored CT frame, an isocentre not in front of a source
// (GeometryIsocentre's errors).
StatusOr<std::vector<PlastimatchProjMat>> PlastimatchFromGeometry(const GeometrySet& set,
                                                                  double sid_mm);

// The file's text, laid out as plastimatch's own writer does, numbers with 17 significant digits.
std::string PlastimatchProjMatText(const PlastimatchProjMat& pm);

// Reads a projection-matrix file (the first 19 numbers: ic, matrix, sad, sid, nrm; like
// plastimatch's reader). Errors name the file and the entry.
StatusOr<PlastimatchProjMat> ReadPlastimatchProjMat(const std::string& path);

// [1 0 ic0; 0 1 ic1; 0 0 1] . matrix  (px from CT mm, scaled as P / sid).
Matrix34 PixelMatrixFromPlastimatch(const PlastimatchProjMat& pm);

// The arguments of `plastimatch drr` rendering this view (without -I / -O / -t), e.g.
//   -r "408 408" -z "..." -c "..." -o "..." -n "..." --vup "..." --sad ... --sid ...
std::string PlastimatchDrrArgs(const PlastimatchProjMat& pm);

}  // namespace carmba
