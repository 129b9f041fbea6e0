// Simulated CT of a marker phantom, written as a DICOM CT series: the CT half of `carmba
// simulate` (scene files with `kind: ct`, e.g. configs/scenes/thesis_ct.yaml).
//
// Scene keys (all optional unless marked; lengths in mm, angles in degrees, values in HU).
// Relative paths are relative to the directory of the scene file.
//
//   kind: ct                      # required
//   description: "..."            # free text
//   seed: 1                       # noise seed (non-negative integer); same seed, same series
//   markers:                      # required
//     csv: ../../data/thesis/markers_table_5_1.csv   # required; one row per marker
//     id_column: marker           # default: 'id' if the CSV has it, else 'marker'
//     columns: [x_ct, y_ct, z_ct] # the patient-coordinate columns; default [x_mm, y_mm, z_mm]
//     diameter_mm: 2.0            # sphere diameter
//     hu: 3000                    # marker material
//   block:                        # the object the markers sit in (axis-aligned, patient frame)
//     enabled: true
//     padding_mm: 5               # default box: the markers' bounding box grown by this ...
//     centre_mm: [x, y, z]        # ... unless centre_mm and size_mm are both given
//     size_mm: [sx, sy, sz]
//     hu: 100
//   air_hu: -1000
//   ct:
//     columns: 512                # pixels along a row
//     rows: 512
//     pixel_spacing_mm: 0.3515625 # square pixels
//     slices: 120
//     slice_spacing_mm: 0.6       # distance between successive slice positions
//     slice_thickness_mm: 0.6     # extent of a voxel along the normal; default = spacing
//     centre_mm: [x, y, z]        # patient position of the volume centre; default: the centre
//                                 # of the markers' bounding box
//     orientation: [1, 0, 0, 0, 1, 0]  # ImageOrientationPatient (row dir, column dir)
//     tilt_deg: 0                 # then rotates both directions about patient +x by this angle
//                                 # (an oblique, gantry-tilt-like slice plane; slices stacked
//                                 # along the tilted normal)
//     noise_hu: 20                # white Gaussian noise sigma
//     metal_streak_hu: 0          # metal streaks' amplitude at a marker (ct_phantom.h)
//     psf_sigma_mm: 0             # the scanner's Gaussian PSF (blooming with clip_hu)
//     clip_hu: 0                  # the scanner's largest value (0: none), e.g. 3071
//     supersampling: 8            # per axis, for voxels cut by a marker surface
//     block_supersampling: 4      # per axis, for voxels cut only by a block face
//     rescale_slope: 1            # stored = round((HU - intercept) / slope), int16
//     rescale_intercept: -1024
//
// Every marker sphere must lie wholly inside the volume (with one voxel to spare) with its centre
// at least two diameters from every other marker's, else the scene is rejected naming the
// marker.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "ct/ct_phantom.h"
#include "ct/ct_volume.h"
#include "util/status.h"
#include "util/yaml_reader.h"

namespace carmba {

struct CtScene {
  CtPhantom phantom;
  CtVolume geometry;  // everything but hu
  CtVoxeliseOptions voxelise;
  CtWriteOptions write;
};

// Reads the CT keys above from `scene` (also `kind`, `description`, `seed`) and calls
// scene.Finish(), so an unknown key is an error: a caller must read its own keys before.
Status ParseCtScene(YamlMap& scene, CtScene* out);

// Builds the geometry of a volume centred at `centre_mm` (no voxels).
CtVolume MakeCtGeometry(int columns,
                        int rows,
                        int slices,
                        double pixel_spacing_mm,
                        double slice_spacing_mm,
                        double slice_thickness_mm,
                        const Eigen::Vector3d& row_dir,
                        const Eigen::Vector3d& col_dir,
                        const Eigen::Vector3d& centre_mm);

// The ground truth of a simulated CT as JSON: {"markers": [{"id","x_mm","y_mm","z_mm"}...],
// "ct": {geometry, materials, noise, seed, uids}}.
nlohmann::json CtTruthJson(const CtScene& scene, const std::string& series_dir_name);

// Simulates the CT scene described by `scene` (the top-level YamlMap of a scene file whose
// `kind` is `ct`) and writes the DICOM series to `out_dir`/ct/ (which must not exist or be
// empty; written to a temporary directory and renamed) and fills truth["markers"] (marker
// centres in patient mm) and truth["ct"] (geometry). No partial output on error.
Status SimulateCtScene(YamlMap& scene, const std::string& out_dir, nlohmann::json* truth);

}  // namespace carmba
