// libFuzzer harness: carmba::ReadCameraJson / CameraFromJson (camera/camera.h): camera.json.
#include "fuzz_util.h"
#include "camera/camera.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("camera.json", data, size);
  (void)carmba::ReadCameraJson(path);
  return 0;
}
