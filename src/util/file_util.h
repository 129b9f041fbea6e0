// File helpers that never leave partial output behind.
#pragma once

#include <string>
#include <vector>

#include "util/status.h"

namespace carmba {

// Writes `contents` to `path` atomically: to `path.tmp.<pid>` first, then rename(2). A crash or an
// error leaves either the old file or no file, never half a file.
Status WriteFileAtomic(const std::string& path, const std::string& contents);

// Reads a whole file. Error names the path.
StatusOr<std::string> ReadFile(const std::string& path);

// Creates a directory and its parents (like mkdir -p).
Status MakeDirs(const std::string& path);

bool FileExists(const std::string& path);
bool IsDirectory(const std::string& path);

// Joins path components with '/'; an absolute `b` replaces `a`.
std::string JoinPath(const std::string& a, const std::string& b);
// Directory part of a path ("." when there is none).
std::string DirName(const std::string& path);

// Expands a directory (all regular files, sorted by name) or a glob pattern (sorted matches).
// Error when nothing matches.
StatusOr<std::vector<std::string>> ListFiles(const std::string& dir_or_glob);
// ListFiles for images: from a directory only the files with an image extension (png, pgm, ppm,
// pnm, tif, tiff, jpg, jpeg, bmp, dcm, dicom; any case) and the other files that have the DICOM
// preamble ("DICM" at byte 128: Siemens .IMA, UID-like names, no extension), but not a DICOMDIR,
// so that e.g. the simulator's truth.json beside its images is not taken for one; a glob is taken
// as given. `file.dcm#frameN` (one frame of a
// multi-frame DICOM file, detect/grid_detector.h ReadImageViews) is taken as given when the file
// exists. Error if no image is left.
StatusOr<std::vector<std::string>> ListImageFiles(const std::string& dir_or_glob);

}  // namespace carmba
