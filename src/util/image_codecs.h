// Image files read and written through OpenCV's codecs (cv::imread, cv::imwrite, cv::imencode),
// which carmba loads only when a process first reads or writes an image.
//
// libopencv_imgcodecs brings GDAL and about 140 shared libraries in all (90 that carmba needs for
// nothing else: `carmba` loaded 167 libraries with it, 77 without). Linked into an
// executable, the dynamic loader maps and relocates all of them before main(): about 75 ms of
// every `carmba` call and every test process, whether it touches an image or not
// (src/docs/speed.md, "Process start"). The codecs therefore live in a module of their own
// (src/codecs/, built beside the libraries), which these functions dlopen on first use. Nothing
// else in carmba calls cv::imread / cv::imwrite / cv::imencode (the executables do not link
// libopencv_imgcodecs, so a direct call would not link).
//
// The functions behave as their OpenCV namesakes, cv::Exception included. When the module cannot
// be loaded (a build tree moved after it was built, say), they print one line naming the module
// and dlerror() to stderr once, and then fail as a file that cannot be decoded or written does.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>  // the IMREAD_* flags (declarations only, nothing linked)
#include <string>
#include <vector>

namespace carmba {

// cv::imread(path, flags): an empty matrix when the file cannot be decoded.
cv::Mat ImRead(const std::string& path, int flags);

// cv::imwrite(path, image): false when the file cannot be written.
bool ImWrite(const std::string& path, const cv::Mat& image);

// cv::imencode(ext, image, *bytes): the file an ImWrite to a name ending in `ext` would write.
bool ImEncode(const std::string& ext, const cv::Mat& image, std::vector<uint8_t>* bytes);

}  // namespace carmba
