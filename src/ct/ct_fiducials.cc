#include "ct/ct_fiducials.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <sstream>

#include "report/format.h"
#include "report/plots.h"
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

std::string V3(const Eigen::Vector3d& v, const char* fmt = "%.3f") {
  return "(" + F(fmt, v.x()) + ", " + F(fmt, v.y()) + ", " + F(fmt, v.z()) + ")";
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

std::string Stem(const std::string& path) {
  const std::string ext = ".csv";
  if (path.size() > ext.size() && path.compare(path.size() - ext.size(), ext.size(), ext) == 0) {
    return path.substr(0, path.size() - ext.size());
  }
  return path;
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

std::string FormatFiducialsCsv(const CtFiducialsResult& r) {
  std::ostringstream o;
  o << "# carmba ct-fiducials: spherical marker centres (intensity-weighted centroid over the "
       "partial-volume rim) with covariance\n";
  o << "# dicom: " << r.dicom_dir << " (SeriesInstanceUID " << r.geometry.series_uid << ", "
    << r.geometry.columns << "x" << r.geometry.rows << "x" << r.geometry.slices << " voxels of "
    << F("%.4f", r.geometry.spacing_mm.x()) << " x " << F("%.4f", r.geometry.spacing_mm.y())
    << " x " << F("%.4f", r.geometry.spacing_mm.z()) << " mm)\n";
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
                  "disagreement with the clipped centroid"
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

ReportDoc FiducialsReportDoc(const CtFiducialsResult& r, const std::string& csv_name) {
  const CtVolume& g = r.geometry;
  const auto& d = r.detect_options;
  ReportDoc doc;
  std::vector<std::vector<std::string>> rows;
  doc.Heading(1, "CT fiducials");
  std::string text = "Centres in `" + csv_name + "`. Series `" + r.dicom_dir +
                     "` (SeriesInstanceUID " + g.series_uid + "): " + std::to_string(g.columns) +
                     " x " + std::to_string(g.rows) + " x " + std::to_string(g.slices) +
                     " voxels of " + F("%.4f", g.spacing_mm.x()) + " x " +
                     F("%.4f", g.spacing_mm.y()) + " x " + F("%.4f", g.spacing_mm.z()) +
                     " mm (slice thickness " + F("%.3f", g.slice_thickness_mm) +
                     " mm), slice axes (row, column, stack) " + V3(g.axes.col(0), "%.4f") + ", " +
                     V3(g.axes.col(1), "%.4f") + ", " + V3(g.axes.col(2), "%.4f") +
                     ", first voxel at " + V3(g.origin_mm) + " mm";
  if (r.skipped_files) {
    text += "; " + std::to_string(r.skipped_files) + " non-image file(s) skipped:";
    for (size_t a = 0; a < r.skipped.size() && a < 10; ++a) text += " `" + BaseName(r.skipped[a]) + "`";
    if (r.skipped.size() > 10) text += " ...";
  }
  doc.Paragraph(text + ".");
  doc.Paragraph("Detection: threshold " + F("%.0f", d.threshold_hu) +
                " HU, 26-connected components, metal if the fitted ball HU >= " +
                F("%.0f", d.min_metal_hu) + ", nominal diameter " + F("%.3g", d.diameter_mm) +
                " mm, core volume accepted within " + F("%.2f", d.min_volume_fraction) + " .. " +
                F("%.2f", d.max_volume_fraction) + " x nominal; " +
                std::to_string(r.detection.markers.size()) + " marker(s)" +
                (d.expected_count ? " (expected " + std::to_string(d.expected_count) + ")" : "") +
                ", " + std::to_string(r.detection.rejected.size()) + " component(s) rejected, " +
                std::to_string(r.detection.core_voxels) + " voxels above the threshold. Read " +
                F("%.3f", r.read_seconds) + " s, detection " + F("%.3f", r.detect_seconds) +
                " s." +
                (r.detection.clip_hu > 0
                     ? " The scanner's clip, read from the data: " +
                           F("%.0f", r.detection.clip_hu) + " HU (" +
                           std::to_string(r.detection.clipped_voxels) +
                           " voxels at it); markers clipped there are measured by a surface fit "
                           "to their half-level edge and checked against a clipped centroid."
                     : std::string()));
  doc.Heading(2, "Markers (patient coordinates, mm)");
  doc.Paragraph("Centre: intensity-weighted centroid over the partial-volume rim, or, when bone "
                "or air around the marker pulls it (centroid and robust partial-volume ball fit "
                "disagree beyond their covariances, chi2 > " +
                F("%.2f", d.contamination_chi2) +
                "), the ball fit's centre. BBox: centre of the bounding box of the voxels above "
                "the threshold (the thesis's method), and its distance to the centre. sd: square "
                "roots of the covariance's diagonal. Fit HU: the ball's fitted material HU.");
  for (const auto& m : r.detection.markers) {
    const Eigen::Vector3d sd = m.covariance_mm2.diagonal().cwiseSqrt();
    const std::string from =
        m.saturated
            ? "surface fit, saturated (radii " + F("%.2f", m.surface_radii_mm.x()) + " / " +
                  F("%.2f", m.surface_radii_mm.y()) + " mm; chi2 vs clipped centroid " +
                  F("%.1f", m.contamination_chi2) + ")"
        : m.contaminated ? (m.contamination_chi2 < 0 ? std::string("ball fit (no centroid)")
                                                     : "ball fit (chi2 " +
                                                           F("%.1f", m.contamination_chi2) + ")")
                         : "centroid (chi2 " + F("%.1f", m.contamination_chi2) + ")";
    rows.push_back({std::to_string(m.id), V3(m.centre_mm), from, V3(sd, "%.4f"),
                    V3(m.bbox_centre_mm), F("%.3f", (m.bbox_centre_mm - m.centre_mm).norm()),
                    F("%.3f", m.volume_mm3), F("%.0f", m.peak_hu), F("%.0f", m.fit_metal_hu),
                    F("%.0f", m.background_hu), F("%.1f", m.noise_hu)});
  }
  doc.Table({"id", "centre", "from", "sd (x, y, z)", "bbox centre", "bbox - centre",
             "volume mm^3", "peak HU", "fit HU", "background HU", "noise HU"},
            rows);
  doc.Figures({"markers"});
  if (!r.detection.rejected.empty()) {
    doc.Heading(2, "Rejected components");
    rows.clear();
    for (const auto& c : r.detection.rejected) {
      rows.push_back({V3(c.centroid_mm), F("%.3f", c.volume_mm3), F("%.0f", c.peak_hu), c.reason});
    }
    doc.Table({"centroid (mm)", "volume mm^3", "peak HU", "reason"}, rows);
  }
  doc.Heading(2, "Ids");
  if (r.labelled) {
    std::string t = "Labelled with the model `" + r.model_csv + "` by pairwise distances (" +
                    std::to_string(r.labelling.assignments) + " consistent assignment(s)";
    if (r.candidates > 0) {
      t += "; the " + std::to_string(r.detection.markers.size()) + " markers selected among " +
           std::to_string(r.candidates) + " marker-like candidates, the others listed as rejected";
    }
    t += "); rigid fit model <- CT: RMS " + F("%.4f", r.labelling.rms_mm) + " mm, max " +
         F("%.4f", r.labelling.max_mm) + " mm";
    if (r.labelling.second_best_rms_mm >= 0) {
      t += "; next best assignment RMS " + F("%.3f", r.labelling.second_best_rms_mm) + " mm";
    }
    doc.Paragraph(t + ".");
    rows.clear();
    for (size_t a = 0; a < r.detection.markers.size(); ++a) {
      rows.push_back({std::to_string(r.detection.markers[a].id),
                      F("%.4f", r.labelling.residual_mm[a])});
    }
    doc.Table({"id", "residual mm"}, rows);
  } else {
    doc.Paragraph("No model: markers numbered by increasing patient z, then y, then x.");
  }
  doc.Heading(2, "Frame");
  if (r.has_object_frame) {
    const auto& T = r.object_from_ct;
    doc.Paragraph("The CSV is in the object frame `" + r.frame +
                  "`: p_in_object = object_from_ct * p_in_patient with");
    std::string code = "R = ";
    for (int i = 0; i < 3; ++i) {
      code += std::string(i ? "    " : "") + F("%12.9f", T.R(i, 0)) + " " + F("%12.9f", T.R(i, 1)) +
              " " + F("%12.9f", T.R(i, 2)) + "\n";
    }
    code += "t_mm = " + F("%.6f", T.t.x()) + " " + F("%.6f", T.t.y()) + " " + F("%.6f", T.t.z()) +
            "\n";
    doc.Code(code);
  } else {
    doc.Paragraph("The CSV is in DICOM patient coordinates (LPS, mm).");
  }
  doc.Heading(2, "Covariance model");
  doc.Paragraph(
      "Per marker: voxel noise (the local background's MAD) propagated through the weighted "
      "centroid, the background level's error, and the sub-voxel sampling error of a " +
      F("%.3g", d.diameter_mm) +
      " mm ball box-filtered over each voxel (variance over a uniform sub-voxel phase), "
      "multiplied by max(1, chi2 / 3) when centroid and ball fit disagree more than expected; "
      "for a ball-fit centre, the fit's covariance (its residual scale, at least that of the "
      "voxels the ball's surface cuts) plus the same sampling term" +
      (r.extra_sigma_mm > 0 ? ", plus an isotropic (" + F("%.4g", r.extra_sigma_mm) +
                                  " mm)^2 for what the model leaves out"
                            : std::string()) +
      ". Correlated noise, streaks and beam hardening near metal are not modelled; the frame's "
      "own uncertainty is not added. A saturated marker (at the scanner's clip): the surface "
      "fit's covariance (residual scale of the edge points, counted as one independent point "
      "per voxel area of the surface), multiplied by max(1, chi2 / 3) with chi2 the disagreement "
      "of the clipped centroid and the surface fit over their covariances.");
  return doc;
}

std::string FormatFiducialsReport(const CtFiducialsResult& r, const std::string& csv_name) {
  return FiducialsReportDoc(r, csv_name).Markdown();
}

nlohmann::json FiducialsPlotData(const CtFiducialsResult& r) {
  nlohmann::json items = nlohmann::json::array();
  for (const auto& m : r.detection.markers) {
    items.push_back({{"id", m.id},
                     {"p", {m.centre_mm.x(), m.centre_mm.y(), m.centre_mm.z()}},
                     {"cov", JsonRows(m.covariance_mm2)}});
  }
  return {{"kind", "ct_fiducials"},
          {"markers",
           {{"frame", "CT patient (LPS)"},
            {"items", items},
            {"note", "Located in the CT (the covariance model is in the report)."}}}};
}

Status WriteCtFiducials(const CtFiducialsResult& r,
                        const std::string& out_csv,
                        std::string* report_warning,
                        const PlotSet* plots) {
  const std::string stem = Stem(out_csv);
  const std::string csv = FormatFiducialsCsv(r);
  const ReportFiles report = RenderReport(FiducialsReportDoc(r, BaseName(out_csv)),
                                          "carmba CT fiducials",
                                          plots ? *plots : MakePlots(FiducialsPlotData(r)));
  if (report_warning) *report_warning = report.warning;
  std::string json;
  if (r.has_object_frame) {
    nlohmann::json j;
    const auto& T = r.object_from_ct;
    j["frame"] = r.frame;
    j["R"] = {T.R(0, 0), T.R(0, 1), T.R(0, 2), T.R(1, 0), T.R(1, 1),
              T.R(1, 2), T.R(2, 0), T.R(2, 1), T.R(2, 2)};
    j["t_mm"] = {T.t.x(), T.t.y(), T.t.z()};
    j["comment"] = "p_in_object = R * p_in_patient + t_mm (CT patient coordinates, LPS, mm)";
    json = j.dump(2) + "\n";
  }
  const std::string dir = DirName(out_csv);
  if (!IsDirectory(dir)) return Status::Error(dir + ": output directory does not exist");
  CARMBA_RETURN_IF_ERROR(WriteFileAtomic(out_csv, csv));
  CARMBA_RETURN_IF_ERROR(WriteFileAtomic(stem + ".md", report.markdown));
  CARMBA_RETURN_IF_ERROR(WriteFileAtomic(stem + ".html", report.html));
  if (!json.empty()) CARMBA_RETURN_IF_ERROR(WriteFileAtomic(stem + ".object_from_ct.json", json));
  return Status::Ok();
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
