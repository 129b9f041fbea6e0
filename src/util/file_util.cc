#include "util/file_util.h"

#include <glob.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <cctype>
#include <set>
#include <system_error>
#include <vector>
#include <fstream>
#include <sstream>

#include "util/dicom_structure.h"
#include "util/temp_paths.h"

namespace carmba {

Status WriteFileAtomic(const std::string& path, const std::string& contents) {
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  const TempPathRegistration registration(tmp);  // removed on SIGINT / SIGTERM
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

namespace {

std::string StripTrailingSlashes(std::string p) {
  while (p.size() > 1 && p.back() == '/') p.pop_back();
  return p;
}

// `target` (named `what`) is to be created in the existing directory `d`: it must accept new
// entries.
Status CheckCanCreateIn(const std::string& d, const std::string& target, const std::string& what) {
  struct statvfs vfs;
  if (::statvfs(d.c_str(), &vfs) == 0 && (vfs.f_flag & ST_RDONLY)) {
    return Status::Error(what + " " + target + ": " + d +
                         " is on a read-only file system, expected a writable directory");
  }
  const std::string probe = JoinPath(d, ".carmba-probe." + std::to_string(::getpid()));
  if (::mkdir(probe.c_str(), 0700) != 0) {
    const int e = errno;
    if (e != EEXIST) {
      // ENOENT for an existing directory: a virtual file system (/proc) that has no such entries.
      const std::string reason =
          e == ENOENT ? "the file system accepts no new entries" : std::strerror(e);
      return Status::Error(what + " " + target + ": cannot create files in " + d + " (" + reason +
                           "), expected a writable directory");
    }
  } else {
    ::rmdir(probe.c_str());
  }
  return Status::Ok();
}

// The nearest existing ancestor of `p` (not `p` itself); "." or "/" at the top.
std::string NearestExistingAncestor(const std::string& p) {
  std::string a = DirName(p);
  while (!FileExists(a) && a != "." && a != "/") a = DirName(a);
  return a;
}

}  // namespace

Status CheckOutputDir(const std::string& dir_in,
                      const std::string& what,
                      bool force,
                      const std::string& how_to_override) {
  if (dir_in.empty()) return Status::Error(what + ": expected a directory path, got nothing");
  const std::string dir = StripTrailingSlashes(dir_in);
  if (FileExists(dir)) {
    if (!IsDirectory(dir)) {
      return Status::Error(what + " " + dir + ": exists and is not a directory, expected a "
                                              "directory");
    }
    CARMBA_RETURN_IF_ERROR(CheckCanCreateIn(dir, dir, what));
    if (force) return Status::Ok();
    std::vector<std::string> names;
    std::error_code ec;
    for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {
      names.push_back(e.path().filename().string());
    }
    if (names.empty()) return Status::Ok();
    std::sort(names.begin(), names.end());
    std::string list;
    for (size_t i = 0; i < std::min<size_t>(3, names.size()); ++i) {
      list += (i ? ", " : "") + names[i];
    }
    if (names.size() > 3) list += ", ... " + std::to_string(names.size()) + " entries";
    return Status::Error(what + " " + dir + ": holds a previous result (" + list +
                         "); " + how_to_override +
                         ", or choose a new directory");
  }
  const std::string a = NearestExistingAncestor(dir);
  if (!IsDirectory(a)) {
    return Status::Error(what + " " + dir + ": " + a + " is a file, expected a directory");
  }
  return CheckCanCreateIn(a, dir, what);
}

Status CheckOutputFile(const std::string& path, const std::string& what, bool force) {
  if (path.empty() || path.back() == '/') {
    return Status::Error(what + " " + path + ": expected a file name");
  }
  struct stat st;
  if (::stat(path.c_str(), &st) == 0) {
    if (S_ISDIR(st.st_mode)) {
      return Status::Error(what + " " + path + ": is a directory, expected a file name");
    }
    if (!S_ISREG(st.st_mode)) {
      return Status::Error(what + " " + path + ": exists and is not a regular file, expected a "
                                               "file name");
    }
    if (!force) {
      return Status::Error(what + " " + path +
                           ": exists (a previous result); pass --force to replace it");
    }
  }
  const std::string d = DirName(path);
  if (!FileExists(d)) {
    const std::string a = NearestExistingAncestor(d);
    if (!IsDirectory(a)) {
      return Status::Error(what + " " + path + ": " + a + " is a file, expected a directory");
    }
    return CheckCanCreateIn(a, path, what);  // the missing directories are created on writing
  }
  if (!IsDirectory(d)) {
    return Status::Error(what + " " + path + ": " + d + " is a file, expected a directory");
  }
  return CheckCanCreateIn(d, path, what);
}

Status MakeParentDirs(const std::string& path) {
  const std::string d = DirName(path);
  return FileExists(d) ? Status::Ok() : MakeDirs(d);
}

namespace {

// The file or directory an input names: a glob's directory before its first wildcard, a DICOM
// frame's file.
std::string InputRoot(const std::string& input) {
  std::string p = SplitFrameSuffix(input).file;
  const size_t wild = p.find_first_of("*?[");
  if (wild != std::string::npos) {
    const size_t slash = p.rfind('/', wild);
    p = slash == std::string::npos ? "." : p.substr(0, slash + (slash == 0 ? 1 : 0));
  }
  return p;
}

std::filesystem::path Resolved(const std::string& p) {
  std::error_code ec;
  auto abs = std::filesystem::absolute(p, ec);
  if (ec) return std::filesystem::path(p).lexically_normal();
  auto c = std::filesystem::weakly_canonical(abs, ec);
  return (ec ? abs : c).lexically_normal();
}

// True when `inner` is `outer` or lies below it (both resolved).
bool IsWithin(const std::filesystem::path& inner, const std::filesystem::path& outer) {
  auto i = inner.begin();
  for (auto o = outer.begin(); o != outer.end(); ++o, ++i) {
    if (o->empty()) continue;  // a trailing separator
    if (i == inner.end() || *i != *o) return false;
  }
  return true;
}

}  // namespace

Status CheckOutputIsNotInput(const std::string& out,
                             const std::string& out_what,
                             const std::string& input,
                             const std::string& input_what) {
  if (out.empty() || input.empty()) return Status::Ok();
  const std::string root = InputRoot(input);
  if (!FileExists(root)) return Status::Ok();
  const auto o = Resolved(StripTrailingSlashes(out)), i = Resolved(StripTrailingSlashes(root));
  if (!IsWithin(i, o)) return Status::Ok();
  // A glob's directory holds the inputs rather than being one.
  const bool same = o == i && input.find_first_of("*?[") == std::string::npos;
  const std::string how = same ? ": is the input " : ": contains the input ";
  return Status::Error(out_what + " " + out + how + input_what + " " + input +
                       " (an output never replaces an input, with --force or not)");
}

StagedOutputDir::StagedOutputDir(std::string dir) : dir_(StripTrailingSlashes(std::move(dir))) {}

StagedOutputDir::~StagedOutputDir() {
  if (!done_ && !staging_.empty()) {
    std::error_code ec;
    std::filesystem::remove_all(staging_, ec);
    for (const auto& d : created_parents_) ::rmdir(d.c_str());  // only if empty
  }
  UnregisterTempPath(slot_);
}

Status StagedOutputDir::Begin() {
  const std::string suffix = std::to_string(::getpid());
  if (FileExists(dir_)) {
    if (!IsDirectory(dir_)) return Status::Error(dir_ + ": exists and is not a directory");
    inside_ = true;
    staging_ = JoinPath(dir_, ".carmba-tmp." + suffix);
  } else {
    staging_ = dir_ + ".tmp." + suffix;
    for (std::string a = DirName(dir_); !FileExists(a) && a != "." && a != "/"; a = DirName(a)) {
      created_parents_.push_back(a);
    }
  }
  std::error_code ec;
  std::filesystem::remove_all(staging_, ec);
  UnregisterTempPath(slot_);
  slot_ = RegisterTempPath(staging_);
  return MakeDirs(staging_);
}

Status StagedOutputDir::Commit(bool replace_all) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!inside_) {
    fs::rename(staging_, dir_, ec);
    if (ec)
      return Status::Error(dir_ + ": cannot move the results into place (" + ec.message() + ")");
    UnregisterTempPath(slot_);
    slot_ = -1;
    done_ = true;
    return Status::Ok();
  }
  // Everything below stays inside dir_: one file system.
  const fs::path staging(staging_);
  const fs::path old = fs::path(dir_) / (".carmba-old." + std::to_string(::getpid()));
  std::vector<fs::path> moved_aside;
  auto restore = [&]() {
    std::error_code e2;
    for (const auto& p : moved_aside) fs::rename(old / p.filename(), p, e2);
    fs::remove_all(old, e2);
  };
  if (replace_all) {
    fs::create_directory(old, ec);
    if (ec)
      return Status::Error(dir_ + ": cannot move the old contents aside (" + ec.message() + ")");
    std::vector<fs::path> before;
    for (const auto& e : fs::directory_iterator(dir_, ec)) {
      if (e.path() != staging && e.path() != old) before.push_back(e.path());
    }
    for (const auto& p : before) {
      fs::rename(p, old / p.filename(), ec);
      if (ec) {
        restore();  // the entries moved so far go back
        return Status::Error(dir_ + ": cannot move the old contents aside (" + ec.message() + ")");
      }
      moved_aside.push_back(p);
    }
  }
  std::vector<fs::path> entries;
  for (const auto& e : fs::directory_iterator(staging, ec)) entries.push_back(e.path());
  // A file cannot replace a directory: found before anything is moved.
  for (const auto& p : entries) {
    const fs::path target = fs::path(dir_) / p.filename();
    if (!fs::is_directory(p) && fs::is_directory(target)) {
      restore();
      return Status::Error(target.string() + ": is a directory, expected a file (or nothing)");
    }
  }
  for (const auto& p : entries) {
    const fs::path target = fs::path(dir_) / p.filename();
    // A directory replaces a directory of the same name (calibrate's mrcal/).
    if (fs::is_directory(p) && fs::is_directory(target) && !fs::is_symlink(target)) {
      fs::remove_all(target, ec);
    }
    fs::rename(p, target, ec);
    if (ec) {
      restore();
      return Status::Error(dir_ + ": cannot move " + p.filename().string() + " into place (" +
                           ec.message() + ")");
    }
  }
  fs::remove_all(staging, ec);
  fs::remove_all(old, ec);
  UnregisterTempPath(slot_);
  slot_ = -1;
  done_ = true;
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

std::string BaseName(const std::string& path) {
  const auto pos = path.find_last_of('/');
  return pos == std::string::npos ? path : path.substr(pos + 1);
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

FrameName SplitFrameSuffix(const std::string& name) {
  const size_t hash = name.rfind("#frame");
  if (hash == std::string::npos) return {name, ""};
  return {name.substr(0, hash), name.substr(hash)};
}

StatusOr<std::vector<std::string>> ListImageFiles(const std::string& dir_or_glob) {
  const FrameName frame = SplitFrameSuffix(dir_or_glob);
  if (!frame.suffix.empty() && !FileExists(dir_or_glob) && FileExists(frame.file)) {
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

StatusOr<nlohmann::json> ReadJsonFile(const std::string& path, const std::string& expected) {
  auto text = ReadFile(path);
  if (!text.ok()) return text.status();
  try {
    return nlohmann::json::parse(*text);
  } catch (const nlohmann::json::parse_error& e) {
    return Status::Error(path + ": invalid JSON at byte " + std::to_string(e.byte) +
                         ", expected " + expected);
  } catch (const nlohmann::json::exception& e) {
    // Not a syntax error: e.g. out_of_range for a number beyond a double (1e999).
    return Status::Error(path + ": invalid JSON (" + e.what() + "), expected " + expected);
  }
}

}  // namespace carmba
