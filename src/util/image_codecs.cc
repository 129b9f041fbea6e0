#include "util/image_codecs.h"

#include <dlfcn.h>

#include <cstdio>

#include "codecs/image_codecs_module.h"

// The module's path in the build tree (src/CMakeLists.txt).
#ifndef CARMBA_IMAGE_CODECS_MODULE
#error "CARMBA_IMAGE_CODECS_MODULE (the path of the carmba_image_codecs module) is not defined"
#endif

namespace carmba {
namespace {

// The module's table; nullptr (after one line on stderr) when it cannot be loaded. The module
// stays loaded until the process ends.
const ImageCodecTable* LoadCodecs() {
  const char* path = CARMBA_IMAGE_CODECS_MODULE;
  void* module = dlopen(path, RTLD_NOW | RTLD_LOCAL);
  if (module == nullptr) {
    std::fprintf(stderr, "carmba: cannot load the image codecs module %s (%s)\n", path, dlerror());
    return nullptr;
  }
  using Entry = const ImageCodecTable* (*)();
  auto entry = reinterpret_cast<Entry>(dlsym(module, CARMBA_IMAGE_CODECS_SYMBOL));
  if (entry == nullptr) {
    std::fprintf(stderr, "carmba: %s has no symbol %s\n", path, CARMBA_IMAGE_CODECS_SYMBOL);
    return nullptr;
  }
  return entry();
}

// Loaded once per process (a function-local static is initialised once, thread-safely).
const ImageCodecTable* Codecs() {
  static const ImageCodecTable* const table = LoadCodecs();
  return table;
}

}  // namespace

cv::Mat ImRead(const std::string& path, int flags) {
  const ImageCodecTable* codecs = Codecs();
  return codecs == nullptr ? cv::Mat() : codecs->read(path, flags);
}

bool ImWrite(const std::string& path, const cv::Mat& image) {
  const ImageCodecTable* codecs = Codecs();
  return codecs != nullptr && codecs->write(path, image);
}

bool ImEncode(const std::string& ext, const cv::Mat& image, std::vector<uint8_t>* bytes) {
  const ImageCodecTable* codecs = Codecs();
  return codecs != nullptr && codecs->encode(ext, image, bytes);
}

}  // namespace carmba
