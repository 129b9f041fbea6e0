// Scratch directories for the tests, benchmarks and fuzz harnesses: the one way they get a place
// to write. Every directory is made by mkdtemp(3), so its name is unique across processes,
// threads and repeated runs (`ctest -j --schedule-random --repeat`); no test writes to a fixed
// name. tests/lint_scratch_names.sh (ctest: lint_scratch_names) fails on one that does.
// Header-only and free of GoogleTest, so the benchmarks and fuzz harnesses use it too.
#pragma once

#include <stdlib.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

namespace carmba::test {

// A new, empty directory `<base>/carmba_<tag>_XXXXXX` (base: the system temporary directory,
// $TMPDIR or /tmp, when empty). Aborts when it cannot be made: nothing can run without it.
inline std::string MakeScratchDir(const std::string& tag, const std::string& base = "") {
  const std::string root = base.empty() ? std::filesystem::temp_directory_path().string() : base;
  std::string tmpl = root + "/carmba_" + tag + "_XXXXXX";
  if (::mkdtemp(tmpl.data()) == nullptr) {
    std::perror(("mkdtemp " + tmpl).c_str());
    std::abort();
  }
  return tmpl;
}

// A MakeScratchDir directory, removed with its contents when the object dies (kept when
// CARMBA_KEEP_TMP is set, to look at a failing test's files).
class ScratchDir {
 public:
  explicit ScratchDir(const std::string& tag = "test") : path_(MakeScratchDir(tag)) {}
  ~ScratchDir() {
    if (std::getenv("CARMBA_KEEP_TMP") != nullptr) return;
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;

  const std::string& path() const { return path_; }
  // The path of `name` (which may contain sub-directories) inside the directory.
  std::string File(const std::string& name) const { return path_ + "/" + name; }
  // Writes `text` to File(name).
  void Write(const std::string& name, const std::string& text) const {
    std::ofstream(File(name)) << text;
  }

 private:
  std::string path_;
};

}  // namespace carmba::test
