// The module util/image_codecs.cc loads on first use: OpenCV's codecs behind one C symbol, so
// that only processes that read or write an image load libopencv_imgcodecs and the ~140
// libraries it brings.
#include "codecs/image_codecs_module.h"

#include <opencv2/imgcodecs.hpp>

namespace {

cv::Mat Read(const std::string& path, int flags) { return cv::imread(path, flags); }

bool Write(const std::string& path, const cv::Mat& image) { return cv::imwrite(path, image); }

bool Encode(const std::string& ext, const cv::Mat& image, std::vector<uint8_t>* bytes) {
  return cv::imencode(ext, image, *bytes);
}

constexpr carmba::ImageCodecTable kTable{&Read, &Write, &Encode};

}  // namespace

extern "C" __attribute__((visibility("default"))) const carmba::ImageCodecTable*
carmba_image_codecs() {
  return &kTable;
}
