// Calibration grids and their detected image points ("observations").
//
// Grid frame (the plate frame, "object" of cam_from_object): the plate lies in z = 0, x along the
// columns, y along the rows, in mm. Point id = row * cols + col (row-major, as mrcal and OpenCV
// order them).
//   circles    (symmetric circle grid, the thesis's 5x5 sphere plate): (col s, row s, 0)
//   acircles   (OpenCV's asymmetric circle grid): ((2 col + row % 2) s, row s, 0)
//   chessboard (inner corners): (col s, row s, 0)
//
// observations.csv (written by `carmba detect` and `carmba calibrate`, read by `calibrate
// --observations`):
//   # carmba observations
//   # grid: circles 5 5 20            (pattern rows cols spacing_mm)
//   # image_size: 408 408             (width height, px)
//   view,image,point,u_px,v_px
//   0,calib/0001.pgm,0,101.25,88.5
// One row per detected point; pixel (0,0) is the centre of the top-left pixel.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "ba/problem.h"
#include "geometry/pose.h"
#include "util/status.h"

namespace carmba {

enum class GridPattern { kCircles, kAsymmetricCircles, kChessboard };

// "circles", "acircles", "chessboard".
const char* GridPatternName(GridPattern pattern);
StatusOr<GridPattern> ParseGridPattern(const std::string& name);

struct GridSpec {
  GridPattern pattern = GridPattern::kCircles;
  int rows = 5;             // points per column
  int cols = 5;             // points per row
  double spacing_mm = 20;   // pitch between neighbouring points of a row
  // Diameter of the plate's spheres (mm; 0 = not known, or flat printed circles): the engine then
  // corrects each detected centre for its cone-beam shadow's offset (ba/shadow_correction.h).
  // Not part of observations.csv's grid line.
  double sphere_diameter_mm = 0;

  int NumPoints() const { return rows * cols; }
  // rows, cols >= 2 (acircles: rows >= 3 ... OpenCV needs >= 2), spacing > 0 and finite, a
  // sphere diameter of 0 or plausible and below the spacing.
  bool Check(std::string* error) const;
  // Plate-frame coordinates of point `id` (mm).
  Eigen::Vector3d PointInPlate(int id) const;
  // PointInPlate of every point, by id: the plate's nominal points.
  std::vector<Eigen::Vector3d> PointsInPlate() const;
};

struct ViewObservations {
  std::string image;                 // source image path (or a label)
  std::vector<int> point_ids;        // into the grid, each at most once
  std::vector<Eigen::Vector2d> uv_px;
};

struct ObservationSet {
  GridSpec grid;
  int width = 0, height = 0;  // image size, px
  std::vector<ViewObservations> views;

  int NumPoints() const;
};

// The engine's view of plate view `view`: its points' ids and pixels, each at `sigma_px`, in
// intrinsics group `group`, starting from `cam_from_plate`. The one translation of a plate view,
// for the calibration (calib/calibrate.h) and the joint problem (joint/joint_solver.h) alike.
ba::BaView ToBaPlateView(const ViewObservations& view,
                         std::string id,
                         int group,
                         const Pose6& cam_from_plate,
                         double sigma_px);

// The plate part of every engine problem: the intrinsics groups, the plate's nominal points (none
// without plate views; held) and the plate views. problem/ba_assembly.h's ToBaProblem builds on
// it; a calibration (calib/calibrate.cc) is this part alone.
ba::BaProblem ToBaPlateProblem(const std::string& name,
                               const ObservationSet& plate,
                               std::vector<ba::IntrinsicsGroup> groups,
                               std::vector<ba::BaView> plate_views);

// Writes observations.csv (atomically).
Status WriteObservationsCsv(const ObservationSet& obs, const std::string& path);
// Reads observations.csv. Errors name file:line and what was expected.
StatusOr<ObservationSet> ReadObservationsCsv(const std::string& path);
// Observations held in memory as a dense array (the Python module's): the pixel of point k of
// view v at uv[2 * (v * grid.NumPoints() + k)] and the next element, (NaN, NaN) where not seen.
// Checked as an observations.csv is: each pixel within plausible::kPixelCoordinatePx, the image
// size integers within plausible::kImageSizePx. Errors name `name[v, k]` or "image_size".
StatusOr<ObservationSet> ObservationsFromArray(const double* uv,
                                               int views,
                                               const GridSpec& grid,
                                               double width,
                                               double height,
                                               const std::string& name);
// mrcal's corners.vnl: "# filename x y level", rows*cols rows per view in row-major order,
// missing points as "filename nan nan -" (level 0 = weight 1).
std::string CornersVnl(const ObservationSet& obs);

}  // namespace carmba
