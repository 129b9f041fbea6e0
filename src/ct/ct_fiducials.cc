#include "ct/ct_fiducials.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <sstream>

#include "util/csv.h"
#include "util/file_util.h"
#include "util/plausible.h"

namespace carmba {

namespace {

std::string F(const char* fmt, double v) {
  char b[64];
  std::snprintf(b, sizeof(b), fmt, v);
  return b;
}

bool ParseMarkerFrame(const std::string& frame, int* k) {
  if (frame.rfind("marker:", 0) != 0) return false;
  const std::string s = frame.substr(7);
  if (s.empty() || s.size() > 9) return false;
  for (char c : s) {
    if (c < '0' || c > '9') return false;
  }
  *k = std::stoi(s);
  return true;
}

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

}  // namespace

bool CtFiducialsOptions::Check(std::string* error) const {
  if (!read.Check(error) || !detect.Check(error)) return false;
  if (extra_sigma_mm != 0 &&
      !CheckRange("extra_sigma_mm (0: none)", extra_sigma_mm, plausible::kToleranceMm, error)) {
    return false;
  }
  if (!CheckRange("label_tolerance_mm", label_tolerance_mm, plausible::kToleranceMm, error)) {
    return false;
  }
  int k = 0;
  if (frame != "patient" && frame != "model" && !ParseMarkerFrame(frame, &k)) {
    *error = "frame must be 'patient', 'model' or 'marker:K' (K a marker id), got '" + frame + "'";
    return false;
  }
  if (frame == "model" && model_csv.empty()) {
    *error = "frame 'model' needs a model CSV";
    return false;
  }
  if (!model_columns.empty() && model_columns.size() != 3) {
    *error = "model columns must be 3 names (x, y, z)";
    return false;
  }
  return true;
}

StatusOr<CtFiducialsResult> ComputeCtFiducials(const std::string& dicom_dir,
                                               const CtFiducialsOptions& options) {
  std::string error;
  if (!options.Check(&error)) return Status::Error(error);
  CtFiducialsResult r;
  r.dicom_dir = dicom_dir;
  r.model_csv = options.model_csv;
  r.frame = options.frame;
  if (!options.model_csv.empty()) {
    auto model = ReadModelCsv(options.model_csv, options.model_columns);
    if (!model.ok()) return model.status();
    r.model = std::move(model).value();
  }
  auto t0 = std::chrono::steady_clock::now();
  std::vector<std::string> skipped;
  auto volume = ReadCtSeries(dicom_dir, options.read, &skipped);
  if (!volume.ok()) return volume.status();
  r.read_seconds = Seconds(t0);
  r.skipped_files = static_cast<int>(skipped.size());
  r.skipped = skipped;
  MarkerDetectionOptions detect = options.detect;
  // With a model, the labelling selects the model's markers among the candidates; the expected
  // count (given, or the model's) is checked on the labelled markers.
  int expected = detect.expected_count;
  if (!r.model.empty()) {
    if (expected == 0) expected = static_cast<int>(r.model.size());
    detect.expected_count = 0;
  }
  r.detect_options = detect;
  r.detect_options.expected_count = expected;
  t0 = std::chrono::steady_clock::now();
  auto det = DetectMarkers(*volume, detect);
  if (!det.ok()) return det.status().WithContext(dicom_dir);
  r.detect_seconds = Seconds(t0);
  r.detection = std::move(det).value();
  r.geometry = std::move(volume).value();
  r.geometry.hu.clear();
  r.geometry.hu.shrink_to_fit();
  r.warnings = SliceSamplingWarnings(r.geometry, detect.diameter_mm);

  auto& markers = r.detection.markers;
  r.extra_sigma_mm = options.extra_sigma_mm;
  for (auto& m : markers) {
    m.covariance_mm2 += options.extra_sigma_mm * options.extra_sigma_mm *
                        Eigen::Matrix3d::Identity();
  }
  if (!r.model.empty()) {
    std::vector<Eigen::Vector3d> found;
    for (const auto& m : markers) found.push_back(m.centre_mm);
    auto lab = LabelMarkers(found, r.model, options.label_tolerance_mm);
    if (!lab.ok()) return lab.status().WithContext(dicom_dir + " vs model " + options.model_csv);
    r.labelling = std::move(lab).value();
    r.labelled = true;
    if (r.labelling.selected > 0) {
      // Keep the selected candidates; the others are reported as rejected.
      std::vector<DetectedMarker> kept;
      std::vector<int> index;
      std::vector<double> residual;
      for (size_t a = 0; a < markers.size(); ++a) {
        if (r.labelling.model_index[a] < 0) {
          RejectedComponent rej;
          rej.centroid_mm = markers[a].centre_mm;
          rej.volume_mm3 = markers[a].volume_mm3;
          rej.peak_hu = markers[a].peak_hu;
          rej.voxels = markers[a].core_voxels;
          rej.reason = "a marker-like candidate that does not fit the model's pairwise distances";
          r.detection.rejected.push_back(rej);
          continue;
        }
        kept.push_back(markers[a]);
        index.push_back(r.labelling.model_index[a]);
        residual.push_back(r.labelling.residual_mm[a]);
      }
      r.candidates = static_cast<int>(markers.size());
      markers = kept;
      r.labelling.model_index = index;
      r.labelling.residual_mm = residual;
    }
    if (expected > 0 && static_cast<int>(markers.size()) != expected) {
      return Status::Error(dicom_dir + ": labelled " + std::to_string(markers.size()) +
                           " markers with the model " + options.model_csv + ", expected " +
                           std::to_string(expected));
    }
    for (size_t a = 0; a < markers.size(); ++a) {
      markers[a].id = r.model[r.labelling.model_index[a]].id;
    }
    // Sort markers (and the labelling's per-marker arrays) by id.
    std::vector<size_t> order(markers.size());
    for (size_t a = 0; a < order.size(); ++a) order[a] = a;
    std::sort(order.begin(), order.end(),
              [&](size_t a, size_t b) { return markers[a].id < markers[b].id; });
    std::vector<DetectedMarker> sorted;
    std::vector<int> index;
    std::vector<double> residual;
    for (size_t a : order) {
      sorted.push_back(markers[a]);
      index.push_back(r.labelling.model_index[a]);
      residual.push_back(r.labelling.residual_mm[a]);
    }
    markers = sorted;
    r.labelling.model_index = index;
    r.labelling.residual_mm = residual;
  } else {
    std::sort(markers.begin(), markers.end(), [](const DetectedMarker& a, const DetectedMarker& b) {
      const Eigen::Vector3d &p = a.centre_mm, &q = b.centre_mm;
      if (p.z() != q.z()) return p.z() < q.z();
      if (p.y() != q.y()) return p.y() < q.y();
      return p.x() < q.x();
    });
    for (size_t a = 0; a < markers.size(); ++a) markers[a].id = static_cast<int>(a) + 1;
  }

  int k = 0;
  if (options.frame == "model") {
    r.has_object_frame = true;
    r.object_from_ct = r.labelling.object_from_ct;
  } else if (ParseMarkerFrame(options.frame, &k)) {
    const DetectedMarker* origin = nullptr;
    for (const auto& m : markers) {
      if (m.id == k) origin = &m;
    }
    if (!origin) {
      return Status::Error("frame 'marker:" + std::to_string(k) + "': no marker with id " +
                           std::to_string(k) + " (ids 1.." + std::to_string(markers.size()) +
                           (r.labelled ? ", from the model)" : ")"));
    }
    r.has_object_frame = true;
    r.object_from_ct.R = Eigen::Matrix3d::Identity();
    r.object_from_ct.t = -origin->centre_mm;
  }
  return r;
}

std::vector<std::string> SliceSamplingWarnings(const CtVolume& g, double diameter_mm) {
  if (!SlicesHaveGaps(g) || diameter_mm >= 2 * g.spacing_mm.z()) return {};
  return {"slices " + F("%.4g", g.slice_thickness_mm) + " mm thick every " +
          F("%.4g", g.spacing_mm.z()) + " mm: one or two slices through a " +
          F("%.3g", diameter_mm) +
          " mm marker, too few for its centre across the slices, which may be off by more than "
          "its covariance says; reconstruct the series with contiguous slices (increment <= "
          "thickness)"};
}

std::string FormatFiducialsCsv(const CtFiducialsResult& r) {
  std::ostringstream o;
  o << "# carmba ct-fiducials: spherical marker centres (intensity-weighted centroid over the "
       "partial-volume rim) with covariance\n";
  o << "# dicom: " << r.dicom_dir << " (SeriesInstanceUID " << r.geometry.series_uid << ", "
    << r.geometry.columns << "x" << r.geometry.rows << "x" << r.geometry.slices << " voxels of "
    << F("%.4f", r.geometry.spacing_mm.x()) << " x " << F("%.4f", r.geometry.spacing_mm.y())
    << " x " << F("%.4f", r.geometry.spacing_mm.z()) << " mm"
    << (SlicesHaveGaps(r.geometry) ? "; slices " + F("%.4f", r.geometry.slice_thickness_mm) +
                                         " mm thick: gaps between them"
                                   : std::string())
    << ")\n";
  if (r.has_object_frame) {
    o << "# frame: object (" << r.frame << "); p_in_object = object_from_ct * p_in_patient\n";
    const auto& T = r.object_from_ct;
    o << "# object_from_ct R (row-major):";
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) o << " " << F("%.9f", T.R(i, j));
    }
    o << "\n# object_from_ct t_mm: " << F("%.6f", T.t.x()) << " " << F("%.6f", T.t.y()) << " "
      << F("%.6f", T.t.z()) << "\n";
  } else {
    o << "# frame: patient (DICOM patient coordinates, LPS, mm)\n";
  }
  for (const auto& w : r.warnings) o << "# warning: " << w << "\n";
  if (r.labelled) {
    o << "# ids: labelled with model " << r.model_csv << " (rigid-fit RMS "
      << F("%.4f", r.labelling.rms_mm) << " mm)\n";
  } else {
    o << "# ids: no model; numbered by increasing patient z, then y, then x\n";
  }
  o << "# covariance (mm^2): voxel noise (local MAD) + sub-voxel sampling of a "
    << F("%.3g", r.detect_options.diameter_mm)
    << " mm ball (ball-fit centres where bone or air pulls the centroid: fit covariance + "
       "sampling)"
    << (r.extra_sigma_mm > 0 ? " + (" + F("%.4g", r.extra_sigma_mm) + " mm)^2 I" : "")
    << (r.detection.clip_hu > 0
            ? "; markers at the scanner's clip (" + F("%.0f", r.detection.clip_hu) +
                  " HU, read from the data): surface fit to the half-level edge, widened by its "
                  "disagreement with the clipped centroid" +
                  (SlicesHaveGaps(r.geometry)
                       ? std::string(" and covering a delete-one-sector jackknife of the edge fit "
                                     "(the gaps)")
                       : std::string())
            : std::string())
    << "; frame uncertainty not included. volume_mm3: voxels >= "
    << F("%.0f", r.detect_options.threshold_hu) << " HU\n";
  o << "id,x_mm,y_mm,z_mm,cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz,volume_mm3,peak_hu\n";
  for (const auto& m : r.detection.markers) {
    Eigen::Vector3d p = m.centre_mm;
    Eigen::Matrix3d C = m.covariance_mm2;
    if (r.has_object_frame) {
      p = r.object_from_ct * p;
      C = r.object_from_ct.R * C * r.object_from_ct.R.transpose();
    }
    o << m.id << "," << F("%.5f", p.x()) << "," << F("%.5f", p.y()) << "," << F("%.5f", p.z());
    const double c[6] = {C(0, 0), C(0, 1), C(0, 2), C(1, 1), C(1, 2), C(2, 2)};
    for (double v : c) o << "," << F("%.6e", v);
    o << "," << F("%.4f", m.volume_mm3) << "," << F("%.1f", m.peak_hu) << "\n";
  }
  return o.str();
}

