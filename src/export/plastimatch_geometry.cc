// plastimatch projection-matrix files and drr arguments (plastimatch_geometry.h).
#include "export/plastimatch_geometry.h"

#include <cmath>
#include <cstdio>
#include <sstream>

#include "geometry/rotation.h"
#include "util/file_util.h"
#include "util/format.h"
#include "util/plausible.h"

namespace carmba {
namespace {

std::string Triple(const Eigen::Vector3d& v) {
  return FmtRoundTrip(v[0]) + " " + FmtRoundTrip(v[1]) + " " + FmtRoundTrip(v[2]);
}

}  // namespace

StatusOr<std::vector<PlastimatchProjMat>> PlastimatchFromGeometry(const GeometrySet& set,
                                                                  double sid_mm) {
  if (!InRange(sid_mm, plausible::kDistanceMm)) {
    return Status::Error("source-detector distance: expected " +
                         FormatRange(plausible::kDistanceMm) + ", got " + FormatCompact(sid_mm));
  }
  auto iso = GeometryIsocentre(set);
  if (!iso.ok()) return iso.status();
  std::vector<PlastimatchProjMat> out;
  for (const auto& v : set.views) {
    if (v.ct_mirrored) {
      return Status::Error("view '" + v.id + "': the CT frame is mirrored (handedness: mirrored): "
                           "plastimatch's geometry cannot carry a reflection");
    }
    const Eigen::Matrix3d R = RotationOf(v.cam_from_ct.head<3>());
    const Eigen::Vector3d t = v.cam_from_ct.tail<3>();
    const Eigen::Vector3d src = SourceInCt(v), axis = PrincipalAxisInCt(v);
    PlastimatchProjMat pm;
    pm.id = v.id;
    pm.width = v.camera.width;
    pm.height = v.camera.height;
    pm.sid_mm = sid_mm;
    pm.sad_mm = axis.dot(*iso - src);
    if (!(pm.sad_mm > 0)) {
      return Status::Error("view '" + v.id + "': the isocentre is not in front of the source");
    }
    pm.isocentre_ct_mm = src + pm.sad_mm * axis;
    pm.ic[0] = v.camera.params[kCx];
    pm.ic[1] = v.camera.params[kCy];
    pm.extrinsic.topLeftCorner<3, 3>() = R;
    pm.extrinsic.topRightCorner<3, 1>() = t;
    pm.intrinsic(0, 0) = v.camera.params[kFx] / sid_mm;  // 1 / ps_u
    pm.intrinsic(1, 1) = v.camera.params[kFy] / sid_mm;  // 1 / ps_v
    pm.intrinsic(2, 2) = 1 / sid_mm;
    pm.matrix = pm.intrinsic * pm.extrinsic;
    pm.nrm = axis;
    pm.vup = -R.row(1).transpose();
    out.push_back(pm);
  }
  return out;
}

std::string PlastimatchProjMatText(const PlastimatchProjMat& pm) {
  std::ostringstream o;
  o << FmtRoundTrip(pm.ic[0]) << " " << FmtRoundTrip(pm.ic[1]) << "\n";
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) o << (c ? " " : "") << FmtRoundTrip(pm.matrix(r, c));
    o << "\n";
  }
  o << FmtRoundTrip(pm.sad_mm) << "\n" << FmtRoundTrip(pm.sid_mm) << "\n" << Triple(pm.nrm) << "\n";
  o << "Extrinsic\n";
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) o << (c ? " " : "") << FmtRoundTrip(pm.extrinsic(r, c));
    o << "\n";
  }
  o << "Intrinsic\n";
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) o << (c ? " " : "") << FmtRoundTrip(pm.intrinsic(r, c));
    o << "\n";
  }
  return o.str();
}

StatusOr<PlastimatchProjMat> ReadPlastimatchProjMat(const std::string& path) {
  auto text = ReadFile(path);
  if (!text.ok()) return text.status();
  std::istringstream in(*text);
  double v[19];
  static const char* const kWhat[] = {"image centre", "matrix", "sad", "sid", "nrm"};
  for (int k = 0; k < 19; ++k) {
    const int what = k < 2 ? 0 : k < 14 ? 1 : k == 14 ? 2 : k == 15 ? 3 : 4;
    if (!(in >> v[k]) || !std::isfinite(v[k])) {
      return Status::Error(path + ": number " + std::to_string(k + 1) + " (" + kWhat[what] +
                           "): expected a finite number");
    }
  }
  PlastimatchProjMat pm;
  pm.ic[0] = v[0];
  pm.ic[1] = v[1];
  for (int k = 0; k < 12; ++k) pm.matrix(k / 4, k % 4) = v[2 + k];
  pm.sad_mm = v[14];
  pm.sid_mm = v[15];
  pm.nrm = Eigen::Vector3d(v[16], v[17], v[18]);
  if (!(pm.sid_mm > 0)) return Status::Error(path + ": sid: expected a positive distance");
  return pm;
}

Matrix34 PixelMatrixFromPlastimatch(const PlastimatchProjMat& pm) {
  Eigen::Matrix3d C = Eigen::Matrix3d::Identity();
  C(0, 2) = pm.ic[0];
  C(1, 2) = pm.ic[1];
  return C * pm.matrix;
}

std::string PlastimatchDrrArgs(const PlastimatchProjMat& pm) {
  const double ps_u = 1 / pm.intrinsic(0, 0), ps_v = 1 / pm.intrinsic(1, 1);
  std::ostringstream o;
  o << "-r \"" << pm.width << " " << pm.height << "\" -z \"" << FmtRoundTrip(pm.width * ps_u) << " "
    << FmtRoundTrip(pm.height * ps_v) << "\" -c \"" << FmtRoundTrip(pm.ic[0]) << " "
    << FmtRoundTrip(pm.ic[1]) << "\" -o \"" << Triple(pm.isocentre_ct_mm) << "\" -n \""
    << Triple(-pm.nrm) << "\" --vup \"" << Triple(pm.vup) << "\" --sad " << FmtRoundTrip(pm.sad_mm)
    << " --sid " << FmtRoundTrip(pm.sid_mm);
  return o.str();
}

}  // namespace carmba
