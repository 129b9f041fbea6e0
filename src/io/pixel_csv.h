// The one reader of pixel-observation CSV files: one row per observation, in long format,
//   view,<key>,u_px,v_px[,cov_uu,cov_uv,cov_vv | ,sigma_px]
// (any column order, '#' comment lines; pixel (0,0) is the centre of the top-left pixel). The
// key names what was observed: a marker id (the pose problem's `observations`, the joint
// problem's `object_views.observations`, observations.csv as `carmba pose` writes it) or a point
// name (`carmba triangulate --points`). The covariance columns come all three or none; each
// row's 2x2 must be positive definite (px^2). `sigma_px` (an isotropic sigma per row) is read
// where the caller allows it. Errors name the file, the line and the column.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "util/status.h"

namespace carmba {

struct PixelCsvRow {
  std::string view;
  std::string key;  // the key column's text (PixelCsvColumns::absent_key without the column)
  int id = 0;       // the key as an integer, when PixelCsvColumns::integer_key
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();
  // The row's 2x2 pixel covariance (px^2): from cov_uu, cov_uv, cov_vv, or sigma_px^2 I; zero
  // when the file has neither (the problem's sigma applies).
  Eigen::Matrix2d covariance_px2 = Eigen::Matrix2d::Zero();
  std::string where;  // "file:line"
  bool HasCovariance() const { return covariance_px2(0, 0) > 0; }
};

struct PixelCsvColumns {
  std::string key = "marker";  // the key column's name
  bool key_required = true;    // false: a file without it has one key, absent_key
  std::string absent_key;
  bool integer_key = true;    // the key must be an integer (a marker id)
  bool sigma_column = false;  // read an isotropic `sigma_px` column when there is no covariance
};

// The rows in file order. A file with no rows is not an error here (the callers say what was
// expected of it).
StatusOr<std::vector<PixelCsvRow>> ReadPixelCsv(const std::string& path,
                                                const PixelCsvColumns& columns = {});

}  // namespace carmba
