// The data of an object view as every reader hands it on: the markers (CT fiducials) in the
// object frame, and per view the markers' pixels with their noise. The one form of an object view
// between the readers (io/pixel_csv.h, detect/marker_views.h ToPoseViews, the problem loader
// problem/problem.h) and the engine (problem/ba_assembly.h ToBaObjectView).
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "util/status.h"

namespace carmba {

struct Marker {
  int id = 0;
  Eigen::Vector3d p_in_object;  // as measured (CT), mm; before any mirroring
  Eigen::Matrix3d covariance;   // mm^2
};

struct Observation {
  int marker_id = 0;
  Eigen::Vector2d uv_px;
  // This observation's pixel sigma (px, per coordinate); 0 = the problem's sigma_px. Set for
  // detected marker blobs (detect/marker_views.h).
  double sigma_px = 0;
  // Its full 2x2 pixel covariance (px^2); zero = none (isotropic sigma_px). Detected blobs carry
  // one, as do observations.csv files with columns cov_uu, cov_uv, cov_vv. The bundle adjustment
  // whitens by it in full.
  Eigen::Matrix2d covariance_px2 = Eigen::Matrix2d::Zero();
  bool HasCovariance() const { return covariance_px2(0, 0) > 0; }
};

// An object view: the markers seen in one image.
struct PoseView {
  std::string id;
  std::vector<Observation> observations;
};

// Reads markers (fiducials) from a CSV: ids in `id_column`, positions (mm) in `columns`, and the
// covariance from the columns cov_xx, cov_xy, cov_xz, cov_yy, cov_yz, cov_zz (mm^2, as `carmba
// ct-fiducials` writes them) or, when sigma_mm > 0, isotropic sigma_mm. Without either the error
// names `sigma_key`. Errors name file:line.
StatusOr<std::vector<Marker>> ReadMarkersCsv(const std::string& path,
                                             const std::string& id_column,
                                             const std::vector<std::string>& columns,
                                             double sigma_mm,
                                             const std::string& sigma_key);

}  // namespace carmba
