// Analytic X-ray phantoms: spheres and boxes with linear attenuation coefficients.
//
// A phantom lives in its own frame (`plate` for the calibration plate, `object` for marker
// objects), in mm. The renderer (sim/xray_render.h) integrates attenuation along rays exactly:
// chord lengths through spheres, the slab method through boxes. A sphere may be embedded in a
// host box (a metal ball inside a plastic plate): along a ray the sphere's material then
// REPLACES the host's where they overlap, i.e. the line integral is
//   mu_host |I_host| + mu_sphere |I_sphere| - mu_host |I_sphere ∩ I_host|
// with I the intervals of the ray inside each (convex) solid.
#pragma once

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "camera/carm_geometry.h"
#include "util/status.h"

namespace carmba::sim {

// Linear attenuation coefficients (1/mm) at an effective energy of about 60 keV (a fluoroscopy
// beam of 70-80 kVp), from NIST XCOM mass attenuation coefficients times density:
//   steel/iron 0.94, tungsten 7.0 (not resolved: it is black anyway), aluminium 0.074,
//   pmma (acrylic) 0.023, water / soft tissue 0.0206, bone (cortical) 0.057, wood (dry, about
//   0.5 g/cm^3) 0.010, air 0.
// Scenes may override or add materials.
std::map<std::string, double> DefaultMaterials();

struct SpherePrimitive {
  Eigen::Vector3d center_mm = Eigen::Vector3d::Zero();  // in the phantom frame
  double radius_mm = 0.0;
  double mu_per_mm = 0.0;
  int host_box = -1;  // index into Phantom::boxes whose material the sphere replaces, or -1
  int id = 0;         // marker number / grid index, reported in the ground truth
};

struct BoxPrimitive {
  Rigid3 phantom_from_box;  // box centred at the origin of its own frame, axis-aligned there
  Eigen::Vector3d half_size_mm = Eigen::Vector3d::Zero();
  double mu_per_mm = 0.0;
};

struct Phantom {
  std::string frame = "object";  // name of the phantom frame in the truth ("plate", "object")
  std::vector<SpherePrimitive> spheres;
  std::vector<BoxPrimitive> boxes;
};

// The calibration plate: rows x cols metal spheres on a regular grid, embedded in a plate.
// PLATE FRAME: origin at the centre of sphere (row 0, col 0); x along a row (increasing column),
// y along a column (increasing row), z normal to the plate; sphere centres at z = 0, the plate's
// mid-plane. Sphere k = row * cols + col has centre (col * pitch, row * pitch, 0) and id k — the
// row-major order of OpenCV's symmetric circle grid with patternSize = (cols, rows).
struct PlateSpec {
  int rows = 5;
  int cols = 5;
  double pitch_mm = 20.0;
  double sphere_diameter_mm = 3.06;  // the thesis: sphere volume 0.015 cm^3
  double thickness_mm = 5.0;         // 0 = no plate body (spheres in air)
  double margin_mm = 10.0;           // plate border beyond the outer sphere centres
  std::string sphere_material = "steel";
  std::string plate_material = "pmma";
  bool Check(std::string* error) const;
};

// A marker object: spheres at given centres, optionally embedded in a block (an axis-aligned
// box in the object frame spanning the markers' bounding box plus `block_margin_mm`).
struct MarkerSpec {
  std::vector<Eigen::Vector3d> centers_mm;  // object frame
  std::vector<int> ids;                     // one per centre
  double sphere_diameter_mm = 2.5;          // not given in the thesis: an assumption
  std::string sphere_material = "steel";
  bool block = true;
  double block_margin_mm = 5.0;
  std::string block_material = "pmma";
  bool Check(std::string* error) const;
};

// Builds the phantoms; errors name the unknown material.
StatusOr<Phantom> MakePlatePhantom(const PlateSpec& spec,
                                   const std::map<std::string, double>& materials);
StatusOr<Phantom> MakeMarkerPhantom(const MarkerSpec& spec,
                                    const std::map<std::string, double>& materials);

// Reads marker centres from a CSV (util/csv.h format): columns `x_col, y_col, z_col` (mm) and,
// if `id_col` is non-empty, an integer id column (else ids 1..N). Errors name file:line.
Status ReadMarkerCsv(const std::string& path,
                     const std::string& id_col,
                     const std::string& x_col,
                     const std::string& y_col,
                     const std::string& z_col,
                     MarkerSpec* spec);

}  // namespace carmba::sim
