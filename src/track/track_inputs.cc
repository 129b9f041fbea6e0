// The inputs of `carmba track`: the cameras' calibration text and the images paired by frame.

#include <Eigen/SVD>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "camera/camera.h"
#include "geometry/rotation.h"
#include "track/track.h"
#include "util/csv.h"
#include "util/file_util.h"
#include "util/plausible.h"

namespace carmba {

namespace {

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// The numbers of one line: separated by commas, spaces or tabs. False on anything else.
bool ParseNumbers(const std::string& line, std::vector<double>* out) {
  out->clear();
  std::string token;
  std::istringstream in(line);
  for (std::string field; in >> field;) {
    std::istringstream parts(field);
    for (std::string part; std::getline(parts, part, ',');) {
      if (part.empty()) continue;
      char* end = nullptr;
      const double x = std::strtod(part.c_str(), &end);
      if (end == part.c_str() || *end != '\0' || !std::isfinite(x)) return false;
      out->push_back(x);
    }
  }
  return true;
}

}  // namespace

Eigen::Vector3d TrackCamera::CentreInLab() const {
  return -RotationOf(cam_from_lab.data()).transpose() * cam_from_lab.tail<3>();
}

Eigen::Vector3d TrackCamera::AxisInLab() const {
  return RotationOf(cam_from_lab.data()).transpose() * Eigen::Vector3d::UnitZ();
}

StatusOr<TrackCamera> ReadXmaCalibration(const std::string& path, const std::string& name) {
  std::ifstream in(path);
  if (!in)
    return Status::Error(path + ": cannot be read (expected an XMALab camera calibration text)");
  // Section name -> (rows expected, numbers per row).
  const std::map<std::string, std::pair<int, int>> kSections = {{"image size", {1, 2}},
                                                                {"camera matrix", {3, 3}},
                                                                {"rotation", {3, 3}},
                                                                {"translation", {3, 1}}};
  std::map<std::string, std::vector<std::vector<double>>> values;
  std::string section, line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    const std::string t = TrimSpaces(line);
    if (t.empty()) continue;
    const std::string where = path + ":" + std::to_string(line_no);
    if (std::isalpha(static_cast<unsigned char>(t[0]))) {
      section = Lower(t);
      if (!kSections.count(section)) {
        return Status::Error(where + ": unknown section '" + t +
                             "' (expected image size, camera matrix, rotation or translation)");
      }
      if (values.count(section)) return Status::Error(where + ": section '" + t + "' given twice");
      values[section];
      continue;
    }
    if (section.empty()) return Status::Error(where + ": numbers before any section heading");
    std::vector<double> row;
    const auto [rows, per_row] = kSections.at(section);
    if (!ParseNumbers(t, &row) || static_cast<int>(row.size()) != per_row) {
      return Status::Error(where + ": expected " + std::to_string(per_row) +
                           " number(s) in section '" + section + "', got '" + t + "'");
    }
    if (static_cast<int>(values[section].size()) == rows) {
      return Status::Error(where + ": section '" + section + "' has more than " +
                           std::to_string(rows) + " row(s)");
    }
    values[section].push_back(row);
  }
  for (const auto& [s, shape] : kSections) {
    if (!values.count(s) || static_cast<int>(values[s].size()) != shape.first) {
      return Status::Error(path + ": section '" + s + "' is missing or has fewer than " +
                           std::to_string(shape.first) + " row(s)");
    }
  }
  TrackCamera cam;
  cam.name = name;
  cam.width = static_cast<int>(values["image size"][0][0]);
  cam.height = static_cast<int>(values["image size"][0][1]);
  if (cam.width != values["image size"][0][0] || cam.height != values["image size"][0][1] ||
      !InRange(cam.width, plausible::kImageSizePx) ||
      !InRange(cam.height, plausible::kImageSizePx)) {
    return Status::Error(path + ": image size must be two whole numbers in " +
                         FormatRange(plausible::kImageSizePx));
  }
  const auto& K = values["camera matrix"];
  if (K[0][1] != 0 || K[1][0] != 0 || K[2][0] != 0 || K[2][1] != 0 || K[2][2] != 1) {
    return Status::Error(path + ": camera matrix must be [fx 0 cx; 0 fy cy; 0 0 1] (no skew)");
  }
  cam.intrinsics = {K[0][0], K[1][1], K[0][2], K[1][2], 0, 0, 0, 0, 0};
  if (!InRange(K[0][0], plausible::kFocalPx) || !InRange(K[1][1], plausible::kFocalPx) ||
      !InRange(K[0][2], plausible::kPixelCoordinatePx) ||
      !InRange(K[1][2], plausible::kPixelCoordinatePx)) {
    return Status::Error(path + ": camera matrix fx, fy must be in " +
                         FormatRange(plausible::kFocalPx) + ", cx, cy in " +
                         FormatRange(plausible::kPixelCoordinatePx));
  }
  Eigen::Matrix3d R;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) R(i, j) = values["rotation"][i][j];
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() > 1e-4 || R.determinant() < 0) {
    return Status::Error(path +
                         ": rotation is not a rotation matrix (orthonormal, det +1 within 1e-4)");
  }
  cam.cam_from_lab.head<3>() = RvecFromRotation(NearestRotation(R));
  for (int i = 0; i < 3; ++i) cam.cam_from_lab[3 + i] = values["translation"][i][0];
  if (!InRange(cam.CentreInLab().norm(), plausible::kSourceToObjectMm)) {
    return Status::Error(path + ": the source lies " + FormatCompact(cam.CentreInLab().norm()) +
                         " mm from the lab origin, outside " +
                         FormatRange(plausible::kSourceToObjectMm) + " (translation in metres?)");
  }
  return cam;
}

