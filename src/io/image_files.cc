#include "io/image_files.h"

#include <opencv2/imgcodecs.hpp>

#include "util/image_header.h"
#include "util/quiet_stderr.h"

namespace carmba {

StatusOr<cv::Mat> ReadImageFile(const std::string& path) {
  if (IsDicomFileName(path)) {
    auto views = ReadImageViews(path);
    if (!views.ok()) return views.status();
    if (views->size() != 1) {
      return Status::Error(path + ": " + std::to_string(views->size()) +
                           " frames, name one as " + path + "#frameN (N = 1.." +
                           std::to_string(views->size()) + ")");
    }
    return views->front().image;
  }
  CARMBA_RETURN_IF_ERROR(CheckImageFileSize(path));
  cv::Mat m;
  try {
    // libpng / libtiff print their own diagnostics on a corrupt file; the Status below is the
    // one-line message.
    QuietStderr quiet;
    m = cv::imread(path, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    return Status::Error(path + ": unreadable image (" + e.what() + ")");
  }
  if (m.empty()) return Status::Error(path + ": unreadable image (not an image OpenCV can decode)");
  if (m.depth() != CV_8U && m.depth() != CV_16U && m.depth() != CV_32F) {
    return Status::Error(path + ": unsupported pixel depth (expected 8 or 16 bit)");
  }
  return m;
}

StatusOr<std::vector<NamedImage>> ReadImageViews(const std::string& path) {
  std::vector<NamedImage> views;
  if (!IsDicomFileName(path)) {
    auto img = ReadImageFile(path);
    if (!img.ok()) return img.status();
    views.push_back({path, *img, std::nullopt});
    return views;
  }
  std::string file = path, err;
  int frame = -1;
  if (SplitDicomFrameName(path, &file, &frame, &err) && !err.empty()) return Status::Error(err);
  auto dicom = ReadDicomXray(file);
  if (!dicom.ok()) return dicom.status();
  CARMBA_RETURN_IF_ERROR(CheckProjectionImage(*dicom));
  const int n = static_cast<int>(dicom->frames.size());
  if (frame >= n) {
    return Status::Error(path + ": no such frame, " + file + " has " + std::to_string(n) +
                         (n == 1 ? " frame" : " frames"));
  }
  for (int k = 0; k < n; ++k) {
    if (frame >= 0 && k != frame) continue;
    views.push_back(
        {frame >= 0 ? path : DicomFrameName(file, k, n), dicom->frames[k], dicom->geometry[k]});
  }
  return views;
}

}  // namespace carmba
