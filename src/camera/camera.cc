#include "camera/camera.h"

#include <algorithm>
#include <cmath>
#include <set>

#include "util/accepted_keys.h"
#include "util/file_util.h"
#include "util/plausible.h"

namespace carmba {

const char* const kIntrinsicNames[kNumIntrinsics] = {"fx", "fy", "cx", "cy", "k1",
                                                     "k2", "p1", "p2", "k3"};

int IntrinsicIndexOf(const std::string& name) {
  for (int i = 0; i < kNumIntrinsics; ++i) {
    if (name == kIntrinsicNames[i]) return i;
  }
  return -1;
}

Status Camera::Check() const {
  namespace pl = plausible;
  std::string e;
  if (!CheckRange("key 'image_size': width", width, pl::kImageSizePx, &e) ||
      !CheckRange("key 'image_size': height", height, pl::kImageSizePx, &e) ||
      !CheckRange("key 'fx'", params[kFx], pl::kFocalPx, &e) ||
      !CheckRange("key 'fy'", params[kFy], pl::kFocalPx, &e)) {
    return Status::Error(e);
  }
  // The principal point's range is in image sizes; stated in px for this image.
  const double size[2] = {static_cast<double>(width), static_cast<double>(height)};
  for (int i = 0; i < 2; ++i) {
    const PlausibleRange r{pl::kPrincipalPointImageSizes.lo * size[i],
                           pl::kPrincipalPointImageSizes.hi * size[i], "px"};
    if (!CheckRange(std::string("key '") + kIntrinsicNames[kCx + i] + "'", params[kCx + i], r,
                    &e)) {
      return Status::Error(e + " (" + FormatCompact(pl::kPrincipalPointImageSizes.lo) + " .. " +
                           FormatCompact(pl::kPrincipalPointImageSizes.hi) + " x the image " +
                           (i == 0 ? "width" : "height") + ")");
    }
  }
  for (int i = 4; i < kNumIntrinsics; ++i) {
    if (!CheckRange("key 'distortion': element " + std::to_string(i - 4) + " (" +
                        kIntrinsicNames[i] + ")",
                    params[i], pl::kDistortion, &e)) {
      return Status::Error(e);
    }
  }
  if (covariance_names.empty() && covariance.empty()) return Status::Ok();
  const size_t n = covariance_names.size();
  std::set<std::string> seen;
  for (const auto& name : covariance_names) {
    bool known = false;
    for (const char* k : kIntrinsicNames) known = known || name == k;
    if (!known || !seen.insert(name).second) {
      return Status::Error("key 'covariance.names': expected distinct intrinsic names (fx fy cx "
                           "cy k1 k2 p1 p2 k3), got '" + name + "'");
    }
  }
  if (covariance.size() != n) {
    return Status::Error("key 'covariance.matrix': expected " + std::to_string(n) + " rows (one "
                         "per name), got " + std::to_string(covariance.size()));
  }
  for (size_t r = 0; r < n; ++r) {
    if (covariance[r].size() != n) {
      return Status::Error("key 'covariance.matrix': row " + std::to_string(r) + ": expected " +
                           std::to_string(n) + " numbers, got " +
                           std::to_string(covariance[r].size()));
    }
  }
  double max_var = 0;
  for (size_t r = 0; r < n; ++r) {
    const double var = covariance[r][r];
    if (!CheckRange("key 'covariance.matrix': the sigma of " + covariance_names[r] +
                        " (square root of the diagonal)",
                    var >= 0 ? std::sqrt(var) : var, pl::kIntrinsicSigma, &e)) {
      return Status::Error(e);
    }
    max_var = std::max(max_var, var);
  }
  for (size_t r = 0; r < n; ++r) {
    for (size_t c = 0; c < n; ++c) {
      // |cov_rc| <= sigma_r sigma_c (a correlation within [-1, 1]) and cov_rc = cov_cr, with
      // slack for the rounding of a written file and of a computed covariance.
      const double limit = std::sqrt(covariance[r][r] * covariance[c][c]);
      const double slack = 1e-6 * limit + 1e-12 * max_var;
      if (!std::isfinite(covariance[r][c]) || std::fabs(covariance[r][c]) > limit + slack ||
          std::fabs(covariance[r][c] - covariance[c][r]) > slack) {
        return Status::Error("key 'covariance.matrix': element [" + std::to_string(r) + "][" +
                             std::to_string(c) + "] = " + FormatCompact(covariance[r][c]) +
                             ": expected a symmetric matrix with correlations within [-1, 1]");
      }
    }
  }
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
  // The keys this reader looks at, for util/accepted_keys.h (recorded when the camera is read).
  std::vector<std::string> keys = {"image_size", "distortion", "covariance"};
  if (!j.contains("image_size") || !j["image_size"].is_array() || j["image_size"].size() != 2 ||
      !j["image_size"][0].is_number_integer() || !j["image_size"][1].is_number_integer()) {
    return Status::Error(where + ": key 'image_size': expected [width, height] in px");
  }
  // Beyond int (e.g. 99999999999) the cast would wrap: out-of-range sizes are kept out of it and
  // reported by Check().
  const double size[2] = {j["image_size"][0].get<double>(), j["image_size"][1].get<double>()};
  for (int i = 0; i < 2; ++i) {
    if (!InRange(size[i], plausible::kImageSizePx)) {
      return Status::Error(where + ": key 'image_size': " + (i == 0 ? "width" : "height") +
                           ": expected " + FormatRange(plausible::kImageSizePx) + ", got " +
                           FormatCompact(size[i]));
    }
  }
  c.width = static_cast<int>(size[0]);
  c.height = static_cast<int>(size[1]);
  for (int i = 0; i < 4; ++i) {
    keys.push_back(kIntrinsicNames[i]);
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
  if (j.contains("covariance")) {
    const auto& cov = j["covariance"];
    keys.insert(keys.end(), {"covariance.names", "covariance.matrix"});
    const auto& names = cov.is_object() && cov.contains("names") ? cov["names"] : nlohmann::json();
    const auto& matrix =
        cov.is_object() && cov.contains("matrix") ? cov["matrix"] : nlohmann::json();
    bool ok = names.is_array() && matrix.is_array();
    for (const auto& nm : names) ok = ok && nm.is_string();
    for (const auto& row : matrix) {
      ok = ok && row.is_array();
      for (const auto& x : row) ok = ok && x.is_number();
    }
    if (!ok) {
      return Status::Error(where + ": key 'covariance': expected {\"names\": [\"fx\", ...], "
                           "\"matrix\": [[numbers], ...]}");
    }
    c.covariance_names = names.get<std::vector<std::string>>();
    c.covariance = matrix.get<std::vector<std::vector<double>>>();
  }
  Status s = c.Check();
  if (!s.ok()) return s.WithContext(where);
  for (const auto& k : keys) RecordAcceptedKey(where, k);
  return c;
}

StatusOr<Camera> ReadCameraJson(const std::string& path) {
  auto j = ReadJsonFile(path, "a camera object");
  if (!j.ok()) return j.status();
  return CameraFromJson(*j, path);
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
