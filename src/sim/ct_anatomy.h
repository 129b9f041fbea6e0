// Anatomy from a real CT in an X-ray scene: a CT volume placed in the object's frame (the patient
// the markers are fixed to), and each view's image attenuated by the volume's line integrals
// along that view's rays -- a digitally reconstructed radiograph (DRR) that moves with the
// object, shows bone edges where the C-arm sees them, and comes from data carmba did not design.
//
// MODEL. A ray leaves the source through pixel (u, v) along (x, y, 1), (x, y) =
// UnprojectToNormalized(intrinsics, (u, v)) (with the view's distortion, as the renderer's rays).
// Inside the volume's box (voxel centres, in its index space) it is sampled every
// `step_fraction` x the smallest voxel spacing, HU trilinear (ct/ct_volume.h TrilinearHu), and
//   mu(HU) = mu_water * max(0, 1 + HU / 1000)   (1/mm; air 0, water mu_water, bone about 2x)
//   gain(u, v) = exp(-sum mu * step)
// multiplies the expected grey level (sim/xray_render.h, background_gain). The line integral is
// computed every `subsample` pixels and bilinear in between (a CT voxel of about 1 mm covers
// several detector pixels), then exponentiated. Outside the box the gain is 1.
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <string>

#include "camera/camera.h"
#include "ct/ct_volume.h"
#include "geometry/pose.h"
#include "sim/xray_render.h"
#include "util/status.h"

namespace carmba::sim {

struct CtAnatomy {
  std::string file;  // as the scene names it (messages, truth.json)
  std::shared_ptr<const CtVolume> volume;
  Rigid3 object_from_ct;          // the CT's patient frame in the object frame
  double mu_water_per_mm = 0.02;  // water at a fluoroscopy spectrum's effective energy
  int subsample = 2;              // line integrals every this many pixels (1..8)
  double step_fraction = 1.0;     // sampling step along a ray / smallest voxel spacing
};

// The CT of `path`: an InVesalius 3 project (.inv3, ct/ct_invesalius.h) or a directory holding one
// DICOM CT series (ct/ct_volume.h ReadCtSeries). Errors name the file. An .inv3 read before in
// this process, unchanged since (size and modification time), is not read again: scenes rendered
// one after the other share it.
StatusOr<std::shared_ptr<const CtVolume>> ReadAnatomyCt(const std::string& path);

// The centre of the volume's voxel box, in its patient frame (mm).
Eigen::Vector3d CtVolumeCentre(const CtVolume& volume);

// The per-pixel gain (CV_32F, the camera's size, values in (0, 1]) of `anatomy` seen by `camera`
// with the object at `cam_from_object`. With `fov`, pixels further than two grid steps outside its
// circle (which the renderer leaves dark) get 1 without a ray.
cv::Mat CtAnatomyGain(const CtAnatomy& anatomy,
                      const Camera& camera,
                      const Rigid3& cam_from_object,
                      const FovCircle* fov = nullptr);

}  // namespace carmba::sim
