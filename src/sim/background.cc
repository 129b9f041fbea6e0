// LoadBackgroundGain (sim/xray_render.h): reads a real X-ray frame (DICOM through io/dicom_xray.h,
// or any image OpenCV reads) and turns it into a multiplicative background.

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "io/dicom_xray.h"
#include "sim/xray_render.h"
#include "util/file_util.h"
#include "util/image_codecs.h"
#include "util/image_header.h"
#include "util/quiet_stderr.h"

namespace carmba::sim {

StatusOr<cv::Mat> LoadBackgroundGain(const std::string& path,
                                     int width,
                                     int height,
                                     double strength,
                                     double crop_fraction,
                                     cv::Point2d crop_center) {
  if (!(strength >= 0 && strength <= 1)) {
    return Status::Error("background strength must be in [0, 1]");
  }
  if (!(crop_fraction > 0 && crop_fraction <= 1)) {
    return Status::Error("background crop must be in (0, 1]");
  }
  std::string file = path, error;
  int index = 0;  // the first frame unless `file#frameN` names one
  if (SplitDicomFrameName(path, &file, &index, &error) && !error.empty()) {
    return Status::Error(error);
  }
  if (!FileExists(file)) return Status::Error(file + ": no such file");
  cv::Mat frame;
  if (IsDicomFileName(path)) {
    auto dicom = ReadDicomXray(file);
    if (!dicom.ok()) return dicom.status();
    if (index >= static_cast<int>(dicom->frames.size())) {
      return Status::Error(path + ": no such frame, " + file + " has " +
                           std::to_string(dicom->frames.size()) + " frame(s)");
    }
    dicom->frames[index].convertTo(frame, CV_32F);
  } else {
    CARMBA_RETURN_IF_ERROR(CheckImageFileSize(path));
    cv::Mat raw;
    {
      QuietStderr quiet;
      raw = ImRead(path, cv::IMREAD_GRAYSCALE | cv::IMREAD_ANYDEPTH);
    }
    if (raw.empty()) return Status::Error(path + ": not an image OpenCV can read");
    raw.convertTo(frame, CV_32F);
  }
  const int side = static_cast<int>(std::lround(crop_fraction * std::min(frame.cols, frame.rows)));
  if (side < 2) return Status::Error(path + ": image too small for the background crop");
  if (!(crop_center.x >= 0 && crop_center.x <= 1 && crop_center.y >= 0 && crop_center.y <= 1)) {
    return Status::Error("background crop centre must be fractions in [0, 1]");
  }
  const auto corner = [side](double c, int n) {
    if (c == 0.5) return (n - side) / 2;  // the frame's central square, as before the key
    return std::clamp(static_cast<int>(std::lround(c * n - 0.5 * side)), 0, n - side);
  };
  const cv::Rect roi(
      corner(crop_center.x, frame.cols), corner(crop_center.y, frame.rows), side, side);
  cv::Mat crop;
  cv::resize(frame(roi), crop, cv::Size(width, height), 0, 0, cv::INTER_AREA);
  std::vector<float> values(crop.begin<float>(), crop.end<float>());
  const size_t k = static_cast<size_t>(0.99 * (values.size() - 1));
  std::nth_element(values.begin(), values.begin() + k, values.end());
  const double p99 = values[k];
  if (!(p99 > 0)) return Status::Error(path + ": background image is black");
  cv::Mat gain(height, width, CV_32F);
  for (int v = 0; v < height; ++v) {
    const float* in = crop.ptr<float>(v);
    float* out = gain.ptr<float>(v);
    for (int u = 0; u < width; ++u) {
      const double x = std::clamp(in[u] / p99, 0.02, 1.0);
      out[u] = static_cast<float>(1.0 - strength + strength * x);
    }
  }
  return gain;
}

}  // namespace carmba::sim