StatusOr<TrackCamera> ReadCameraJsonWithPose(const std::string& camera_json,
                                             const std::string& pose_json,
                                             const std::string& name) {
  auto camera = ReadCameraJson(camera_json);
  if (!camera.ok()) return camera.status();
  auto j = ReadJsonFile(pose_json, "a JSON object with cam_from_lab {rvec, t_mm}");
  if (!j.ok()) return j.status();
  const nlohmann::json* pose =
      j->is_object() && j->contains("cam_from_lab") ? &(*j)["cam_from_lab"] : nullptr;
  auto vec3 = [&](const char* key, Eigen::Vector3d* out) {
    if (!pose || !pose->is_object() || !pose->contains(key) || !(*pose)[key].is_array() ||
        (*pose)[key].size() != 3) {
      return false;
    }
    for (int i = 0; i < 3; ++i) {
      if (!(*pose)[key][i].is_number()) return false;
      (*out)[i] = (*pose)[key][i].get<double>();
    }
    return out->allFinite();
  };
  Eigen::Vector3d r, t;
  if (!vec3("rvec", &r) || !vec3("t_mm", &t)) {
    return Status::Error(
        pose_json +
        ": key 'cam_from_lab': expected {\"rvec\": [3 numbers, rad], \"t_mm\": [3 numbers, mm]}");
  }
  if (r.norm() > 2 * M_PI + 1e-9)
    return Status::Error(
        pose_json +
        ": key 'cam_from_lab.rvec': a rotation vector of at most 2 pi rad (degrees given?)");
  TrackCamera cam;
  cam.name = name;
  cam.width = camera->width;
  cam.height = camera->height;
  cam.intrinsics = camera->params;
  cam.cam_from_lab << r, t;
  const auto n = static_cast<Eigen::Index>(camera->covariance_names.size());
  cam.covariance = Eigen::MatrixXd::Zero(n, n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const auto it = std::find_if(std::begin(kIntrinsicNames), std::end(kIntrinsicNames),
                                 [&](const char* k) { return camera->covariance_names[i] == k; });
    cam.covariance_indices.push_back(static_cast<int>(it - std::begin(kIntrinsicNames)));
    for (Eigen::Index k = 0; k < n; ++k) cam.covariance(i, k) = camera->covariance[i][k];
  }
  if (!InRange(cam.CentreInLab().norm(), plausible::kSourceToObjectMm)) {
    return Status::Error(pose_json + ": the source lies " +
                         FormatCompact(cam.CentreInLab().norm()) +
                         " mm from the lab origin, outside " +
                         FormatRange(plausible::kSourceToObjectMm) + " (t_mm in metres?)");
  }
  return cam;
}

StatusOr<TrackCamera> ReadTrackCamera(const std::string& name, const std::string& spec) {
  const auto plus = spec.find('+');
  if (plus == std::string::npos) return ReadXmaCalibration(spec, name);
  return ReadCameraJsonWithPose(spec.substr(0, plus), spec.substr(plus + 1), name);
}

StatusOr<int> FrameNumberOfFile(const std::string& path) {
  std::string base = path.substr(path.find_last_of('/') + 1);
  const auto hash = base.find('#');
  if (hash != std::string::npos) base = base.substr(0, hash);
  const auto dot = base.find_last_of('.');
  if (dot != std::string::npos && dot > 0) base = base.substr(0, dot);
  const auto last = base.find_last_of("0123456789");
  if (last == std::string::npos) {
    return Status::Error(
        path + ": no frame number in the file name (expected digits, e.g. name.0002.tif)");
  }
  auto first = last;
  while (first > 0 && std::isdigit(static_cast<unsigned char>(base[first - 1]))) --first;
  const std::string digits = base.substr(first, last - first + 1);
  if (digits.size() > 9) return Status::Error(path + ": frame number '" + digits + "' is too long");
  return std::stoi(digits);
}

StatusOr<std::vector<TrackFrame>> PairFrames(const std::vector<std::vector<std::string>>& images,
                                             std::vector<std::string>* unpaired) {
  std::map<int, TrackFrame> by_number;
  for (size_t c = 0; c < images.size(); ++c) {
    for (const std::string& path : images[c]) {
      auto n = FrameNumberOfFile(path);
      if (!n.ok()) return n.status();
      TrackFrame& f = by_number[*n];
      f.number = *n;
      f.image_per_camera.resize(images.size());
      if (!f.image_per_camera[c].empty()) {
        return Status::Error("frame " + std::to_string(*n) + " is given twice for one camera: " +
                             f.image_per_camera[c] + " and " + path);
      }
      f.image_per_camera[c] = path;
    }
  }
  std::vector<TrackFrame> frames;
  for (auto& [n, f] : by_number) {
    const auto seen = std::count_if(f.image_per_camera.begin(), f.image_per_camera.end(),
                                    [](const std::string& p) { return !p.empty(); });
    if (seen >= 2) {
      frames.push_back(f);
    } else if (unpaired) {
      for (const auto& p : f.image_per_camera)
        if (!p.empty()) unpaired->push_back(p);
    }
  }
  if (frames.empty()) {
    return Status::Error("no frame number is imaged by two cameras (frames are paired by the "
                         "number in the file names)");
  }
  return frames;
}

}  // namespace carmba
