// `carmba undistort`: writes each image (each DICOM frame) undistorted with a calibrated camera,
// onto the pixel grid of the projection matrices in geometry.json (export/undistort.h).
#include <gflags/gflags.h>

#include <filesystem>
#include <iostream>
#include <set>

#include "cli/command.h"
#include "cli/common_flags.h"
#include "detect/grid_detector.h"
#include "export/undistort.h"
#include "io/image_files.h"
#include "util/file_util.h"
#include "util/image_codecs.h"

namespace {

using namespace carmba;

// The camera from camera.json, or from a joint solve's result.json (its `intrinsics` object).
StatusOr<Camera> LoadCamera(const std::string& path) {
  auto parsed = ReadJsonFile(path, "a camera.json or a joint result.json");
  if (!parsed.ok()) return parsed.status();
  const nlohmann::json& j = *parsed;
  if (j.is_object() && j.contains("intrinsics")) {
    if (!j["intrinsics"].is_object()) {
      return Status::Error(path + ": key 'intrinsics': one camera expected (per-group intrinsics: "
                                  "save one group's object as a camera.json)");
    }
    return CameraFromJson(j["intrinsics"], path + ": intrinsics");  // checks the ranges too
  }
  return CameraFromJson(j, path);
}

// Output name of a view: the file's stem (+ _frameN for a frame of a multi-frame DICOM file),
// .png for 8 / 16 bit (lossless, depth kept), .tiff for float.
std::string OutputName(const std::string& view, int depth) {
  const FrameName split = SplitFrameSuffix(view);
  const std::string frame = split.suffix.empty() ? "" : "_" + split.suffix.substr(1);
  return std::filesystem::path(split.file).stem().string() + frame +
         (depth == CV_32F ? ".tiff" : ".png");
}

int RunUndistort() {
  const char* kCmd = "undistort";
  if (FLAGS_images.empty()) return cli::FailUsage(kCmd, "--images is required");
  if (FLAGS_camera.empty()) return cli::FailUsage(kCmd, "--camera is required");
  if (FLAGS_out.empty()) return cli::FailUsage(kCmd, "--out (directory) is required");
  {
    const Status s = cli::CheckOutDir();
    if (!s.ok()) return cli::Fail(kCmd, s);
  }
  cli::Step(kCmd, "reading the camera " + FLAGS_camera);
  auto camera = LoadCamera(FLAGS_camera);
  if (!camera.ok()) return cli::Fail(kCmd, camera.status());
  auto files = ListImageFiles(FLAGS_images);
  if (!files.ok()) return cli::Fail(kCmd, files.status().WithContext("--images"));
  StagedOutputDir staged(FLAGS_out);
  Status s = staged.Begin();
  if (!s.ok()) return cli::Fail(kCmd, s);
  std::set<std::string> names;
  int written = 0;
  cli::Step(kCmd, "undistorting " + std::to_string(files->size()) + " image files");
  for (const auto& file : *files) {
    auto views = ReadImageViews(file);
    if (!views.ok()) return cli::Fail(kCmd, views.status());
    for (const auto& view : *views) {
      auto out = UndistortImage(view.image, *camera);
      if (!out.ok()) return cli::Fail(kCmd, out.status().WithContext(view.name));
      const std::string name = OutputName(view.name, out->depth());
      if (!names.insert(name).second) {
        return cli::Fail(kCmd, view.name + ": a second image named " + name + " in --out");
      }
      const std::string path = JoinPath(staged.path(), name);
      bool ok = false;
      try {
        ok = ImWrite(path, *out);
      } catch (const cv::Exception&) {
        ok = false;
      }
      if (!ok) return cli::Fail(kCmd, path + ": cannot write the image");
      ++written;
    }
  }
  cli::Step(kCmd, "moving the outputs into place");
  s = staged.Commit(/*replace_all=*/false);
  if (!s.ok()) return cli::Fail(kCmd, s);
  std::cout << "undistorted " << written << " images into " << FLAGS_out << " (" << camera->width
            << "x" << camera->height << " px, pinhole fx " << camera->params[kFx] << " fy "
            << camera->params[kFy] << " cx " << camera->params[kCx] << " cy "
            << camera->params[kCy] << ", no distortion)" << std::endl;
  return 0;
}

}  // namespace

CARMBA_COMMAND_FLAGS(undistort, "images,camera,out,force");
CARMBA_REGISTER_COMMAND(
    undistort,
    "Undistort images (PNG, TIFF, ..., DICOM frames) with a calibrated camera: writes --out/"
    "<stem>.png (8/16 bit kept; <stem>_frameN.png per DICOM frame). Output pixel grid: the same "
    "width x height and pixel convention (pixel (0,0) = centre of the top-left pixel), an ideal "
    "pinhole with the camera's fx fy cx cy and no distortion -- the grid geometry.json's "
    "projection matrices map to; pixels whose source lies outside the image are 0.",
    RunUndistort);
