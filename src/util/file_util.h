// File helpers that never leave partial output behind.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "util/status.h"

namespace carmba {

// Writes `contents` to `path` atomically: to `path.tmp.<pid>` first, then rename(2). A crash or an
// error leaves either the old file or no file, never half a file.
Status WriteFileAtomic(const std::string& path, const std::string& contents);

// Output paths, checked before any work so that a bad --out fails at once with a clear reason
// (not after minutes of solving, with a rename's errno). Every command follows the same contract:
// missing parent directories are fine (they are created when the result is written, and removed
// again if it is not); an existing result is refused unless `force`. `what` names the flag, e.g.
// "--out".
// CheckOutputDir: `dir` is an existing directory, or the nearest existing ancestor is a
// directory (none of the ancestors is a file), and that directory is not on a read-only file
// system and accepts new entries (probed by creating and removing a directory
// `.carmba-probe.<pid>` in it: /proc and /sys refuse with ENOENT / EPERM although access(2) says
// they are writable). Unless `force`, an existing `dir` must be empty (a non-empty one holds a
// previous result: "--out DIR: holds a previous result (report.md, ...); pass --force to write
// over it").
// `how_to_override` replaces "pass --force to write over it" in that message.
Status CheckOutputDir(const std::string& dir,
                      const std::string& what,
                      bool force,
                      const std::string& how_to_override = "pass --force to write over it");
// CheckOutputFile: `path` names a file: not an existing directory or other non-regular file
// (renaming onto /dev/null would replace the device); the nearest existing ancestor of its
// directory passes the checks above. Unless `force`, `path` must not exist.
Status CheckOutputFile(const std::string& path, const std::string& what, bool force);

// An output never replaces an input: error when the output `out` (named `out_what`, e.g. "--out")
// is the input `input` (named `input_what`, e.g. "--images") or contains it, with --force or not:
//   --out data/views: is the input --images data/views (an output never replaces an input, with
//   --force or not)
// Paths are compared after resolving symbolic links, `.` and `..` (std::filesystem::
// weakly_canonical; parts that do not exist yet compare as written). `input` may be a glob (the
// directory before its first wildcard is the input), `file.dcm#frameN`, or not exist (Ok).
Status CheckOutputIsNotInput(const std::string& out,
                             const std::string& out_what,
                             const std::string& input,
                             const std::string& input_what);

// Creates the missing directories of `path`'s directory (for an output file checked with
// CheckOutputFile); the error names the directory.
Status MakeParentDirs(const std::string& path);

// An output directory written through a staging directory, so that an error leaves no partial
// output and the final renames stay within one file system (rename(2) across mounts fails with
// EXDEV, e.g. when `dir` is a mount point):
//   - `dir` does not exist: the results are written into `dir.tmp.<pid>` beside it (same parent
//     directory, hence the same mount) and Commit renames that to `dir`;
//   - `dir` exists: they are written into `dir/.carmba-tmp.<pid>` inside it and Commit moves each
//     entry into `dir` (replacing an entry of the same name; a file never replaces a directory:
//     that is an error before anything moves); with `replace_all` the entries that were in `dir`
//     before are moved aside first and deleted after, or moved back on error. A rename failing
//     half-way through (not expected within one directory) can leave some entries moved.
// Without Commit the destructor removes the staging directory, and the parents of `dir` that
// Begin created (when they are empty). The staging directory is registered in util/temp_paths.h
// (removed on SIGINT / SIGTERM), as is WriteFileAtomic's temporary file.
class StagedOutputDir {
 public:
  explicit StagedOutputDir(std::string dir);
  ~StagedOutputDir();
  StagedOutputDir(const StagedOutputDir&) = delete;
  StagedOutputDir& operator=(const StagedOutputDir&) = delete;
  // Creates the staging directory (parents of `dir` as needed).
  Status Begin();
  // Where to write the results.
  const std::string& path() const { return staging_; }
  Status Commit(bool replace_all);

 private:
  std::string dir_;
  std::string staging_;
  std::vector<std::string> created_parents_;  // by Begin, deepest first
  bool inside_ = false;
  bool done_ = false;
  int slot_ = -1;  // util/temp_paths.h: removed on SIGINT / SIGTERM
};

// Reads a whole file. Error names the path.
StatusOr<std::string> ReadFile(const std::string& path);

// Reads and parses a JSON file. Errors: the file's (ReadFile), "<path>: invalid JSON at byte N,
// expected <expected>", or for a value JSON cannot hold (1e999) "<path>: invalid JSON (...)".
StatusOr<nlohmann::json> ReadJsonFile(const std::string& path, const std::string& expected);

// Creates a directory and its parents (like mkdir -p).
Status MakeDirs(const std::string& path);

bool FileExists(const std::string& path);
bool IsDirectory(const std::string& path);

// Joins path components with '/'; an absolute `b` replaces `a`.
std::string JoinPath(const std::string& a, const std::string& b);
// Directory part of a path ("." when there is none).
std::string DirName(const std::string& path);
// The last component of `path` (everything after the last '/'; the path itself without one).
std::string BaseName(const std::string& path);

// Expands a directory (all regular files, sorted by name) or a glob pattern (sorted matches).
// Error when nothing matches.
StatusOr<std::vector<std::string>> ListFiles(const std::string& dir_or_glob);
// ListFiles for images: from a directory only the files with an image extension (png, pgm, ppm,
// pnm, tif, tiff, jpg, jpeg, bmp, dcm, dicom; any case) and the other files that have the DICOM
// preamble ("DICM" at byte 128: Siemens .IMA, UID-like names, no extension), but not a DICOMDIR,
// so that e.g. the simulator's truth.json beside its images is not taken for one; a glob is taken
// as given. `file.dcm#frameN` (one frame of a
// multi-frame DICOM file, io/image_files.h ReadImageViews) is taken as given when the file
// exists. Error if no image is left.
StatusOr<std::vector<std::string>> ListImageFiles(const std::string& dir_or_glob);

// A view name `file#frameN` (one frame of a multi-frame DICOM file) split into the file and the
// suffix "#frameN" (empty when there is none): the one place the suffix is recognised
// (io/dicom_xray.h SplitDicomFrameName also checks N).
struct FrameName {
  std::string file;
  std::string suffix;
};
FrameName SplitFrameSuffix(const std::string& name);

}  // namespace carmba
