#include "io/image_files.h"

#include <filesystem>
#include <set>

#include "util/file_util.h"
#include "util/image_codecs.h"
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
    m = ImRead(path, cv::IMREAD_UNCHANGED);
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

namespace {

// `name` without its `#frameN` (returned in `frame`) and split into path components.
std::vector<std::string> ViewPathParts(const std::string& name, std::string* frame) {
  const FrameName split = SplitFrameSuffix(name);
  const std::string& file = split.file;
  *frame = split.suffix;
  std::vector<std::string> parts;
  for (const auto& part : std::filesystem::path(file).lexically_normal()) {
    if (!part.empty() && part != "/") parts.push_back(part.string());
  }
  if (!parts.empty()) parts.back() = std::filesystem::path(parts.back()).stem().string();
  return parts;
}

}  // namespace

std::vector<std::string> ShortViewIds(const std::vector<std::string>& names) {
  std::vector<std::vector<std::string>> parts(names.size());
  std::vector<std::string> frames(names.size()), ids(names.size());
  for (size_t i = 0; i < names.size(); ++i) {
    parts[i] = ViewPathParts(names[i], &frames[i]);
    ids[i] = (parts[i].empty() ? names[i] : parts[i].back()) + frames[i];
  }
  if (std::set<std::string>(ids.begin(), ids.end()).size() == ids.size()) return ids;
  // The directories every name shares, then the rest of each path.
  size_t common = parts.empty() || parts[0].empty() ? 0 : parts[0].size() - 1;
  for (const auto& p : parts) {
    size_t k = 0;
    while (k < common && k + 1 < p.size() && p[k] == parts[0][k]) ++k;
    common = k;
  }
  for (size_t i = 0; i < names.size(); ++i) {
    std::string id;
    for (size_t k = common; k < parts[i].size(); ++k) id += (id.empty() ? "" : "/") + parts[i][k];
    ids[i] = (id.empty() ? names[i] : id) + frames[i];
  }
  // Names that differ only in their extension keep their whole names.
  if (std::set<std::string>(ids.begin(), ids.end()).size() != ids.size()) return names;
  return ids;
}

}  // namespace carmba
