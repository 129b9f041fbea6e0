// Shared by the libFuzzer harnesses (one reader each, tests/fuzz/fuzz_*.cc).
//
// Most readers take a path, so a harness writes the fuzz input to a file in a private scratch
// directory (in /dev/shm when it exists, so fuzzing does not wear a disk) and calls the reader.
// The scratch directory mirrors the repository's layout, so the shipped YAML files used as seeds
// resolve their relative references (`../data/thesis/camera.json`, `../../problems/...`):
//   <scratch>/data      -> <source>/data            (symlink; the readers only read)
//   <scratch>/problems  -> <source>/problems        (symlink)
//   <scratch>/configs/  real directory holding symlinks to <source>/configs/*.yaml, and real
//                       directories scenes/ and studies/ where scene and study inputs are written
//   <scratch>/p/        where problem inputs are written (depth 1, like problems/)
// The scratch directory is removed at exit.
#pragma once

#include <stdlib.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "../scratch.h"

namespace carmba::fuzz {

inline std::string SourceDir() { return CARMBA_SOURCE_DIR; }

inline const std::string& ScratchDir() {
  // Never destroyed: the atexit handler below runs after the destructors of statics constructed
  // before it was registered.
  static const std::string& dir = *new std::string([] {
    namespace fs = std::filesystem;
    const std::string shm = "/dev/shm";  // NOLINT(scratch): a base; the name comes from mkdtemp
    const std::string tmpl = carmba::test::MakeScratchDir("fuzz", fs::is_directory(shm) ? shm : "");
    const fs::path d(tmpl), src(SourceDir());
    fs::create_directory_symlink(src / "data", d / "data");
    fs::create_directory_symlink(src / "problems", d / "problems");
    fs::create_directories(d / "configs" / "scenes");
    fs::create_directories(d / "configs" / "studies");
    fs::create_directories(d / "p");
    for (const auto& e : fs::directory_iterator(src / "configs")) {
      if (e.is_regular_file()) fs::create_symlink(e.path(), d / "configs" / e.path().filename());
    }
    std::atexit([] {
      std::error_code ec;
      std::filesystem::remove_all(ScratchDir(), ec);
    });
    return tmpl;
  }());
  return dir;
}

// Writes `size` bytes to <scratch>/<name> (name may contain a sub-directory that exists) and
// returns the path.
inline std::string WriteInput(const std::string& name, const uint8_t* data, size_t size) {
  const std::string path = ScratchDir() + "/" + name;
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  f.close();
  if (!f) {
    std::perror(path.c_str());
    std::abort();
  }
  return path;
}

inline std::string WriteText(const std::string& name, const std::string& text) {
  return WriteInput(name, reinterpret_cast<const uint8_t*>(text.data()), text.size());
}

}  // namespace carmba::fuzz
