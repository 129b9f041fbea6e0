// Per-view projection matrices and geometry.json (view_geometry.h).
#include "export/view_geometry.h"

#include <cmath>

#include "geometry/rotation.h"
#include "util/file_util.h"
#include "util/plausible.h"

namespace carmba {
namespace {

constexpr double kPTolerance = 1e-9;  // relative; P is written with 17 significant digits

Eigen::Matrix3d MirrorY() { return Eigen::Vector3d(1, -1, 1).asDiagonal(); }

nlohmann::json Vec(const Eigen::VectorXd& v) {
  nlohmann::json a = nlohmann::json::array();
  for (Eigen::Index i = 0; i < v.size(); ++i) a.push_back(v[i]);
  return a;
}

// Reads a JSON array of n finite numbers; errors name `where`.
Status ReadNumberArray(const nlohmann::json& a, int n, const std::string& where, double* out) {
  if (!a.is_array() || static_cast<int>(a.size()) != n) {
    return Status::Error(where + ": expected an array of " + std::to_string(n) + " numbers");
  }
  for (int i = 0; i < n; ++i) {
    if (!a[i].is_number() || !std::isfinite(a[i].get<double>())) {
      return Status::Error(where + "[" + std::to_string(i) + "]: expected a finite number");
    }
    out[i] = a[i].get<double>();
  }
  return Status::Ok();
}

// The same for j[key]; errors name `prefix` + key.
Status ReadNumbers(const nlohmann::json& j,
                   const std::string& key,
                   int n,
                   const std::string& prefix,
                   double* out) {
  if (!j.contains(key)) return Status::Error(prefix + key + ": missing");
  return ReadNumberArray(j.at(key), n, prefix + key, out);
}

}  // namespace

Matrix34 ProjectionMatrix(const ViewGeometry& v) {
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  K(0, 0) = v.camera.params[kFx];
  K(1, 1) = v.camera.params[kFy];
  K(0, 2) = v.camera.params[kCx];
  K(1, 2) = v.camera.params[kCy];
  Eigen::Matrix3d R = RotationOf(v.cam_from_ct.head<3>());
  if (v.ct_mirrored) R = R * MirrorY();
  Matrix34 Rt;
  Rt.leftCols<3>() = R;
  Rt.col(3) = v.cam_from_ct.tail<3>();
  return K * Rt;
}

Eigen::Vector3d SourceInCt(const ViewGeometry& v) {
  const Eigen::Matrix3d R = RotationOf(v.cam_from_ct.head<3>());
  Eigen::Vector3d c = -R.transpose() * v.cam_from_ct.tail<3>();
  if (v.ct_mirrored) c = MirrorY() * c;
  return c;
}

Eigen::Vector3d PrincipalAxisInCt(const ViewGeometry& v) {
  Eigen::Vector3d a = RotationOf(v.cam_from_ct.head<3>()).row(2).transpose();
  if (v.ct_mirrored) a = MirrorY() * a;
  return a;
}

ViewGeometry ViewLookingAt(const std::string& id,
                           const Camera& camera,
                           const Eigen::Vector3d& source,
                           const Eigen::Vector3d& target,
                           double roll_rad) {
  const Eigen::Vector3d z = (target - source).normalized();
  const Eigen::Vector3d hint =
      std::abs(z.z()) < 0.9 ? Eigen::Vector3d(0, 0, -1) : Eigen::Vector3d(0, 1, 0);
  const Eigen::Vector3d x = hint.cross(z).normalized();
  Eigen::Matrix3d R;
  R.row(0) = x.transpose();
  R.row(1) = z.cross(x).transpose();
  R.row(2) = z.transpose();
  R = Eigen::AngleAxisd(roll_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix() * R;
  ViewGeometry v;
  v.id = id;
  v.camera = camera;
  v.cam_from_ct.head<3>() = RvecFromRotation(R);
  v.cam_from_ct.tail<3>() = -R * source;
  return v;
}

bool ProjectWithMatrix(const Matrix34& P, const Eigen::Vector3d& p_ct, Eigen::Vector2d* uv) {
  const Eigen::Vector3d h = P * p_ct.homogeneous();
  if (!(h[2] > 0) || !h.allFinite()) return false;
  *uv = h.head<2>() / h[2];
  return true;
}

double RelativeMatrixDifference(const Matrix34& a, const Matrix34& b) {
  return (a / a.norm() - b / b.norm()).cwiseAbs().maxCoeff();
}

StatusOr<Eigen::Vector3d> GeometryIsocentre(const GeometrySet& set) {
  if (set.reference_point_ct_mm) return *set.reference_point_ct_mm;
  if (set.views.size() < 2) {
    return Status::Error("no reference_point_ct_mm and fewer than two views: no isocentre");
  }
  // argmin_x sum_v |(I - a a^T)(x - c)|^2  ->  [sum (I - a a^T)] x = sum (I - a a^T) c.
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const auto& v : set.views) {
    const Eigen::Vector3d a = PrincipalAxisInCt(v);
    const Eigen::Matrix3d Q = Eigen::Matrix3d::Identity() - a * a.transpose();
    A += Q;
    b += Q * SourceInCt(v);
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(A);
  if (eig.eigenvalues()[0] < 1e-3) {
    return Status::Error("the views' principal axes are nearly parallel: their intersection (the "
                         "isocentre) is undefined; give reference_point_ct_mm");
  }
  return Eigen::Vector3d(A.ldlt().solve(b));
}

nlohmann::json GeometryToJson(const GeometrySet& set) {
  nlohmann::json j;
  j["format"] = "carmba-geometry";
  j["version"] = 1;
  j["frame"] = set.frame;
  j["image"] =
      "undistorted: same size as the original image, pixel (0,0) = centre of the top-left pixel, "
      "u right, v down; ideal pinhole with the view's fx fy cx cy, no distortion (carmba "
      "undistort); P maps CT mm to these pixels: [u v 1] ~ P [X Y Z 1], P = K [R | t], its last "
      "row the depth in mm";
  if (set.reference_point_ct_mm) j["reference_point_ct_mm"] = Vec(*set.reference_point_ct_mm);
  nlohmann::json views = nlohmann::json::array();
  for (const auto& v : set.views) {
    nlohmann::json vj;
    vj["id"] = v.id;
    nlohmann::json cam = CameraToJson(v.camera);
    cam.erase("covariance");
    cam.erase("rms_px");
    vj["camera"] = cam;
    vj["cam_from_ct"] = {{"rvec", Vec(v.cam_from_ct.head<3>())},
                         {"t_mm", Vec(v.cam_from_ct.tail<3>())}};
    vj["ct_mirrored"] = v.ct_mirrored;
    if (v.sid_mm) vj["sid_mm"] = *v.sid_mm;
    const Matrix34 P = ProjectionMatrix(v);
    nlohmann::json pj = nlohmann::json::array();
    for (int r = 0; r < 3; ++r) pj.push_back(Vec(P.row(r).transpose()));
    vj["P"] = pj;
    vj["source_ct_mm"] = Vec(SourceInCt(v));
    vj["principal_axis_ct"] = Vec(PrincipalAxisInCt(v));
    views.push_back(vj);
  }
  j["views"] = views;
  return j;
}

StatusOr<GeometrySet> ReadGeometryJson(const std::string& path) {
  auto parsed = ReadJsonFile(path, "a carmba geometry.json");
  if (!parsed.ok()) return parsed.status();
  const nlohmann::json& j = *parsed;
  if (!j.is_object() || j.value("format", std::string()) != "carmba-geometry") {
    return Status::Error(path + ": key 'format': expected \"carmba-geometry\" (a geometry.json "
                                "written by carmba solve)");
  }
  if (!j.contains("version") || !j["version"].is_number_integer() || j["version"].get<int>() != 1) {
    return Status::Error(path + ": key 'version': expected 1");
  }
  GeometrySet set;
  if (j.contains("frame") && j["frame"].is_string()) set.frame = j["frame"].get<std::string>();
  if (j.contains("reference_point_ct_mm")) {
    Eigen::Vector3d p;
    CARMBA_RETURN_IF_ERROR(ReadNumbers(j, "reference_point_ct_mm", 3, path + ": ", p.data()));
    set.reference_point_ct_mm = p;
  }
  if (!j.contains("views") || !j["views"].is_array() || j["views"].empty()) {
    return Status::Error(path + ": key 'views': expected a non-empty array");
  }
  for (size_t k = 0; k < j["views"].size(); ++k) {
    const auto& vj = j["views"][k];
    const std::string where = path + ": views[" + std::to_string(k) + "]";
    if (!vj.is_object()) return Status::Error(where + ": expected an object");
    ViewGeometry v;
    if (!vj.contains("id") || !vj["id"].is_string() || vj["id"].get<std::string>().empty()) {
      return Status::Error(where + ".id: expected a non-empty string");
    }
    v.id = vj["id"].get<std::string>();
    if (!vj.contains("camera")) return Status::Error(where + ".camera: missing");
    auto cam = CameraFromJson(vj["camera"], where + ".camera");  // checks the ranges too
    if (!cam.ok()) return cam.status();
    v.camera = *cam;
    if (!vj.contains("cam_from_ct") || !vj["cam_from_ct"].is_object()) {
      return Status::Error(where + ".cam_from_ct: expected {\"rvec\": [3], \"t_mm\": [3]}");
    }
    CARMBA_RETURN_IF_ERROR(
        ReadNumbers(vj["cam_from_ct"], "rvec", 3, where + ".cam_from_ct.", v.cam_from_ct.data()));
    CARMBA_RETURN_IF_ERROR(ReadNumbers(
        vj["cam_from_ct"], "t_mm", 3, where + ".cam_from_ct.", v.cam_from_ct.data() + 3));
    for (int i = 3; i < 6; ++i) {
      if (!InRange(v.cam_from_ct[i], plausible::kCoordinateMm)) {
        return Status::Error(where + ".cam_from_ct.t_mm: expected " +
                             FormatRange(plausible::kCoordinateMm) + ", got " +
                             FormatCompact(v.cam_from_ct[i]));
      }
    }
    if (vj.contains("ct_mirrored")) {
      if (!vj["ct_mirrored"].is_boolean()) {
        return Status::Error(where + ".ct_mirrored: expected true or false");
      }
      v.ct_mirrored = vj["ct_mirrored"].get<bool>();
    }
    if (vj.contains("sid_mm")) {
      double sid = 0;
      if (!vj["sid_mm"].is_number() || !InRange(sid = vj["sid_mm"].get<double>(),
                                                plausible::kDistanceMm)) {
        return Status::Error(where + ".sid_mm: expected a number in " +
                             FormatRange(plausible::kDistanceMm));
      }
      v.sid_mm = sid;
    }
    if (vj.contains("P")) {
      Matrix34 P;
      const auto& pj = vj["P"];
      if (!pj.is_array() || pj.size() != 3) {
        return Status::Error(where + ".P: expected 3 rows of 4 numbers");
      }
      for (int r = 0; r < 3; ++r) {
        double row[4];
        CARMBA_RETURN_IF_ERROR(
            ReadNumberArray(pj[r], 4, where + ".P[" + std::to_string(r) + "]", row));
        for (int c = 0; c < 4; ++c) P(r, c) = row[c];
      }
      const double d = RelativeMatrixDifference(P, ProjectionMatrix(v));
      if (!(d <= kPTolerance)) {
        return Status::Error(where +
                             ".P: differs from K [R | t] of its camera and cam_from_ct by " +
                             FormatCompact(d) + " (relative; expected <= 1e-9): edited by hand?");
      }
    }
    set.views.push_back(v);
  }
  return set;
}

}  // namespace carmba
