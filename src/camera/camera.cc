#include "camera/camera.h"

#include <cmath>

#include "util/file_util.h"

namespace carmba {

const char* const kIntrinsicNames[kNumIntrinsics] = {"fx", "fy", "cx", "cy", "k1",
                                                     "k2", "p1", "p2", "k3"};

Status Camera::Check() const {
  if (width <= 0 || height <= 0) return Status::Error("image_size must be positive");
  for (int i = 0; i < kNumIntrinsics; ++i) {
    if (!std::isfinite(params[i])) {
      return Status::Error(std::string(kIntrinsicNames[i]) + " is not finite");
    }
  }
  if (!(params[kFx] > 0) || !(params[kFy] > 0)) return Status::Error("fx and fy must be positive");
  return Status::Ok();
}

namespace {
StatusOr<double> Num(const nlohmann::json& j, const std::string& key, const std::string& where) {
  if (!j.contains(key)) return Status::Error(where + ": missing key '" + key + "'");
  const auto& v = j.at(key);
  if (!v.is_number() || !std::isfinite(v.get<double>())) {
    return Status::Error(where + ": key '" + key + "': expected a finite number");
  }
  return v.get<double>();
}
}  // namespace

StatusOr<Camera> CameraFromJson(const nlohmann::json& j, const std::string& where) {
  Camera c;
  if (!j.is_object()) return Status::Error(where + ": expected a JSON object");
  if (!j.contains("image_size") || !j["image_size"].is_array() || j["image_size"].size() != 2 ||
      !j["image_size"][0].is_number_integer() || !j["image_size"][1].is_number_integer()) {
    return Status::Error(where + ": key 'image_size': expected [width, height] in px");
  }
  c.width = j["image_size"][0].get<int>();
  c.height = j["image_size"][1].get<int>();
  for (int i = 0; i < 4; ++i) {
    auto v = Num(j, kIntrinsicNames[i], where);
    if (!v.ok()) return v.status();
    c.params[i] = *v;
  }
  if (j.contains("distortion")) {
    const auto& d = j["distortion"];
    if (!d.is_array() || d.size() != 5) {
      return Status::Error(where + ": key 'distortion': expected [k1, k2, p1, p2, k3]");
    }
    for (int i = 0; i < 5; ++i) {
      if (!d[i].is_number() || !std::isfinite(d[i].get<double>())) {
        return Status::Error(where + ": key 'distortion': element " + std::to_string(i) +
                             ": expected a finite number");
      }
      c.params[4 + i] = d[i].get<double>();
    }
  }
  if (j.contains("covariance") && j["covariance"].is_object()) {
    const auto& cov = j["covariance"];
    if (cov.contains("names") && cov.contains("matrix")) {
      c.covariance_names = cov["names"].get<std::vector<std::string>>();
      c.covariance = cov["matrix"].get<std::vector<std::vector<double>>>();
    }
  }
  Status s = c.Check();
  if (!s.ok()) return s.WithContext(where);
  return c;
}

StatusOr<Camera> ReadCameraJson(const std::string& path) {
  auto text = ReadFile(path);
  if (!text.ok()) return text.status();
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(*text);
  } catch (const nlohmann::json::parse_error& e) {
    return Status::Error(path + ": invalid JSON at byte " + std::to_string(e.byte) +
                         ", expected a camera object");
  }
  return CameraFromJson(j, path);
}

nlohmann::json CameraToJson(const Camera& c) {
  nlohmann::json j;
  j["image_size"] = {c.width, c.height};
  j["lensmodel"] = "LENSMODEL_OPENCV5";
  for (int i = 0; i < 4; ++i) j[kIntrinsicNames[i]] = c.params[i];
  j["distortion"] = {c.params[4], c.params[5], c.params[6], c.params[7], c.params[8]};
  if (!c.covariance.empty()) {
    j["covariance"] = {{"names", c.covariance_names}, {"matrix", c.covariance}};
  }
  return j;
}

}  // namespace carmba
