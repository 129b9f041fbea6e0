// The problem: WHAT is estimated from WHICH data, one schema for every problem kind. A joint
// problem has plate views and object views; a calibration problem has plate views only; a pose
// problem has object views only, with the intrinsics held at `camera` (problem/pose_solver.h). The
// solver configuration (HOW: problem/solver_config.h) is a file of its own.
//
// PROBLEM FILE (problems/*.yaml; paths relative to the file). The reference of every key with
// its units is src/docs/formats.md (kept equal to this reader by tests/cli/docs_formats_test.cc):
//   name: thesis_joint
//   description: ...
//   plate_views:                      # calibration plate views
//     observations: plate/observations.csv   # as `carmba detect` writes it (grid in its header)
//     # or images: DIR_OR_GLOB with pattern: circles, rows: 5, cols: 5, spacing_mm: 20 and
//     # detection: {polarity: dark, ...} (detect/grid_detector.h DetectionOptions; default: the
//     # command's, `carmba calibrate --detection FILE`)
//     sigma_px: 0.05                  # detection noise, 1 sigma per coordinate (required by
//                                     # `carmba solve`; `carmba calibrate` may estimate it)
//     plate: {free: false, sigma_mm: 0.01}    # optional: sphere positions free, tied to the
//                                             # nominal grid by the manufacturing tolerance
//     sphere_diameter_mm: 3                   # optional: the plate's spheres, for the cone-beam
//                                             # shadow correction (ba/shadow_correction.h)
//   object_views:
//     observations: object/observations.csv  # long: view, marker, u_px, v_px (io/pixel_csv.h)
//     format: long                    # or wide: a row per marker, columns u_<view>, v_<view>
//     marker_column: marker           # the marker id's column
//     views: [0, 10, 30]              # the views used (default: all in the file)
//     sigma_px: 0.3
//     # or images: DIR_OR_GLOB (PNG/TIFF/DICOM, multi-frame DICOM: a view per frame) with
//     # detection: {diameter_mm: 2, ...} (detect/marker_views.h ReadObjectViewsOptions): marker
//     # blobs detected and labelled with the fiducials through `camera` (required then); each
//     # observation's 2x2 covariance from its blob's (sigma_px, if given, is not used); views
//     # with fewer than 4 markers found are skipped (listed in skipped_object_views)
//   fiducials: fiducials.csv          # as `carmba ct-fiducials` writes it: id, x_mm, y_mm, z_mm,
//                                     # cov_xx..cov_zz (the CT prior); or a map
//                                     # {file, id_column, columns, sigma_mm}
//   handedness: as_given              # or mirrored (the object's y negated)
//   camera: camera.json               # initial intrinsics (default: Zhang on the plate views);
//                                     # required without plate views, where the intrinsics are
//                                     # held at it; with `intrinsics: {prior: true}` its
//                                     # covariance is an intrinsics prior
//   intrinsics: {model: shared}       # or {model: per_group, groups: groups.csv} (columns view,
//                                     # group; a plate view is named by its image stem or number)
//                                     # or {model: per_group} with angles: one group per plate
//                                     # orientation, an object view in the nearest one's group;
//                                     # or {model: smooth, primary_order: 1, secondary_degree: 1}:
//                                     # fx fy cx cy as functions of the C-arm angles
//                                     # (ba/smooth_intrinsics.h), distortion shared.
//                                     # select: true|false (default true when every view has
//                                     # angles): compare the models by held-out orientation
//                                     # groups and AIC/BIC (analysis/flex_models.h) in the report
//   angles: views.csv                 # optional: C-arm angles per view (columns view, primary_deg,
//                                     # secondary_deg; view = image stem, plate view number or
//                                     # object view id); plate views read from DICOM images take
//                                     # their Positioner Primary / Secondary Angle instead
//   validation: [{a: VIEW, b: VIEW, expected_deg: X}, ...]   # object views
//   reference:                        # optional (the thesis's), shown in the pose report
//     legacy_posit: {focal_px: 2158.0175, cx_px: 205.155, cy_px: 206.617, y_up: true}
//     rotations: posit_rotations.csv  # columns orientation_deg, r11..r33
//     validation: validation.csv      # columns orientation_a_deg, orientation_b_deg, achieved_deg
//   truth: truth.json                 # optional: the simulator's truth
//
// Pose problems written before the one schema keep working: top-level `markers` (the map of
// `fiducials`), `observations: {file, format, marker_column}`, `sigma_px` and `views` are read as
// `fiducials`, `object_views: {observations, format, marker_column, sigma_px, views}`.
// So do calibration problems written before it: top-level `images` or `observations` (a CSV path),
// `pattern`, `rows`, `cols` and `spacing_mm` are read as `plate_views`, and their `config` (which
// the one schema leaves to the command's --config) is kept in Problem::older_config_file.
#pragma once

#include <Eigen/Core>
#include <array>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "ba/smooth_intrinsics.h"
#include "camera/camera.h"
#include "detect/grid_detector.h"
#include "detect/observations.h"
#include "geometry/pose.h"
#include "io/object_views.h"
#include "util/status.h"

