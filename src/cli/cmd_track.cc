// `carmba track`: beads tracked through the frames of a calibrated multi-camera X-ray system
// (track/track.h): detected in every image, matched across the cameras by epipolar geometry,
// identified across frames as rigid bodies, solved as one bundle adjustment over all frames.
//
//   carmba track --cameras 'cam01=FILE;cam02=FILE'
//                --images 'cam01=DIR_OR_GLOB;cam02=DIR_OR_GLOB' --marker-diameter-mm D --out DIR
//
// FILE: the XMALab / Autoscoper calibration text (image size, camera matrix, rotation,
// translation; x_cam = R x_lab + t), or CAMERA_JSON+POSE_JSON: carmba's camera.json (with its
// distortion) and {"cam_from_lab": {"rvec": [rad], "t_mm": [mm]}}. Frames are paired by the number
// in the file names. Writes into --out: points.csv, observations.csv, rigid_bodies.json, report.md,
// report.html, overlays/; all or nothing (report/track_report.h).
#include <gflags/gflags.h>

#include <iostream>
#include <map>

#include "cli/command.h"
#include "cli/common_flags.h"
#include "track/track.h"
#include "report/track_report.h"
#include "util/file_util.h"
#include "util/plausible.h"

DEFINE_string(
    cameras,
    "",
    "The calibrated cameras, 'NAME=FILE;NAME=FILE': XMALab / Autoscoper calibration texts "
    "(image size, camera matrix, rotation, translation; x_cam = R x_lab + t), or "
    "NAME=camera.json+pose.json (carmba's camera and {\"cam_from_lab\": {\"rvec\", \"t_mm\"}}).");
DEFINE_double(epipolar_px, 2.0, "Rays of one bead meet within this many px in every image.");
DEFINE_double(rigid_tolerance_mm, 0.3,
              "Distances within a rigid body agree between frames within this (mm).");

