#include "util/file_util.h"

#include <glob.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <cctype>
#include <set>
#include <fstream>
#include <sstream>

#include "util/dicom_structure.h"

namespace carmba {

Status WriteFileAtomic(const std::string& path, const std::string& contents) {
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) {
      return Status::Error(path + ": cannot open for writing (" + std::strerror(errno) + ")");
    }
    out.write(contents.data(), static_cast<std::streamsize>(contents.size()));
    out.flush();
    if (!out) {
      out.close();
      std::remove(tmp.c_str());
      return Status::Error(path + ": write failed");
    }
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    return Status::Error(path + ": cannot rename temporary file (" + std::strerror(errno) + ")");
  }
  return Status::Ok();
}

StatusOr<std::string> ReadFile(const std::string& path) {
  if (IsDirectory(path)) return Status::Error(path + ": is a directory, expected a file");
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Error(path + ": cannot open (" + std::strerror(errno) + ")");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

Status MakeDirs(const std::string& path) {
  std::error_code ec;
  std::filesystem::create_directories(path, ec);
  if (ec) return Status::Error(path + ": cannot create directory (" + ec.message() + ")");
  return Status::Ok();
}

bool FileExists(const std::string& path) {
  struct stat st;
  return ::stat(path.c_str(), &st) == 0;
}

bool IsDirectory(const std::string& path) {
  struct stat st;
  return ::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode);
}

std::string JoinPath(const std::string& a, const std::string& b) {
  if (a.empty() || (!b.empty() && b[0] == '/')) return b;
  if (a.back() == '/') return a + b;
  return a + "/" + b;
}

std::string DirName(const std::string& path) {
  const auto pos = path.find_last_of('/');
  if (pos == std::string::npos) return ".";
  if (pos == 0) return "/";
  return path.substr(0, pos);
}

StatusOr<std::vector<std::string>> ListFiles(const std::string& dir_or_glob) {
  std::vector<std::string> files;
  if (IsDirectory(dir_or_glob)) {
    std::error_code ec;
    for (const auto& e : std::filesystem::directory_iterator(dir_or_glob, ec)) {
      if (e.is_regular_file()) files.push_back(e.path().string());
    }
    if (ec) return Status::Error(dir_or_glob + ": cannot list directory (" + ec.message() + ")");
    if (files.empty()) return Status::Error(dir_or_glob + ": directory contains no files");
  } else {
    glob_t g;
    const int rc = ::glob(dir_or_glob.c_str(), 0, nullptr, &g);
    if (rc == 0) {
      for (size_t i = 0; i < g.gl_pathc; ++i) files.emplace_back(g.gl_pathv[i]);
    }
    globfree(&g);
    if (files.empty()) {
      return Status::Error(dir_or_glob + ": no such file, directory or matching pattern");
    }
  }
  std::sort(files.begin(), files.end());
  return files;
}

StatusOr<std::vector<std::string>> ListImageFiles(const std::string& dir_or_glob) {
  const size_t frame = dir_or_glob.rfind("#frame");
  if (frame != std::string::npos && !FileExists(dir_or_glob) &&
      FileExists(dir_or_glob.substr(0, frame))) {
    return std::vector<std::string>{dir_or_glob};  // one frame of a multi-frame DICOM file
  }
  auto files = ListFiles(dir_or_glob);
  if (!files.ok() || !IsDirectory(dir_or_glob)) return files;
  static const std::set<std::string> kImageExtensions = {
      ".png", ".pgm", ".ppm", ".pnm", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp", ".dcm", ".dicom"};
  std::vector<std::string> images;
  for (const auto& f : *files) {
    std::string ext = std::filesystem::path(f).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    std::string name = std::filesystem::path(f).filename().string();
    std::transform(name.begin(), name.end(), name.begin(),
                   [](unsigned char c) { return static_cast<char>(std::toupper(c)); });
    if (name == "DICOMDIR") continue;  // a DICOM media directory (no pixels), as on CDs
    // Other DICOM files are found by their preamble: .IMA, UID-like names, no extension.
    if (kImageExtensions.count(ext) || HasDicmMarker(f)) images.push_back(f);
  }
  if (images.empty()) {
    return Status::Error(dir_or_glob + ": directory contains no image files (png, pgm, ppm, tif, "
                                       "jpg, bmp, dcm, or DICOM files with the DICM preamble)");
  }
  return images;
}

}  // namespace carmba