StatusOr<std::vector<CtFiducialRow>> ReadFiducialsCsv(const std::string& path) {
  auto t = ReadCsv(path);
  if (!t.ok()) return t.status();
  const char* cols[] = {"id", "x_mm", "y_mm", "z_mm", "cov_xx", "cov_xy", "cov_xz",
                        "cov_yy", "cov_yz", "cov_zz", "volume_mm3", "peak_hu"};
  for (const char* c : cols) {
    auto col = t->Column(c);
    if (!col.ok()) return col.status();
  }
  std::vector<CtFiducialRow> rows;
  for (int r = 0; r < static_cast<int>(t->rows.size()); ++r) {
    CtFiducialRow f;
    double v[11];
    auto id = t->Integer(r, "id");
    if (!id.ok()) return id.status();
    f.id = *id;
    for (int c = 0; c < 11; ++c) {
      auto x = c < 3 ? t->NumberIn(r, cols[c + 1], plausible::kCoordinateMm)
                     : t->Number(r, cols[c + 1]);
      if (!x.ok()) return x.status();
      v[c] = *x;
    }
    f.p_mm = Eigen::Vector3d(v[0], v[1], v[2]);
    f.covariance_mm2 << v[3], v[4], v[5], v[4], v[6], v[7], v[5], v[7], v[8];
    f.volume_mm3 = v[9];
    f.peak_hu = v[10];
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(f.covariance_mm2);
    if (es.eigenvalues().minCoeff() < -1e-12 * std::max(1.0, es.eigenvalues().maxCoeff())) {
      return Status::Error(path + ":" + std::to_string(t->line_numbers[r]) +
                           ": covariance is not positive semi-definite");
    }
    for (const auto& o : rows) {
      if (o.id == f.id) {
        return Status::Error(path + ":" + std::to_string(t->line_numbers[r]) +
                             ": duplicate id " + std::to_string(f.id));
      }
    }
    rows.push_back(f);
  }
  if (rows.empty()) return Status::Error(path + ": no fiducials");
  return rows;
}

}  // namespace carmba
