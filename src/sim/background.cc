// LoadBackgroundGain (sim/xray_render.h): reads a real X-ray frame (DICOM through GDCM, or any
// image OpenCV reads) and turns it into a multiplicative background.
#include <fcntl.h>
#include <gdcmImage.h>
#include <gdcmImageReader.h>
#include <gdcmPhotometricInterpretation.h>
#include <gdcmPixelFormat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "sim/xray_render.h"
#include "util/file_util.h"
#include "util/quiet_stderr.h"

namespace carmba::sim {

namespace {

StatusOr<cv::Mat> ReadDicomFrame(const std::string& path) {
  QuietStderr quiet;  // GDCM writes its warnings and errors to std::cerr
  gdcm::ImageReader reader;
  reader.SetFileName(path.c_str());
  if (!reader.Read()) return Status::Error(path + ": not a readable DICOM image");
  const gdcm::Image& image = reader.GetImage();
  const unsigned int* dims = image.GetDimensions();
  const int cols = static_cast<int>(dims[0]), rows = static_cast<int>(dims[1]);
  const gdcm::PixelFormat pf = image.GetPixelFormat();
  if (pf.GetSamplesPerPixel() != 1) {
    return Status::Error(path + ": expected a monochrome DICOM image");
  }
  std::vector<char> buffer(image.GetBufferLength());
  if (buffer.empty() || !image.GetBuffer(buffer.data())) {
    return Status::Error(path + ": cannot decode the DICOM pixel data");
  }
  const size_t n = static_cast<size_t>(rows) * cols;  // first frame only
  cv::Mat frame(rows, cols, CV_32F);
  float* out = frame.ptr<float>();
  switch (pf.GetScalarType()) {
    case gdcm::PixelFormat::UINT8:
      if (buffer.size() < n) return Status::Error(path + ": truncated pixel data");
      for (size_t i = 0; i < n; ++i) out[i] = static_cast<unsigned char>(buffer[i]);
      break;
    case gdcm::PixelFormat::UINT16:
    case gdcm::PixelFormat::INT16: {
      if (buffer.size() < 2 * n) return Status::Error(path + ": truncated pixel data");
      const bool is_signed = pf.GetScalarType() == gdcm::PixelFormat::INT16;
      for (size_t i = 0; i < n; ++i) {
        uint16_t raw;
        std::memcpy(&raw, buffer.data() + 2 * i, 2);
        out[i] = is_signed ? static_cast<float>(static_cast<int16_t>(raw)) : raw;
      }
      break;
    }
    default:
      return Status::Error(path + ": unsupported DICOM pixel type (expected 8 or 16 bit)");
  }
  if (image.GetPhotometricInterpretation() == gdcm::PhotometricInterpretation::MONOCHROME1) {
    double lo, hi;
    cv::minMaxLoc(frame, &lo, &hi);
    frame = hi - frame;
  }
  return frame;
}

}  // namespace

StatusOr<cv::Mat> LoadBackgroundGain(
    const std::string& path, int width, int height, double strength, double crop_fraction) {
  if (!(strength >= 0 && strength <= 1)) {
    return Status::Error("background strength must be in [0, 1]");
  }
  if (!(crop_fraction > 0 && crop_fraction <= 1)) {
    return Status::Error("background crop must be in (0, 1]");
  }
  if (!FileExists(path)) return Status::Error(path + ": no such file");
  cv::Mat frame;
  const bool dicom = path.size() > 4 && path.substr(path.size() - 4) == ".dcm";
  if (dicom) {
    auto f = ReadDicomFrame(path);
    if (!f.ok()) return f.status();
    frame = *f;
  } else {
    cv::Mat raw;
    {
      QuietStderr quiet;
      raw = cv::imread(path, cv::IMREAD_GRAYSCALE | cv::IMREAD_ANYDEPTH);
    }
    if (raw.empty()) return Status::Error(path + ": not an image OpenCV can read");
    raw.convertTo(frame, CV_32F);
  }
  const int side = static_cast<int>(std::lround(crop_fraction * std::min(frame.cols, frame.rows)));
  if (side < 2) return Status::Error(path + ": image too small for the background crop");
  const cv::Rect roi((frame.cols - side) / 2, (frame.rows - side) / 2, side, side);
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
