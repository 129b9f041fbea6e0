// X-ray scenes for `carmba simulate`: a C-arm, a phantom and a list of views, read strictly from
// YAML, rendered to images with their ground truth.
//
// SCENE FILE (kind: xray). Lengths mm, angles degrees. Relative paths are relative to the
// directory of the scene file. Unknown keys are errors.
//
//   kind: xray                       # required ('ct' scenes go to ct/ct_simulate.h)
//   description: "..."
//   seed: 1                          # noise seed; view i uses a seed derived from (seed, i)
//   output: {format: png, bit_depth: 8}        # png | pgm | dcm, 8 | 16
//     multiframe: true (dcm only): all views in ONE multi-frame DICOM XA file `views.dcm` (views
//     named views.dcm#frame1.. in truth.json), the first view's angles as Positioner Primary /
//     Secondary Angle and each frame's offset from them as the per-frame increments (0018,1520 /
//     1521); SID, SOD and the pixel spacing are the file's (the views must share them).
//     dcm: one single-frame DICOM XA file per view (io/dicom_xray.h WriteDicomXray) carrying the
//     view's Positioner Primary / Secondary Angle, SID, SOD and Imager Pixel Spacing
//     (SID / fy \ SID / fx, so that io/dicom_view.h gives back fx, fy). The detector rotation,
//     the isocentre, the axis offset, cx, cy and the distortion have no XA tag: only truth.json
//     has them.
//   camera:
//     image_size: [408, 408]         # required, px
//     fx: .., fy: .., cx: .., cy: .. # px; either all four, or
//     pixel_pitch_mm: 0.485          # detector pitch (number or [x, y]): fx = sid / pitch, ...
//     principal_offset_px: [0, 0]    # ... and c = image centre + this offset
//     distortion: [k1, k2, p1, p2, k3]          # default zeros; k1 < 0 barrel, k1 > 0 pincushion
//   carm:                            # camera/carm_geometry.h
//     sid_mm: 1000, sod_mm: 620, isocenter_mm: [0, 0, 0], axis_offset_mm: [0, 0]
//     flex: {cx_primary_px: 6, cx_secondary_px: 0.5, cy_primary_px: 2.5, cy_secondary_px: 0.3,
//            f_primary: 0.004, f_secondary: 0.001}
//       # optional: intrinsics that depend on the view's angles (camera/carm_flex.h); `camera`
//       # gives them at primary = secondary = 0. Each view's true intrinsics go to truth.json
//       # (views[].intrinsics); a DICOM view's Imager Pixel Spacing follows its fx, fy.
//   imaging:                         # sim/xray_render.h RenderOptions
//     supersampling: 3, white_level: 220, photons_per_pixel: 3000, read_noise_gray: 0.8,
//     blur_sigma_px: 0.6, vignetting: 0.2, outside_fov_gray: 0,
//     vignetting_power: 2,           # fall-off profile 1 - vignetting (r / R)^power
//     heel: {gradient: 0.08, direction_deg: 0}   # +-8 % across the field, brighter towards +x
//     glare: {fraction: 0.1, sigma_px: 60}       # veiling glare (xray_render.h step 5)
//     fov: {circular: true, radius_px: 204, center_px: [203.5, 203.5], edge_px: 6}
//     background: {file: /usr/share/doc/libgdcm3.0/examples/00191113.dcm, strength: 0.3,
//                  crop: 0.6}
//   anatomy:                         # a real CT fixed to the object (sim/ct_anatomy.h): each
//                                    # view's image attenuated by its DRR, which moves with it
//     ct: /usr/share/doc/invesalius-examples/examples/Cranium.inv3   # required: .inv3, or a
//                                    # directory holding one DICOM CT series
//     center_mm: [0, 0, 0]           # the CT volume's centre in the object frame
//     rotation_deg: [0, 0, 0]        # rotation vector of the CT's axes in the object frame
//     mu_water_per_mm: 0.02          # mu = mu_water (1 + HU / 1000), 0 at and below -1000 HU
//     subsample: 2                   # line integrals every N px (1..8), bilinear in between
//   materials: {steel: 0.94, ...}    # mu (1/mm): overrides / additions to DefaultMaterials()
//   plate:                           # the calibration plate (sim/phantom.h PlateSpec), or
//     rows: 5, cols: 5, pitch_mm: 20, sphere_diameter_mm: 3.06, thickness_mm: 5, margin_mm: 10,
//     sphere_material: steel, plate_material: pmma
//   markers:                         # a marker object from a CSV (exactly one of plate/markers)
//     csv: ../../data/thesis/markers_table_5_1.csv   # required
//     id_column: marker              # default: ids 1..N
//     columns: [x_o, y_o, z_o]       # required: object-frame columns, mm
//     diameter_mm: 2.5, material: steel
//   block: {enabled: true, padding_mm: 5, material: pmma}   # the markers' host block
//   object_pose:                     # where the phantom is in the world (patient LPS)
//     rotation_deg: [rx, ry, rz]     # rotation vector (degrees) about the spheres' centroid
//     center_mm: [x, y, z]           # world position of the spheres' centroid (default: 0)
//     i.e. world_from_object = T(center) * R(rotation) * T(-centroid)
//   clutter:                         # markers scenes: metal that is NOT a marker (object frame),
//                                    # rendered but not in the truth's spheres: spurious beads
//     spheres: [{center_mm: [x, y, z], diameter_mm: 2.0, material: steel}]
//     wires: [{from_mm: [x, y, z], to_mm: [x, y, z], diameter_mm: 0.6, material: steel}]
//                                    # a square rod of that width along the segment
//     truth.json: per view "clutter_centers_px" (the spheres', projected)
//   views:                           # required, at least one
//     - name: view_000               # file stem (letters, digits, '_', '-'); default view_NNN
//       primary_deg: 0               # LAO +, RAO -
//       secondary_deg: 0             # cranial +, caudal -
//       detector_rotation_deg: 0
//       object_rotation_deg: [..]    # optional per-view object_pose overrides
//       object_center_mm: [..]
//       partial: false               # true: markers may fall outside the field of view here
//
// Every sphere of every view (but `partial` ones) must project, with its whole silhouette, inside
// the image and the fully exposed part of the field of view (radius_px - edge_px), else the scene
// is rejected naming the view and the sphere.
//
// GROUND TRUTH (truth.json, filled by SimulateXrayScene):
//   {"kind": "xray", "description", "seed",
//    "camera": CameraToJson (image_size, fx, fy, cx, cy, distortion [k1 k2 p1 p2 k3]),
//    "carm": {sid_mm, sod_mm, isocenter_mm, axis_offset_mm},
//    "object": {"kind": "plate"|"markers", "frame": "plate"|"object", "sphere_ids": [..],
//               "centers_mm": [[x,y,z]..] (phantom frame), "sphere_diameter_mm",
//               plate: "rows", "cols", "pitch_mm", "thickness_mm"},
//    "anatomy" (with `anatomy`): {"ct", "object_from_ct" {"R", "rvec", "t_mm"}, "mu_water_per_mm"},
//    "views": [{"name", "file", "primary_deg", "secondary_deg", "detector_rotation_deg", "seed",
//               "cam_from_world", "world_from_object", "cam_from_plate"|"cam_from_object"
//                  (each {"R": 3x3 row-major, "rvec": [rad], "t_mm": [..]}),
//               "centers_px": [[u, v]..] (sphere order, projected with distortion),
//               "centers_in_cam_mm": [[x,y,z]..],
//               "intrinsics": CameraToJson of the view's camera (with flex: at its angles)}]}
#pragma once