namespace {

using namespace carmba;

// 'name=value;name=value' in the order given. Error naming the flag.
StatusOr<std::vector<std::pair<std::string, std::string>>> NamedList(const std::string& flag,
                                                                     const std::string& text) {
  std::vector<std::pair<std::string, std::string>> out;
  size_t start = 0;
  while (start <= text.size()) {
    const size_t end = std::min(text.find(';', start), text.size());
    const std::string item = text.substr(start, end - start);
    start = end + 1;
    if (item.empty()) continue;
    const size_t eq = item.find('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 == item.size()) {
      return Status::Error(flag + ": expected 'NAME=PATH;NAME=PATH', got '" + item + "'");
    }
    const std::string name = item.substr(0, eq);
    for (const auto& [n, p] : out) {
      if (n == name) return Status::Error(flag + ": camera '" + name + "' is given twice");
    }
    out.emplace_back(name, item.substr(eq + 1));
  }
  if (out.size() < 2)
    return Status::Error(flag + ": expected at least two cameras, 'NAME=PATH;NAME=PATH'");
  return out;
}

int RunTrack() {
  const char* kCmd = "track";
  if (!InRange(FLAGS_marker_diameter_mm, plausible::kMarkerDiameterMm)) {
    return cli::FailUsage(kCmd,
                          "--marker-diameter-mm: expected " +
                              FormatRange(plausible::kMarkerDiameterMm) + ", got " +
                              FormatCompact(FLAGS_marker_diameter_mm) +
                              (FLAGS_marker_diameter_mm > 0 && FLAGS_marker_diameter_mm < 0.1
                                   ? " (a diameter in metres?)"
                                   : ""));
  }
  TrackOptions options;
  options.marker_diameter_mm = FLAGS_marker_diameter_mm;
  options.epipolar_px = FLAGS_epipolar_px;
  options.rigid_tolerance_mm = FLAGS_rigid_tolerance_mm;
  if (std::string error; !options.Check(&error)) {
    std::replace(error.begin(), error.end(), '_', '-');
    return cli::FailUsage(kCmd, "--" + error);
  }
  auto camera_files = NamedList("--cameras", FLAGS_cameras);
  if (!camera_files.ok()) return cli::FailUsage(kCmd, camera_files.status());
  auto image_sets = NamedList("--images", FLAGS_images);
  if (!image_sets.ok()) return cli::FailUsage(kCmd, image_sets.status());
  std::vector<cli::InputPath> inputs;
  for (const auto& [n, p] : *camera_files) {
    const auto plus = p.find('+');
    inputs.push_back({"--cameras " + n, p.substr(0, plus)});
    if (plus != std::string::npos) inputs.push_back({"--cameras " + n, p.substr(plus + 1)});
  }
  for (const auto& [n, p] : *image_sets) inputs.push_back({"--images " + n, p});
  if (Status s = cli::CheckOutIsNoInput(inputs); !s.ok()) return cli::FailUsage(kCmd, s);
  if (Status s = cli::CheckOutDir(); !s.ok()) return cli::Fail(kCmd, s);

  cli::Step(kCmd, "reading the cameras and listing the images");
  std::map<std::string, std::string> images_of(image_sets->begin(), image_sets->end());
  std::vector<TrackCamera> cameras;
  std::vector<std::vector<std::string>> images;
  for (const auto& [name, file] : *camera_files) {
    auto cam = ReadTrackCamera(name, file);
    if (!cam.ok()) return cli::Fail(kCmd, cam.status());
    cameras.push_back(*cam);
    if (!images_of.count(name)) {
      return cli::FailUsage(kCmd, "--images: no images for camera '" + name + "' of --cameras");
    }
    auto list = ListImageFiles(images_of.at(name));
    if (!list.ok()) return cli::Fail(kCmd, "--images " + name + ": " + list.status().message());
    images.push_back(*list);
    images_of.erase(name);
  }
  if (!images_of.empty()) {
    return cli::FailUsage(
        kCmd, "--images: camera '" + images_of.begin()->first + "' is not in --cameras");
  }
  std::vector<std::string> unpaired;
  auto frames = PairFrames(images, &unpaired);
  if (!frames.ok()) return cli::Fail(kCmd, frames.status());
  cli::Step(
      kCmd,
      "detecting, matching, identifying and solving " + std::to_string(frames->size()) + " frames");
  auto result = Track(cameras, *frames, options);
  if (!result.ok()) return cli::Fail(kCmd, result.status());
  for (const std::string& p : unpaired)
    result->warnings.push_back(p + ": no other camera imaged this frame (left out)");
  cli::Step(kCmd, "writing the outputs and overlays");
  StagedOutputDir staged(FLAGS_out);
  Status s = staged.Begin();
  if (s.ok()) s = WriteTrackOutputs(*result, TrackTargets{}, staged.path());
  if (s.ok()) s = staged.Commit(/*replace_all=*/false);
  if (!s.ok()) return cli::Fail(kCmd, s);
  for (const std::string& w : result->warnings) std::cerr << "carmba track: warning: " << w << "\n";
  const TrackChecks& c = result->checks;
  std::printf(
      "track: %zu frames, %zu beads in %zu bodies (>= %d per frame from 2+ cameras), RMS %.3f px, "
      "distances within bodies: spread <= %.3f mm, change <= %.2f sigma; wrote %s\n",
      result->frames.size(),
      result->beads.size(),
      result->bodies.size(),
      c.min_beads_per_frame,
      c.rms_px,
      c.max_spread_mm,
      c.max_change_sigmas,
      FLAGS_out.c_str());
  return 0;
}

}  // namespace

CARMBA_COMMAND_FLAGS(track, "images,out,force,marker_diameter_mm");
CARMBA_REQUIRED_FLAGS(track, "cameras,images,marker_diameter_mm,out");
CARMBA_REGISTER_COMMAND(track,
                        "Beads tracked through frames of calibrated X-ray cameras: epipolar "
                        "matching, rigid bodies, one bundle adjustment over all frames.",
                        RunTrack);
