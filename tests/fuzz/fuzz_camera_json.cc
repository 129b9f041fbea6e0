// Fuzz target `camera_json` (fuzz_main.cc): the camera readers of JSON files.
// carmba::ReadCameraJson / CameraFromJson (camera/camera.h): camera.json; carmba::ReadGeometryJson
// (export/view_geometry.h): the geometry.json that carmba export-geometry reads (a camera and a
// pose per view, P checked); carmba::ReadXmaCalibration (track/track.h): the XMALab calibration
// text of `carmba track
// --cameras` (seeded with the wrist set's two).
#include "camera/camera.h"
#include "export/view_geometry.h"
#include "fuzz_target.h"
#include "fuzz_util.h"
#include "track/track.h"

namespace {

int FuzzCameraJson(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("camera.json", data, size);
  (void)carmba::ReadCameraJson(path);
  (void)carmba::ReadGeometryJson(path);
  (void)carmba::ReadXmaCalibration(path, "cam");
  return 0;
}

}  // namespace

CARMBA_FUZZ_TARGET(camera_json, FuzzCameraJson, nullptr)