#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "camera/camera.h"
#include "camera/carm_flex.h"
#include "camera/carm_geometry.h"
#include "sim/ct_anatomy.h"
#include "sim/phantom.h"
#include "sim/xray_render.h"
#include "util/status.h"
#include "util/yaml_reader.h"

namespace carmba::sim {

struct XrayView {
  std::string name;
  CarmGeometry carm;         // the scene's C-arm with this view's angles
  Rigid3 world_from_object;  // the phantom's placement in this view
  uint64_t seed = 0;         // noise seed of this view
  bool partial = false;      // markers may lie outside the field of view
};

struct XrayScene {
  std::string path;  // the scene file (messages)
  std::string description;
  uint64_t seed = 1;
  std::string format = "png";
  int bit_depth = 8;
  Camera camera;
  RenderOptions render;     // seed is set per view
  std::string object_kind;  // "plate" | "markers"
  PlateSpec plate;          // if plate
  MarkerSpec markers;       // if markers
  Phantom phantom;
  Phantom clutter;          // metal that is not a marker (object frame); may be empty
  std::optional<CtAnatomy> anatomy;  // a real CT fixed to the object, when given
  bool multiframe = false;  // dcm: one multi-frame file
  std::vector<XrayView> views;
  CarmFlex flex;            // rigid unless carm.flex is given

  // The camera of view `view`: `camera` moved by the flex at the view's angles.
  Camera ViewCamera(int view) const {
    Camera c = camera;
    c.params = flex.Apply(camera.params, views[view].carm.primary_angle_deg,
                          views[view].carm.secondary_angle_deg);
    return c;
  }

  Rigid3 CamFromObject(int view) const {
    return CamFromWorld(views[view].carm) * views[view].world_from_object;
  }
};

// The noise seed of view `index` of a scene with seed `seed` (53 bits, exact in JSON).
uint64_t ViewSeed(uint64_t seed, int index);
// Sets the scene's seed and re-derives every view's seed (Monte Carlo studies over noise).
void ReseedXrayScene(uint64_t seed, XrayScene* scene);

// Reads the X-ray scene keys (all of the above, including `kind`) and calls scene.Finish().
// Then checks every view's projection against the field of view.
Status ParseXrayScene(YamlMap& scene, XrayScene* out);
// Loads and parses a scene file.
StatusOr<XrayScene> LoadXrayScene(const std::string& path);

// One rendered view and its truth.
struct RenderedView {
  cv::Mat gray;   // CV_32F grey levels (before rounding)
  cv::Mat image;  // CV_8U / CV_16U, as written
  Rigid3 cam_from_object;
  std::vector<Eigen::Vector2d> centers_px;  // per sphere, with distortion
  nlohmann::json truth;                     // the view's entry of truth.json (file name included)
};

// Renders view `index`. `grid` may be null (then built for this call).
StatusOr<RenderedView> RenderXrayView(const XrayScene& scene,
                                      int index,
                                      const RayGrid* grid = nullptr);

// Renders all views into `out_dir` (must exist) as <name>.<format> and fills `truth` (everything
// but writing truth.json, which the caller does).
Status SimulateXrayScene(const XrayScene& scene, const std::string& out_dir, nlohmann::json* truth);

// Checks that every sphere of every view lies, with its silhouette, inside the image and the
// FOV. Error names the view and the sphere.
Status CheckViewsInsideFov(const XrayScene& scene);

}  // namespace carmba::sim