namespace carmba {

enum class Handedness { kAsGiven, kMirrored };

struct ValidationPair {
  std::string a, b;
  std::optional<double> expected_deg;
};

struct LegacyPositReference {
  double focal_px = 0, cx_px = 0, cy_px = 0;
  bool y_up = true;
};

// Ground truth, when known (simulated problems).
struct ProblemTruth {
  std::optional<Camera> camera;
  std::map<std::string, Pose6> object_poses;  // cam_from_object of the markers' frame, by view id
  // Per-view true intrinsics of a flexing C-arm ("view_intrinsics": [{"id", "camera"}]).
  std::map<std::string, std::array<double, kNumIntrinsics>> view_intrinsics;
  std::map<int, Eigen::Vector3d> markers;  // true marker positions (object frame)
};

struct Problem {
  std::string name, description;
  std::string path;  // the problem file, for messages
  // Plate views.
  ObservationSet plate;                     // empty views when there are none
  std::vector<std::string> plate_view_ids;  // image stems (or numbers), per plate view
  double plate_sigma_px = 0;
  bool plate_free = false;
  double plate_sigma_mm = 0;
  std::vector<std::string> skipped_images;  // plate images without a usable grid ("file: why")
  std::vector<GridDetection> plate_detections;  // every plate image's detection, when from images
  // A calibration problem file in the spelling before the one schema names its config (resolved
  // against the file's directory); empty otherwise.
  std::string older_config_file;
  // Object views.
  std::vector<PoseView> object_views;  // io/object_views.h: the one object-view form
  double object_sigma_px = 0;          // from images: the median of the per-observation sigmas
  // Diameter of the marker spheres (mm), when known (detected from images): the engine then
  // corrects each blob for its cone-beam shadow's offset (ba/shadow_correction.h). 0 = unknown.
  double marker_diameter_mm = 0;
  std::vector<std::string> skipped_object_views;  // object images not labelled ("view: why")
  std::vector<Marker> fiducials;
  Handedness handedness = Handedness::kAsGiven;
  // Intrinsics.
  std::optional<Camera> camera;
  bool camera_prior = false;
  bool per_group = false;
  std::map<std::string, std::string> group_of_view;  // per_group: view id -> group name
  bool smooth = false;                               // model smooth
  ba::SmoothBasis smooth_basis;
  bool secondary_degree_given = false;  // intrinsics.secondary_degree was in the file
  bool select_model = true;
  // C-arm angles (deg) by view id (plate view ids as plate_view_ids, object view ids), and where
  // each came from ("views.csv:12", "DICOM image.dcm").
  std::map<std::string, std::pair<double, double>> angles;
  std::map<std::string, std::string> angles_from;
  std::vector<ValidationPair> validation;
  // Reference values for the report (the thesis's).
  std::optional<LegacyPositReference> legacy_reference;
  std::map<std::string, Eigen::Matrix3d> reference_rotations;  // by view id
  std::map<std::pair<std::string, std::string>, double> reference_angles_deg;
  ProblemTruth truth;

  // A pose problem: object views only, the intrinsics held at `camera` (no intrinsics prior).
  bool IsPoseProblem() const { return plate.views.empty() && !camera_prior; }

  // The object views' consistency: view ids unique, every observation names a fiducial once, in
  // the plausible pixel range, >= 4 observations per view, validation pairs name object views.
  // A pose problem also needs the camera and a plausible sigma_px. Errors name the problem file.
  Status Check() const;
};

// "shared", "per_group" or "smooth": the problem's intrinsics model as the files spell it.
inline const char* IntrinsicsModelName(const Problem& p) {
  return p.smooth ? "smooth" : p.per_group ? "per_group" : "shared";
}

// What the command reading a problem adds: the detection options of plate images whose
// `plate_views` has no `detection` map of its own (calibrate --detection; else the defaults).
struct ProblemReadOptions {
  std::optional<DetectionOptions> plate_detection;
};

// The one problem reader, for every problem kind; the result has passed Check().
StatusOr<Problem> LoadProblem(const std::string& yaml_path,
                              const ProblemReadOptions& options = {});

// Where a problem's plate views come from: an observations CSV, or images the grid is detected
// in. A problem file's `plate_views` keys, `carmba calibrate`'s flags and the Python calibrate()
// all fill one and read it with LoadPlateViews.
struct PlateViewsInput {
  std::string observations;        // an observations.csv, or
  std::string images;              // a directory or glob of images
  std::optional<GridSpec> grid;    // as named (pattern, rows, cols, spacing_mm); images need it,
                                   // a CSV's own grid must then agree with it
  double spacing_mm_override = 0;  // > 0: replaces a CSV's pitch (calibrate --spacing-mm)
  double sphere_diameter_mm = 0;   // 0: not known
  DetectionOptions detection;      // for images
  // How an error names an input ("images", "observations", "pattern", "rows",
  // "sphere_diameter_mm"): `key` within a sentence ("plate_views.rows" in a problem, "--rows"
  // for calibrate's flags), `fail` as the error about it ("FILE:LINE: key 'plate_views.rows':
  // WHAT", "--rows: WHAT"). NameInputsAsFlags sets both for flags.
  std::function<std::string(const std::string& input)> key;
  std::function<Status(const std::string& input, const std::string& what)> fail;
  // Optional: called with the number of images before the grid is detected in them; returns the
  // callback ticked once per image (a progress bar).
  std::function<ProgressFn(int num_images)> detecting;
};

// PlateViewsInput::key and fail naming inputs as a command's flags: "rows" as "--rows".
void NameInputsAsFlags(PlateViewsInput* in);

// Reads or detects the plate views into p->plate, p->plate_view_ids, p->skipped_images and
// p->plate_detections. An error is one line naming the input (PlateViewsInput::fail).
Status LoadPlateViews(const PlateViewsInput& in, Problem* p);

// A fiducial's position and CT covariance in the problem's handedness (mirrored: y negated).
Eigen::Vector3d MarkerInProblemFrame(const Problem& problem, const Marker& m);
Eigen::Matrix3d MarkerCovarianceInProblemFrame(const Problem& problem, const Marker& m);

}  // namespace carmba
