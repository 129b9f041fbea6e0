// A calibrated C-arm camera: image size and OPENCV5 intrinsics (camera/camera_model.h), with an
// optional covariance. Read from and written to `camera.json`, the file `carmba calibrate` writes
// and the pose problems read:
//
//   { "image_size": [width, height],           // px
//     "fx": ..., "fy": ..., "cx": ..., "cy": ..., // px, pixel (0,0) = centre of top-left pixel
//     "distortion": [k1, k2, p1, p2, k3],
//     "covariance": { "names": ["fx", ...], "matrix": [[...], ...] },   // optional, px^2 etc.
//     "rms_px": ... }                                                     // optional
#pragma once

#include <array>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "camera/camera_model.h"
#include "util/status.h"

namespace carmba {

struct Camera {
  int width = 0;   // px
  int height = 0;  // px
  std::array<double, kNumIntrinsics> params{};  // fx, fy, cx, cy, k1, k2, p1, p2, k3

  // Covariance of the intrinsics named in `covariance_names` (subset of kIntrinsicNames), if known.
  std::vector<std::string> covariance_names;
  std::vector<std::vector<double>> covariance;

  // Every value within its plausible range (util/plausible.h): image size, fx, fy, cx, cy (in
  // image sizes), distortion; the covariance square, symmetric, over distinct intrinsic names,
  // with plausible sigmas and correlations within [-1, 1]. The message names the key, the range
  // and the value; callers prefix the file.
  Status Check() const;
};

// "fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"
extern const char* const kIntrinsicNames[kNumIntrinsics];
// The index of the intrinsic called `name` in kIntrinsicNames (fx fy cx cy k1 k2 p1 p2 k3), or -1.
int IntrinsicIndexOf(const std::string& name);

// Parses camera.json. Errors name the file and the key.
StatusOr<Camera> ReadCameraJson(const std::string& path);
StatusOr<Camera> CameraFromJson(const nlohmann::json& j, const std::string& where);
nlohmann::json CameraToJson(const Camera& camera);

}  // namespace carmba
