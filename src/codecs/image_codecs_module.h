// The interface between util/image_codecs.cc and the module it loads (image_codecs_module.cc):
// one C symbol that returns OpenCV's codec functions. Both sides are built from this header in
// one build, against one OpenCV, so the table's C++ signatures cannot drift apart.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace carmba {

struct ImageCodecTable {
  cv::Mat (*read)(const std::string& path, int flags);
  bool (*write)(const std::string& path, const cv::Mat& image);
  bool (*encode)(const std::string& ext, const cv::Mat& image, std::vector<uint8_t>* bytes);
};

}  // namespace carmba

// The module's one exported symbol.
#define CARMBA_IMAGE_CODECS_SYMBOL "carmba_image_codecs"
extern "C" const carmba::ImageCodecTable* carmba_image_codecs();
