// Reading the markers CSV (io/object_views.h).
#include "io/object_views.h"

#include <Eigen/Eigenvalues>
#include <cmath>
#include <set>

#include "util/csv.h"
#include "util/plausible.h"

namespace carmba {

StatusOr<std::vector<Marker>> ReadMarkersCsv(const std::string& path,
                                             const std::string& id_column,
                                             const std::vector<std::string>& columns,
                                             double sigma_mm,
                                             const std::string& sigma_key) {
  auto t = ReadCsv(path);
  if (!t.ok()) return t.status();
  const char* cov_cols[6] = {"cov_xx", "cov_xy", "cov_xz", "cov_yy", "cov_yz", "cov_zz"};
  const bool has_cov = t->Column("cov_xx").ok();
  if (!has_cov && !(sigma_mm > 0)) {
    return Status::Error(sigma_key +
                         ": missing: give the CT sigma or covariance columns "
                         "cov_xx..cov_zz in " +
                         path);
  }
  std::vector<Marker> markers;
  std::set<int> ids;
  for (size_t r = 0; r < t->rows.size(); ++r) {
    Marker mk;
    auto id = t->Integer(r, id_column);
    if (!id.ok()) return id.status();
    mk.id = *id;
    if (!ids.insert(mk.id).second) {
      return Status::Error(path + ":" + std::to_string(t->line_numbers[r]) + ": marker id " +
                           std::to_string(mk.id) + " appears twice");
    }
    for (int c = 0; c < 3; ++c) {
      auto v = t->NumberIn(r, columns[c], plausible::kCoordinateMm);
      if (!v.ok()) return v.status();
      mk.p_in_object[c] = *v;
    }
    if (sigma_mm > 0) {
      mk.covariance = Eigen::Matrix3d::Identity() * sigma_mm * sigma_mm;
    } else {
      double c6[6];
      for (int k = 0; k < 6; ++k) {
        auto v = t->Number(r, cov_cols[k]);
        if (!v.ok()) return v.status();
        c6[k] = *v;
      }
      mk.covariance << c6[0], c6[1], c6[2], c6[1], c6[3], c6[4], c6[2], c6[4], c6[5];
      for (int k : {0, 3, 5}) {  // the variances: their square roots are sigmas in mm
        const double sigma = c6[k] >= 0 ? std::sqrt(c6[k]) : c6[k];
        if (!InRange(sigma, plausible::kCtSigmaMm)) {
          return Status::Error(path + ":" + std::to_string(t->line_numbers[r]) + ": column '" +
                               cov_cols[k] + "': expected a variance whose square root is " +
                               FormatRange(plausible::kCtSigmaMm) + ", got " +
                               FormatCompact(c6[k]));
        }
      }
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(mk.covariance);
      if (!(es.eigenvalues().minCoeff() > 0)) {
        return Status::Error(path + ":" + std::to_string(t->line_numbers[r]) +
                             ": marker covariance is not positive definite");
      }
    }
    markers.push_back(mk);
  }
  if (markers.empty()) return Status::Error(path + ": no markers");
  return markers;
}

}  // namespace carmba
