#include "sim/ct_anatomy.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <mutex>
#include <vector>

#include "camera/camera_model.h"
#include "ct/ct_invesalius.h"
#include "util/file_util.h"

namespace carmba::sim {

namespace {

// The .inv3 volumes read in this process, by path, with the file's size and time when read.
struct CachedVolume {
  std::uintmax_t size = 0;
  std::filesystem::file_time_type time;
  std::shared_ptr<const CtVolume> volume;
};

StatusOr<std::shared_ptr<const CtVolume>> ReadInvesaliusCached(const std::string& path) {
  static std::mutex mutex;
  static std::map<std::string, CachedVolume> cache;
  std::error_code ec;
  const std::uintmax_t size = std::filesystem::file_size(path, ec);
  const auto time =
      ec ? std::filesystem::file_time_type() : std::filesystem::last_write_time(path, ec);
  if (!ec) {
    std::lock_guard<std::mutex> lock(mutex);
    const auto it = cache.find(path);
    if (it != cache.end() && it->second.size == size && it->second.time == time) {
      return it->second.volume;
    }
  }
  auto volume = ReadInvesaliusVolume(path);
  if (!volume.ok()) return volume.status();
  auto shared = std::make_shared<const CtVolume>(std::move(*volume));
  if (!ec) {
    std::lock_guard<std::mutex> lock(mutex);
    cache[path] = {size, time, shared};
  }
  return shared;
}

}  // namespace

StatusOr<std::shared_ptr<const CtVolume>> ReadAnatomyCt(const std::string& path) {
  if (std::filesystem::path(path).extension() == ".inv3") return ReadInvesaliusCached(path);
  if (!IsDirectory(path)) {
    return Status::Error(path +
                         ": expected an InVesalius project (.inv3) or a directory holding "
                         "one DICOM CT series");
  }
  auto series = ReadCtSeries(path);
  if (!series.ok()) return series.status();
  return std::make_shared<const CtVolume>(std::move(*series));
}

Eigen::Vector3d CtVolumeCentre(const CtVolume& volume) {
  return volume.PatientFromIndex(
      0.5 * Eigen::Vector3d(volume.columns - 1, volume.rows - 1, volume.slices - 1));
}

namespace {

// sum mu * step along the ray through normalised image point `xy`.
double LineIntegral(const CtAnatomy& a,
                    const Eigen::Matrix3d& index_from_cam,
                    const Eigen::Vector3d& index_of_source,
                    const Eigen::Vector2d& xy,
                    double step) {
  const CtVolume& vol = *a.volume;
  const Eigen::Vector3d dir = Eigen::Vector3d(xy.x(), xy.y(), 1.0).normalized();
  const Eigen::Vector3d along = index_from_cam * dir;
  // Inside the box of voxel centres, [0, n - 1] along each index (t in mm: `dir` is a unit vector).
  const Eigen::Vector3d hi(vol.columns - 1, vol.rows - 1, vol.slices - 1);
  double t0, t1;
  if (!RayBoxInterval(index_of_source, along, Eigen::Vector3d::Zero(), hi, &t0, &t1)) return 0;
  double sum = 0;
  for (double t = t0 + 0.5 * step; t < t1; t += step) {
    const double hu = TrilinearHu(vol, index_of_source + t * along);
    sum += std::max(0.0, 1.0 + hu / 1000.0);
  }
  return a.mu_water_per_mm * sum * step;
}

}  // namespace

cv::Mat CtAnatomyGain(const CtAnatomy& a,
                      const Camera& camera,
                      const Rigid3& cam_from_object,
                      const FovCircle* fov) {
  const CtVolume& vol = *a.volume;
  const Rigid3 ct_from_cam = (cam_from_object * a.object_from_ct).Inverse();
  const Eigen::Matrix3d index_from_patient = vol.PatientFromIndexLinear().inverse();
  const Eigen::Matrix3d index_from_cam = index_from_patient * ct_from_cam.R;
  const Eigen::Vector3d index_of_source = index_from_patient * (ct_from_cam.t - vol.origin_mm);
  const double step = a.step_fraction * vol.spacing_mm.minCoeff();
  const int s = a.subsample, W = camera.width, H = camera.height;
  const int nu = (W - 1 + s - 1) / s + 1, nv = (H - 1 + s - 1) / s + 1;
  // The line integrals on the coarse grid (pixel (s i, s j), the last row and column at or just
  // past the image's), then bilinear per pixel.
  std::vector<double> grid(static_cast<size_t>(nu) * nv, 0.0);
  for (int j = 0; j < nv; ++j) {
    for (int i = 0; i < nu; ++i) {
      const double uv[2] = {static_cast<double>(s * i), static_cast<double>(s * j)};
      if (fov && std::hypot(uv[0] - fov->u, uv[1] - fov->v) > fov->r + 2 * s) continue;
      double xy[2];
      if (!UnprojectToNormalized(camera.params.data(), uv, xy)) continue;
      grid[static_cast<size_t>(j) * nu + i] =
          LineIntegral(a, index_from_cam, index_of_source, Eigen::Vector2d(xy[0], xy[1]), step);
    }
  }
  cv::Mat gain(H, W, CV_32F);
  for (int v = 0; v < H; ++v) {
    const int j = v / s;
    const double fj = (v - s * j) / static_cast<double>(s);
    for (int u = 0; u < W; ++u) {
      const int i = u / s;
      const double fi = (u - s * i) / static_cast<double>(s);
      auto g = [&](int di, int dj) {
        return grid[static_cast<size_t>(std::min(j + dj, nv - 1)) * nu + std::min(i + di, nu - 1)];
      };
      const double integral =
          (1 - fj) * ((1 - fi) * g(0, 0) + fi * g(1, 0)) + fj * ((1 - fi) * g(0, 1) + fi * g(1, 1));
      gain.at<float>(v, u) = static_cast<float>(std::exp(-integral));
    }
  }
  return gain;
}

}  // namespace carmba::sim
