#include "report/ct_fiducials_report.h"

#include <Eigen/Core>

#include "ct/marker_detection.h"
#include "util/file_util.h"
#include "util/format.h"

namespace carmba {

namespace {

// A 3-vector as "(x, y, z)".
std::string Vec3Text(const Eigen::Vector3d& v, const char* fmt = "%.3f") {
  return FmtTriple(fmt, v.x(), v.y(), v.z());
}

// The output path without its ".csv".
std::string CsvStem(const std::string& path) {
  const std::string ext = ".csv";
  if (path.size() > ext.size() && path.compare(path.size() - ext.size(), ext.size(), ext) == 0) {
    return path.substr(0, path.size() - ext.size());
  }
  return path;
}

// The report's "Covariance model" paragraph: what each marker's covariance is made of.
std::string CovarianceModelText(const CtFiducialsResult& r) {
  const auto& d = r.detect_options;
  return "Per marker: voxel noise (the local background's MAD) propagated through the weighted "
         "centroid, the background level's error, and the sub-voxel sampling error of a " +
         Fmt("%.3g", d.diameter_mm) +
         " mm ball box-filtered over each voxel (variance over a uniform sub-voxel phase), "
         "multiplied by max(1, chi2 / 3) when centroid and ball fit disagree more than expected; "
         "for a ball-fit centre, the fit's covariance (its residual scale, at least that of the "
         "voxels the ball's surface cuts) plus the same sampling term" +
         (r.extra_sigma_mm > 0 ? ", plus an isotropic (" + Fmt("%.4g", r.extra_sigma_mm) +
                                     " mm)^2 for what the model leaves out"
                               : std::string()) +
         ". Correlated noise, streaks and beam hardening near metal are not modelled; the frame's "
         "own uncertainty is not added. A saturated marker (at the scanner's clip): the surface "
         "fit's covariance (residual scale of the edge points, counted as one independent point "
         "per voxel area of the surface) plus the sampling term (with gaps between the slices at "
         "least the fit's own error on simulated clipped balls sampled alike)" +
         (SlicesHaveGaps(r.geometry)
              ? ", widened to cover a delete-one-sector jackknife of the edge fit (this series has "
                "gaps: slices " +
                    Fmt("%.4g", r.geometry.slice_thickness_mm) + " mm thick every " +
                    Fmt("%.4g", r.geometry.spacing_mm.z()) + " mm)"
              : std::string()) +
         ", multiplied by max(1, chi2 / 3) with chi2 the disagreement of the clipped centroid and "
         "the surface fit over their covariances.";
}

}  // namespace

ReportDoc FiducialsReportDoc(const CtFiducialsResult& r, const std::string& csv_name) {
  const CtVolume& g = r.geometry;
  const auto& d = r.detect_options;
  ReportDoc doc;
  std::vector<std::vector<std::string>> rows;
  doc.Heading(1, "CT fiducials");
  std::string text =
      "Centres in `" + csv_name + "`. Series `" + r.dicom_dir + "` (SeriesInstanceUID " +
      g.series_uid + "): " + std::to_string(g.columns) + " x " + std::to_string(g.rows) + " x " +
      std::to_string(g.slices) + " voxels of " + Fmt("%.4f", g.spacing_mm.x()) + " x " +
      Fmt("%.4f", g.spacing_mm.y()) + " x " + Fmt("%.4f", g.spacing_mm.z()) +
      " mm (slice thickness " + Fmt("%.3f", g.slice_thickness_mm) +
      " mm), slice axes (row, column, stack) " + Vec3Text(g.axes.col(0), "%.4f") + ", " +
      Vec3Text(g.axes.col(1), "%.4f") + ", " + Vec3Text(g.axes.col(2), "%.4f") +
      ", first voxel at " + Vec3Text(g.origin_mm) + " mm";
  if (r.skipped_files) {
    text += "; " + std::to_string(r.skipped_files) + " non-image file(s) skipped:";
    for (size_t a = 0; a < r.skipped.size() && a < 10; ++a)
      text += " `" + BaseName(r.skipped[a]) + "`";
    if (r.skipped.size() > 10) text += " ...";
  }
  doc.Paragraph(text + ".");
  for (const auto& w : r.warnings) doc.Warning(w);
  doc.Paragraph("Detection: threshold " + Fmt("%.0f", d.threshold_hu) +
                " HU, 26-connected components, metal if the fitted ball HU >= " +
                Fmt("%.0f", d.min_metal_hu) + ", nominal diameter " + Fmt("%.3g", d.diameter_mm) +
                " mm, core volume accepted within " + Fmt("%.2f", d.min_volume_fraction) + " .. " +
                Fmt("%.2f", d.max_volume_fraction) + " x nominal; " +
                std::to_string(r.detection.markers.size()) + " marker(s)" +
                (d.expected_count ? " (expected " + std::to_string(d.expected_count) + ")" : "") +
                ", " + std::to_string(r.detection.rejected.size()) + " component(s) rejected, " +
                std::to_string(r.detection.core_voxels) + " voxels above the threshold. Read " +
                Fmt("%.3f", r.read_seconds) + " s, detection " + Fmt("%.3f", r.detect_seconds) +
                " s." +
                (r.detection.clip_hu > 0
                     ? " The scanner's clip, read from the data: " +
                           Fmt("%.0f", r.detection.clip_hu) + " HU (" +
                           std::to_string(r.detection.clipped_voxels) +
                           " voxels at it); markers clipped there are measured by a surface fit "
                           "to their half-level edge and checked against a clipped centroid."
                     : std::string()));
  doc.Heading(2, "Markers (patient coordinates, mm)");
  doc.Paragraph(
      "Centre: intensity-weighted centroid over the partial-volume rim, or, when bone "
      "or air around the marker pulls it (centroid and robust partial-volume ball fit "
      "disagree beyond their covariances, chi2 > " +
      Fmt("%.2f", d.contamination_chi2) +
      "), the ball fit's centre; a marker at the scanner's clip: the centre of a "
      "spheroid fitted to its half-level edge (\"surface fit, saturated\", its radii "
      "in-plane / across the slices). BBox: centre of the bounding box of the voxels "
      "above the threshold (the thesis's method), and its distance to the centre. sd: "
      "square roots of the covariance's diagonal. Fit HU: the ball's fitted material "
      "HU (at least the clip for a saturated marker).");
  for (const auto& m : r.detection.markers) {
    const Eigen::Vector3d sd = m.covariance_mm2.diagonal().cwiseSqrt();
    const std::string from =
        m.saturated
            ? "surface fit, saturated (radii " + Fmt("%.2f", m.surface_radii_mm.x()) + " / " +
                  Fmt("%.2f", m.surface_radii_mm.y()) + " mm; chi2 vs clipped centroid " +
                  Fmt("%.1f", m.contamination_chi2) + ")"
        : m.contaminated ? (m.contamination_chi2 < 0 ? std::string("ball fit (no centroid)")
                                                     : "ball fit (chi2 " +
                                                           Fmt("%.1f", m.contamination_chi2) + ")")
                         : "centroid (chi2 " + Fmt("%.1f", m.contamination_chi2) + ")";
    rows.push_back({std::to_string(m.id),
                    Vec3Text(m.centre_mm),
                    from,
                    Vec3Text(sd, "%.4f"),
                    Vec3Text(m.bbox_centre_mm),
                    Fmt("%.3f", (m.bbox_centre_mm - m.centre_mm).norm()),
                    Fmt("%.3f", m.volume_mm3),
                    Fmt("%.0f", m.peak_hu),
                    Fmt("%.0f", m.fit_metal_hu),
                    Fmt("%.0f", m.background_hu),
                    Fmt("%.1f", m.noise_hu)});
  }
  doc.Table({"id", "centre", "from", "sd (x, y, z)", "bbox centre", "bbox - centre",
             "volume mm^3", "peak HU", "fit HU", "background HU", "noise HU"},
            rows);
  doc.Figures({"markers"});
  if (!r.detection.rejected.empty()) {
    doc.Heading(2, "Rejected components");
    rows.clear();
    for (const auto& c : r.detection.rejected) {
      rows.push_back(
          {Vec3Text(c.centroid_mm), Fmt("%.3f", c.volume_mm3), Fmt("%.0f", c.peak_hu), c.reason});
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
    t += "); rigid fit model <- CT: RMS " + Fmt("%.4f", r.labelling.rms_mm) + " mm, max " +
         Fmt("%.4f", r.labelling.max_mm) + " mm";
    if (r.labelling.second_best_rms_mm >= 0) {
      t += "; next best assignment RMS " + Fmt("%.3f", r.labelling.second_best_rms_mm) + " mm";
    }
    doc.Paragraph(t + ".");
    rows.clear();
    for (size_t a = 0; a < r.detection.markers.size(); ++a) {
      rows.push_back({std::to_string(r.detection.markers[a].id),
                      Fmt("%.4f", r.labelling.residual_mm[a])});
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
      code += std::string(i ? "    " : "") + Fmt("%12.9f", T.R(i, 0)) + " " +
              Fmt("%12.9f", T.R(i, 1)) + " " + Fmt("%12.9f", T.R(i, 2)) + "\n";
    }
    code += "t_mm = " + Fmt("%.6f", T.t.x()) + " " + Fmt("%.6f", T.t.y()) + " " +
            Fmt("%.6f", T.t.z()) + "\n";
    doc.Code(code);
  } else {
    doc.Paragraph("The CSV is in DICOM patient coordinates (LPS, mm).");
  }
  doc.Heading(2, "Covariance model");
  doc.Paragraph(CovarianceModelText(r));
  return doc;
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
  const std::string stem = CsvStem(out_csv);
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

}  // namespace carmba
