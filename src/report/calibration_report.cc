#include "report/calibration_report.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <opencv2/core.hpp>
#include <sstream>

#include "calib/conditioning.h"
#include "calib/crosscheck.h"
#include "calib/projection_uncertainty.h"
#include "calib/truth_check.h"
#include "camera/camera_model.h"
#include "geometry/rotation.h"
#include "io/image_files.h"
#include "report/lens_report.h"
#include "report/overlays.h"
#include "report/variance_report.h"
#include "util/file_util.h"
#include "util/format.h"
#include "util/image_codecs.h"

namespace carmba {

namespace {

// Which pixel sigma the covariance used, as the report says it wherever it shows an uncertainty.
std::string PixelSigmaKind(const CalibrationResult& r) {
  return r.sigma_estimated ? "a-posteriori (estimated from the residuals, sqrt(SSR / dof))"
                           : "a-priori (given: pixel_sigma_px)";
}

// The title, the command and what was solved how.
void CalibrationSummaryDoc(const CalibrationRun& run, ReportDoc* doc) {
  ReportDoc& d = *doc;
  const CalibrationResult& r = run.result;
  const ObservationSet& obs = run.observations;
  const CalibrationOptions& opt = run.options;
  d.Heading(1, "carmba calibration report");
  if (!run.command_line.empty()) d.Paragraph("Command: `" + run.command_line + "`");
  std::string held;
  for (int i = 0; i < kNumIntrinsics; ++i) {
    if (!r.free[i]) held += (held.empty() ? "" : ", ") + std::string(kIntrinsicNames[i]);
  }
  if (opt.fix_aspect_ratio) {
    held += (held.empty() ? "" : "; ") + std::string("fy = ") +
            FmtRoundTrip(r.camera.params[kFy] / r.camera.params[kFx]) + " fx";
  }
  if (held.empty()) held = "none";
  const bool robust = opt.solve.loss != ba::Loss::kTrivial;
  std::string loss =
      "Robust loss: " + std::string(robust ? NameOf(ba::kLossNames, opt.solve.loss) : "none");
  if (robust) loss += " (scale " + Fmt("%g", opt.solve.loss_scale_px) + " px)";
  d.List({"Grid: " + std::string(GridPatternName(obs.grid.pattern)) + " " +
              std::to_string(obs.grid.rows) + " x " + std::to_string(obs.grid.cols) + ", spacing " +
              Fmt("%g", obs.grid.spacing_mm) + " mm; image " + std::to_string(obs.width) + " x " +
              std::to_string(obs.height) + " px",
          "Views used: " + std::to_string(r.views.size()) + ", skipped: " +
              std::to_string(run.skipped.size()) + "; points: " + std::to_string(r.num_points) +
              " (" + std::to_string(2 * r.num_points) + " residuals), free intrinsics: " +
              std::to_string(r.num_free_intrinsics) + ", dof: " + std::to_string(r.dof),
          "Model: LENSMODEL_OPENCV5 [fx, fy, cx, cy, k1, k2, p1, p2, k3]; held: " + held,
          loss + "; solver: " + r.engine->TerminationText() + " after " +
              std::to_string(r.engine->iterations) + " iterations, " +
              Fixed(r.solve_seconds * 1e3, 1) + " ms; covariance " +
              Fixed(r.covariance_seconds * 1e3, 1) + " ms"});
}

// "Images in `DIR/`" when every image lies in one directory ("" otherwise): the tables name the
// images by their ids, and camera.json `views[].image` keeps each path.
std::string ImagesDirectoryNote(const std::vector<std::string>& paths) {
  if (paths.empty()) return "";
  const std::string dir = std::filesystem::path(paths[0]).parent_path().string();
  for (const std::string& p : paths) {
    if (std::filesystem::path(p).parent_path().string() != dir) return "";
  }
  return dir.empty() ? "" : "Images in `" + dir + "/`. ";
}

// Per image: points found, blobs rejected and why; or the images skipped.
void CalibrationDetectionDoc(const CalibrationRun& run, ReportDoc* doc) {
  ReportDoc& d = *doc;
  const ObservationSet& obs = run.observations;
  std::vector<std::vector<std::string>> rows;
  if (!run.detections.empty()) {
    d.Heading(2, "Detection per image");
    std::vector<std::string> paths;
    for (const GridDetection& g : run.detections) paths.push_back(g.view.image);
    const std::vector<std::string> ids = ShortViewIds(paths);
    d.Paragraph(ImagesDirectoryNote(paths) +
                "Overlays (found points with ids, rejected blobs and why): `overlays/`.");
    rows.clear();
    for (size_t i = 0; i < run.detections.size(); ++i) {
      const GridDetection& g = run.detections[i];
      // Rejected blobs by reason ("centre unreliable: background edge (core 0.31 px off)" counts
      // under "centre unreliable: background edge").
      std::map<std::string, int> why;
      for (const RejectedBlob& b : g.rejected) why[b.why.substr(0, b.why.find(" ("))]++;
      std::string rejected = std::to_string(g.rejected.size());
      for (const auto& [reason, count] : why) {
        rejected +=
            (reason == why.begin()->first ? " (" : "; ") + std::to_string(count) + " " + reason;
      }
      if (!why.empty()) rejected += ")";
      rows.push_back({std::to_string(i), ids[i],
                      std::to_string(g.view.uv_px.size()) + " / " +
                          std::to_string(obs.grid.NumPoints()),
                      rejected, g.found ? "used" : "skipped: " + g.reason});
    }
    d.Table({"#", "image", "points found", "rejected blobs (why)", "status"}, rows);
  } else if (!run.skipped.empty()) {
    d.Heading(2, "Skipped images");
    d.List(run.skipped);
  }

}

void CalibrationResidualsDoc(const CalibrationResult& r, ReportDoc* doc) {
  ReportDoc& d = *doc;
  d.Heading(2, "Residuals");
  d.List({"RMS per coordinate: **" + Fixed(r.rms_px) +
              " px** (sqrt(SSR / 2N), mrcal's rms_reproj_error__pixels)",
          "OpenCV's figure sqrt(SSR / N) = sqrt(2) x the above: " + Fixed(r.rms_opencv_px) + " px",
          "Pixel sigma for the covariance: " + Fixed(r.sigma_px) + " px, " + PixelSigmaKind(r)});
  d.Figures({"residuals-per-view", "residual-field"});
  if (r.engine) d.Append(ShadowCorrectionDoc(*r.engine));
}

// The intrinsics with their sigmas, against mrcal (m) and OpenCV (cvr) when they ran.
void CalibrationIntrinsicsDoc(const CalibrationResult& r,
                              const nlohmann::json* m,
                              const OpenCvReference* cvr,
                              ReportDoc* doc) {
  ReportDoc& d = *doc;
  std::vector<std::vector<std::string>> rows;
  d.Heading(2, "Intrinsics (1-sigma marginal over the plate poses)");
  d.Paragraph("Sigmas from the " + PixelSigmaKind(r) + " pixel sigma " + Fixed(r.sigma_px) +
              " px; mrcal's sigmas (its formula, at its own solution) use the same pixel sigma.");
  std::vector<std::string> header = {"", "carmba", "sigma", "initial (closed form)"};
  if (m) {
    for (const char* h : {"mrcal", "mrcal sigma", "sigma ratio carmba/mrcal"}) header.push_back(h);
  }
  if (cvr) {
    header.push_back("OpenCV");
    header.push_back("OpenCV sigma");
  }
  rows.clear();
  for (int i = 0; i < kNumIntrinsics; ++i) {
    std::vector<std::string> row = {kIntrinsicNames[i], FmtRoundTrip(r.camera.params[i]),
                                    r.free[i] ? Fixed(r.sigma[i], 6) : "held",
                                    Fixed(r.initial_intrinsics[i], 4)};
    if (m) {
      const double ms = (*m)["sigma"][i].get<double>();
      row.push_back(FmtRoundTrip((*m)["intrinsics"][i].get<double>()));
      row.push_back(Fixed(ms, 6));
      row.push_back(ms > 0 && r.free[i] ? Fixed(r.sigma[i] / ms, 4) : "-");
    }
    if (cvr) {
      row.push_back(FmtRoundTrip(cvr->intrinsics[i]));
      row.push_back(Fixed(cvr->sigma[i], 6));
    }
    rows.push_back(row);
  }
  d.Table(header, rows);
  d.Figures({"distortion"});
}

void CalibrationConditioningDoc(const CalibrationRun& run, ReportDoc* doc) {
  ReportDoc& d = *doc;
  const CalibrationResult& r = run.result;
  const ConditioningReport cond =
      AssessConditioning(r, run.observations.width, run.observations.height);
  d.Heading(2, "Conditioning");
  std::string text;
  if (cond.warnings.empty()) {
    text = "No warnings: the principal point's sigmas are under " +
           Fixed(100 * kPrincipalPointSigmaWarnFraction, 0) +
           " % of the image, where the linearised covariance matched a seeded Monte Carlo, and "
           "no two intrinsics correlate beyond " + Fixed(kIntrinsicsCorrelationWarn, 2) + ".";
  }
  std::vector<std::string> items;
  for (const auto& w : cond.warnings) items.push_back("WARNING: " + w);
  if (!cond.max_pp_distortion_pair.empty()) {
    const std::string corr = "Largest principal-point / distortion correlation: " +
                             cond.max_pp_distortion_pair + " " +
                             Fixed(cond.max_pp_distortion_correlation, 4) + ".";
    if (cond.warnings.empty()) {
      text += " " + corr;
    } else {
      items.push_back(corr);
    }
  }
  if (!text.empty()) d.Paragraph(text);
  d.List(items);
}

// The projection uncertainty at the centre and the corners, against mrcal's (m).
void CalibrationProjectionDoc(const CalibrationResult& r, const nlohmann::json* m, ReportDoc* doc) {
  ReportDoc& d = *doc;
  std::vector<std::vector<std::string>> rows;
  d.Heading(2, "Projection uncertainty at " + Fixed(r.uncertainty_distance_mm, 1) + " mm");
  d.Paragraph("A point at this range along the pixel's ray, fixed in the frame averaged over the "
              "plate poses (mrcal's definition); 1-sigma, px, from the " + PixelSigmaKind(r) +
              " pixel sigma " + Fixed(r.sigma_px) +
              " px (mrcal's columns: mrcal.projection_uncertainty given the same pixel sigma).");
  std::vector<std::string> header = {
      "where", "pixel", "carmba sigma_u", "carmba sigma_v", "carmba worst"};
  if (m) {
    header.push_back("mrcal formula at carmba's solution");
    header.push_back("mrcal at its solution");
  }
  rows.clear();
  for (size_t k = 0; k < r.projection_sigma.size(); ++k) {
    const auto& p = r.projection_sigma[k];
    std::vector<std::string> row = {p.where,
                                    "(" + Fixed(p.u_px, 1) + ", " + Fixed(p.v_px, 1) + ")",
                                    Fixed(p.sigma_u_px), Fixed(p.sigma_v_px), Fixed(p.worst_px)};
    if (m) {
      double a = NAN, b = NAN;
      for (const auto& e : (*m)["projection_uncertainty_carmba_solution"]) {
        if (e["where"] == p.where && e["worst_px"].is_number()) a = e["worst_px"].get<double>();
      }
      for (const auto& e : (*m)["projection_uncertainty_mrcal"]) {
        if (e["where"] == p.where && e["worst_px"].is_number()) b = e["worst_px"].get<double>();
      }
      row.push_back(Fixed(a));
      row.push_back(Fixed(b));
    }
    rows.push_back(row);
  }
  d.Table(header, rows);
  d.Figures({"projection-uncertainty"});

}

// The rows comparing carmba's solution with one mrcal solution (`sol`: rms_px, sigma[9],
// projection_diff {rms_px, max_px, fitted...}); a threshold missed says `fail`.
std::vector<std::vector<std::string>> MrcalComparisonRows(const CalibrationResult& r,
                                                          const nlohmann::json& sol,
                                                          const nlohmann::json& pdm,
                                                          const std::string& fail) {
  std::vector<std::vector<std::string>> rows;
  const double mrms = sol["rms_px"].get<double>();
  const double rel = (r.rms_px - mrms) / mrms;
  const double pd = pdm["rms_px"].get<double>();
  rows.push_back({"RMS carmba vs mrcal",
                  Fixed(r.rms_px, 6) + " vs " + Fixed(mrms, 6) + " px (" + Fixed(100 * rel, 3) +
                      " %)",
                  "1 %", std::abs(rel) <= kMrcalRmsRelTol ? "pass" : fail});
  rows.push_back({"projection difference (rms / max over a 40-column grid; same observations, "
                  "same camera frame: no transform)",
                  Fixed(pd) + " / " + Fixed(pdm["max_px"].get<double>()) + " px",
                  Fmt("%g", kMrcalProjectionDiffPx) + " px rms",
                  pd < kMrcalProjectionDiffPx ? "pass" : fail});
  if (pdm.contains("fitted_rms_px")) {
    const double fpd = pdm["fitted_rms_px"].get<double>();
    rows.push_back({"projection difference after mrcal's fitted rotation "
                    "(mrcal.projection_diff; the fit's own floor, carmba vs itself: " +
                        Fixed(pdm["fit_floor_rms_px"].get<double>()) + " px)",
                    Fixed(fpd) + " / " + Fixed(pdm["fitted_max_px"].get<double>()) + " px",
                    Fmt("%g", kMrcalProjectionDiffPx) + " px rms",
                    fpd < kMrcalProjectionDiffPx ? "pass" : fail});
  }
  for (int i = 0; i < 4; ++i) {
    const double ms = sol["sigma"][i].get<double>();
    if (!r.free[i] || !(ms > 0)) continue;
    const double q = r.sigma[i] / ms - 1;
    rows.push_back({"sigma " + std::string(kIntrinsicNames[i]) + " carmba vs mrcal",
                    Fixed(r.sigma[i]) + " vs " + Fixed(ms) + " (" + Fixed(100 * q, 2) + " %)",
                    "10 %", std::abs(q) <= kMrcalSigmaRelTol ? "pass" : fail});
  }
  return rows;
}

// The intrinsics carmba held or tied, e.g. "cx cy p1 p2 held, fy = r fx".
std::string HeldIntrinsics(const CalibrationResult& r, const CalibrationOptions& opt) {
  std::array<bool, kNumIntrinsics> free{};
  std::copy(r.free.begin(), r.free.end(), free.begin());
  return HeldIntrinsicsText(free, opt.fix_aspect_ratio);
}

// The mrcal cross-check (m: its output, or null when it did not run).
void MrcalCrossCheckDoc(const CalibrationRun& run, const nlohmann::json* m, ReportDoc* doc) {
  ReportDoc& d = *doc;
  const CalibrationResult& r = run.result;
  const CalibrationOptions& opt = run.options;
  d.Heading(2, "Cross-check: mrcal");
  if (!m) {
    d.Paragraph("Not run: " + run.mrcal_error);
    return;
  }
  const bool same_model =
      r.num_free_intrinsics == kNumIntrinsics && opt.solve.loss == ba::Loss::kTrivial;
  const bool held = m->contains("held") && (*m)["held"].is_object();
  d.Paragraph("mrcal " + (*m)["mrcal_version"].get<std::string>() +
              " (python3-mrcal), LENSMODEL_OPENCV5, no board warp, no regularization, no "
              "outlier rejection, seeded by " +
              (*m)["seed"].get<std::string>() + "; solve " +
              Fixed((*m)["solve_seconds"].get<double>(), 3) + " s.");
  if ((*m).contains("seed_note") && (*m)["seed_note"].is_string()) {
    d.Paragraph("**Seeding**: " + (*m)["seed_note"].get<std::string>() + ".");
  }
  d.Paragraph("mrcal's RMS divides by all rows x cols points of every view (missing points "
              "count as zero residuals); carmba's by the observed points.");
  if (held) {
    const nlohmann::json& h = (*m)["held"];
    d.Paragraph("**Like with like.** carmba's config: " + HeldIntrinsics(r, opt) +
                "; mrcal's optimizer always frees all 9 intrinsics. The same observations are "
                "therefore also solved with carmba's free set on mrcal's own residuals and "
                "Jacobian (Gauss-Newton, " + std::to_string(h["iterations"].get<int>()) +
                " iterations from mrcal's all-free solution): these rows pass or FAIL.");
    d.Table({"check (same free intrinsics)", "value", "threshold", "verdict"},
            MrcalComparisonRows(r, h, h["projection_diff"], "FAIL"));
  }
  if (!same_model) {
    d.Paragraph(std::string(held ? "mrcal with all 9 intrinsics free, for information" :
                                   "**Not the same problem**: carmba used a robust loss; mrcal "
                                   "always estimates all 9 intrinsics without one. The comparison "
                                   "below is for information only") +
                ": a difference beyond a threshold says \"differs (other model)\", not FAIL.");
  }
  // A threshold missed by two different models is no failure of either.
  const std::string fail = same_model ? "FAIL" : "differs (other model)";
  d.Table({"check", "value", "threshold", "verdict"},
          MrcalComparisonRows(r, *m, (*m)["projection_diff"]["mrcal"], fail));
  d.Paragraph("mrcal's RMS evaluated at carmba's solution: " +
              Fixed((*m)["rms_px_of_carmba_solution"].get<double>(), 6) +
              " px. `camera.cameramodel` is carmba's solution with mrcal's optimization inputs "
              "(the same observations), written by mrcal: `mrcal-show-projection-uncertainty "
              "camera.cameramodel` works on it (mrcal estimates the pixel sigma from the "
              "residuals and frees all 9 intrinsics).");
}

// The OpenCV cross-check (cvr, or null when it did not run).
void OpenCvCrossCheckDoc(const CalibrationRun& run,
                         const nlohmann::json* m,
                         const OpenCvReference* cvr,
                         ReportDoc* doc) {
  ReportDoc& d = *doc;
  const CalibrationResult& r = run.result;
  d.Heading(2, "Cross-check: OpenCV calibrateCamera");
  if (!cvr) {
    d.Paragraph("Not run: " + run.opencv_error);
  } else {
    d.Paragraph("Flags: " + cvr->flags_text +
                (cvr->equivalent ? "" : " (NOT equivalent: " + cvr->note + ")") + "; " +
                Fixed(cvr->seconds, 3) + " s.");
    std::vector<std::string> items = {
        "RMS: OpenCV returned " + Fixed(cvr->rms_returned_px, 6) + " px (its sqrt(2) figure) = " +
        Fixed(cvr->rms_px, 6) + " px per coordinate; carmba " + Fixed(r.rms_px, 6) + " px (" +
        Fixed(100 * (r.rms_px - cvr->rms_px) / cvr->rms_px, 3) + " %)"};
    if (m && (*m)["projection_diff"].contains("opencv")) {
      const auto& pdo = (*m)["projection_diff"]["opencv"];
      std::string item = "Projection difference carmba vs OpenCV (same frame, no transform): rms " +
                         Fixed(pdo["rms_px"].get<double>()) + " px, max " +
                         Fixed(pdo["max_px"].get<double>()) + " px";
      if (pdo.contains("fitted_rms_px")) {
        item += "; after mrcal's fitted rotation: rms " +
                Fixed(pdo["fitted_rms_px"].get<double>()) + " px, max " +
                Fixed(pdo["fitted_max_px"].get<double>()) + " px";
      }
      items.push_back(item);
    }
    items.push_back("OpenCV's stdDeviationsIntrinsics are its own estimate (column above); "
                    "OpenCV 4.6's are known to exceed the Monte Carlo spread by 1.5-1.65x.");
    d.List(items);
  }
}

// The estimate against the truth, when the run has one.
void CalibrationTruthDoc(const CalibrationRun& run, ReportDoc* doc) {
  ReportDoc& d = *doc;
  const CalibrationResult& r = run.result;
  std::vector<std::vector<std::string>> rows;
  if (run.truth) {
    d.Heading(2, "Against the truth");
    auto tc = CompareWithTruth(r, *run.truth, run.observations);
    if (!tc.ok()) {
      d.Paragraph("Not compared: " + tc.status().message());
    } else {
      d.Paragraph("The true ray of each pixel of a 21 x 21 grid, projected with the estimate; "
                  "difference per coordinate / its sigma from the intrinsics' covariance "
                  "(marginal over the plate poses). Same camera frame, no fitted transform.");
      rows.clear();
      for (const auto& [name, reg] :
           {std::make_pair("whole image", tc->image),
            std::make_pair("observed region (convex hull of the detections)", tc->observed)}) {
        if (reg.num_pixels == 0) continue;
        rows.push_back({name, std::to_string(reg.num_pixels), Fixed(reg.rms_diff_px),
                        Fixed(reg.max_diff_px), Fixed(reg.max_sigmas, 2),
                        Fixed(100 * reg.fraction_within_3_sigma, 1) + " %", reg.worst});
      }
      d.Table({"region", "pixels", "rms diff px", "max diff px", "max diff / sigma",
               "within 3 sigma", "worst"},
              rows);
      std::string text = "Intrinsics against the truth: ";
      for (int i = 0; i < kNumIntrinsics; ++i) {
        if (!(r.sigma[i] > 0)) continue;
        text += std::string(kIntrinsicNames[i]) + " " +
                Fixed((r.camera.params[i] - run.truth->params[i]) / r.sigma[i], 2) + " sigma" +
                (i + 1 < kNumIntrinsics ? ", " : "");
      }
      d.Paragraph(text);
    }
  }

}

// Per view, per point, the worst residuals and the outliers.
void CalibrationPerViewDoc(const CalibrationRun& run, ReportDoc* doc) {
  ReportDoc& d = *doc;
  const CalibrationResult& r = run.result;
  const ObservationSet& obs = run.observations;
  const CalibrationOptions& opt = run.options;
  std::vector<std::vector<std::string>> rows;
  d.Heading(2, "Per view");
  std::vector<std::string> paths;
  for (const auto& v : r.views) paths.push_back(v.image);
  const std::vector<std::string> ids = ShortViewIds(paths);
  const std::string where = ImagesDirectoryNote(paths);
  if (!where.empty()) d.Paragraph(where);
  rows.clear();
  for (size_t i = 0; i < r.views.size(); ++i) {
    const auto& v = r.views[i];
    rows.push_back({std::to_string(i), ids[i], std::to_string(v.num_points), Fixed(v.rms_px),
                    Fixed(v.max_px), Fixed(v.tilt_deg, 1), Fixed(v.distance_mm, 1)});
  }
  d.Table({"view", "image", "points", "rms px", "max px", "tilt deg", "distance mm"}, rows);
  d.Figures({"poses"});
  d.Heading(2, "Per point");
  rows.clear();
  for (const auto& p : r.points) {
    if (p.num_views == 0) continue;
    rows.push_back({std::to_string(p.point_id), std::to_string(p.point_id / obs.grid.cols),
                    std::to_string(p.point_id % obs.grid.cols), std::to_string(p.num_views),
                    Fixed(p.rms_px)});
  }
  d.Table({"point", "row", "col", "views", "rms px"}, rows);
  d.Heading(2, "Worst residuals");
  rows.clear();
  for (const auto& w : r.worst) {
    rows.push_back({std::to_string(w.view), std::to_string(w.point_id), Fixed(w.du_px),
                    Fixed(w.dv_px), Fixed(w.norm_px)});
  }
  d.Table({"view", "point", "du px", "dv px", "norm px"}, rows);
  d.Heading(2,
            "Outliers (> " + Fmt("%g", opt.solve.outlier_sigma) +
                " sigma = " + Fixed(opt.solve.outlier_sigma * r.sigma_px) + " px)");
  if (r.outliers.empty()) d.Paragraph("None.");
  std::vector<std::string> items;
  for (const auto& w : r.outliers) {
    items.push_back("view " + std::to_string(w.view) + " (" + ids[w.view] + "), point " +
                    std::to_string(w.point_id) + ": " + Fixed(w.norm_px) + " px");
  }
  d.List(items);
}

}  // namespace

ReportDoc CalibrationReportDoc(const CalibrationRun& run) {
  const CalibrationResult& r = run.result;
  ReportDoc d;
  CalibrationSummaryDoc(run, &d);
  CalibrationDetectionDoc(run, &d);
  CalibrationResidualsDoc(r, &d);
  const nlohmann::json* m = run.mrcal ? &*run.mrcal : nullptr;
  const OpenCvReference* cvr = run.opencv ? &*run.opencv : nullptr;
  CalibrationIntrinsicsDoc(r, m, cvr, &d);
  CalibrationConditioningDoc(run, &d);
  CalibrationProjectionDoc(r, m, &d);
  d.Append(DistortionSelectionDoc(r.distortion ? &*r.distortion : nullptr, "", true, ""));
  MrcalCrossCheckDoc(run, m, &d);
  OpenCvCrossCheckDoc(run, m, cvr, &d);
  CalibrationTruthDoc(run, &d);
  CalibrationPerViewDoc(run, &d);
  return d;
}

nlohmann::json CalibrationPlotData(const CalibrationRun& run) {
  const CalibrationResult& r = run.result;
  const ObservationSet& obs = run.observations;
  nlohmann::json d = {{"kind", "calibration"}, {"image_size", {obs.width, obs.height}}};
  nlohmann::json views = nlohmann::json::array(), sources = nlohmann::json::array();
  for (size_t v = 0; v < obs.views.size() && v < r.cam_from_plate.size(); ++v) {
    const auto& ov = obs.views[v];
    const double* pose = r.cam_from_plate[v].data();
    nlohmann::json u = nlohmann::json::array(), vv = nlohmann::json::array(),
                   du = nlohmann::json::array(), dv = nlohmann::json::array();
    for (size_t k = 0; k < ov.point_ids.size(); ++k) {
      const Eigen::Vector3d p = obs.grid.PointInPlate(ov.point_ids[k]);
      double uv[2];
      if (!ProjectPoint(r.camera.params.data(), pose, p.data(), uv)) continue;
      u.push_back(ov.uv_px[k].x());
      vv.push_back(ov.uv_px[k].y());
      du.push_back(uv[0] - ov.uv_px[k].x());
      dv.push_back(uv[1] - ov.uv_px[k].y());
    }
    views.push_back({{"id", std::to_string(v)},
                     {"kind", "plate"},
                     {"rms_px", v < r.views.size() ? JsonNumber(r.views[v].rms_px) : nullptr},
                     {"u", u},
                     {"v", vv},
                     {"du", du},
                     {"dv", dv}});
    const Eigen::Vector3d rvec(pose[0], pose[1], pose[2]), t(pose[3], pose[4], pose[5]);
    const Eigen::Vector3d source = -RotationOf(rvec).transpose() * t;
    sources.push_back({{"id", std::to_string(v)}, {"p", {source.x(), source.y(), source.z()}}});
  }
  d["residual_views"] = views;
  nlohmann::json pts = nlohmann::json::array();
  for (const Eigen::Vector3d& p : obs.grid.PointsInPlate()) pts.push_back({p.x(), p.y(), p.z()});
  d["scenes"] = {{{"name", "plate"},
                  {"frame", "plate"},
                  {"pose_name", "cam_from_plate"},
                  {"points_label", "plate points"},
                  {"points", pts},
                  {"sources", sources}}};
  d["cameras"] = {{{"name", "the camera"},
                   {"intrinsics", std::vector<double>(r.camera.params.begin(),
                                                      r.camera.params.end())}}};
  // mrcal's projection uncertainty over a 32 x 24 grid of the image.
  constexpr int kNx = 32, kNy = 24;
  std::vector<Eigen::Vector2d> pixels;
  for (int y = 0; y < kNy; ++y) {
    for (int x = 0; x < kNx; ++x) {
      pixels.emplace_back((obs.width - 1) * x / double(kNx - 1),
                          (obs.height - 1) * y / double(kNy - 1));
    }
  }
  auto sig = ProjectionUncertainties(obs, r, pixels, r.uncertainty_distance_mm);
  if (sig.ok() && obs.width > 0) {
    nlohmann::json u = nlohmann::json::array(), v = nlohmann::json::array(),
                   w = nlohmann::json::array();
    for (const auto& p : *sig) {
      u.push_back(p.u_px);
      v.push_back(p.v_px);
      w.push_back(JsonNumber(p.worst_px));
    }
    d["projection_uncertainty"] = {
        {{"name", "the camera"},
         {"distance_mm", r.uncertainty_distance_mm},
         {"definition",
          "1-sigma uncertainty (worst direction, px) of the projection of a point at " +
              Fixed(r.uncertainty_distance_mm, 0) +
              " mm along each pixel's ray, fixed in the frame averaged over the plate poses "
              "(mrcal's definition), from the " +
              std::string(r.sigma_estimated ? "a-posteriori" : "a-priori") + " pixel sigma " +
              Fixed(r.sigma_px, 3) + " px."},
         {"nx", kNx},
         {"ny", kNy},
         {"u", u},
         {"v", v},
         {"worst_px", w}}};
  }
  return d;
}

nlohmann::json CalibrationResultJson(const CalibrationRun& run) {
  nlohmann::json j = CalibrationCameraJson(run);
  if (run.result.engine) {
    if (nlohmann::json s = ShadowCorrectionJson(*run.result.engine); !s.is_null()) {
      j["shadow_correction"] = s;
    }
  }
  return j;
}

Status WriteCalibrationOutputs(const CalibrationRun& run,
                               const std::string& out_dir,
                               const std::string& mrcal_work_dir,
                               std::string* report_warning,
                               const PlotSet* plots) {
  namespace fs = std::filesystem;
  // Staged beside out_dir when it does not exist, inside it when it does (file_util.h): the
  // final renames never cross file systems, even when out_dir is a mount point.
  StagedOutputDir staged(out_dir);
  CARMBA_RETURN_IF_ERROR(staged.Begin());
  const std::string& tmp = staged.path();
  std::error_code ec;
  const ReportFiles report =
      RenderReport(CalibrationReportDoc(run), "carmba calibration report",
                   plots ? *plots : MakePlots(CalibrationPlotData(run)));
  if (report_warning) *report_warning = report.warning;
  // camera.cameramodel: with the mrcal cross-check, the model mrcal itself wrote from carmba's
  // solution and the same observations, with its optimization_inputs (mrcal's uncertainty tools
  // read them: mrcal-show-projection-uncertainty camera.cameramodel); without, the plain model.
  std::string cameramodel = MrcalCameraModelText(run.result);
  const std::string with_inputs =
      JoinPath(mrcal_work_dir, "camera_with_optimization_inputs.cameramodel");
  if (!mrcal_work_dir.empty() && FileExists(with_inputs)) {
    auto text = ReadFile(with_inputs);
    if (!text.ok()) return text.status();
    // mrcal prints 10 significant digits; carmba's intrinsics go in at full precision (the
    // optimization_inputs blob holds them in binary already).
    const std::string key = "'intrinsics': [";
    const size_t a = text->find(key);
    const size_t b = a == std::string::npos ? a : text->find(']', a);
    if (b == std::string::npos) return Status::Error(with_inputs + ": no 'intrinsics' list");
    std::string list;
    for (double v : run.result.camera.params) list += " " + FmtRoundTrip(v) + ",";
    cameramodel = text->substr(0, a + key.size()) + list + text->substr(b);
  }
  const std::pair<std::string, std::string> files[] = {
      {"camera.json", CalibrationResultJson(run).dump(2) + "\n"},
      {"camera.cameramodel", cameramodel},
      {"camera_opencv.yml", OpenCvCalibrationYaml(run)},
      {"corners.vnl", CornersVnl(run.observations)},
      {"report.md", report.markdown},
      {"report.html", report.html}};
  for (const auto& [name, text] : files) {
    CARMBA_RETURN_IF_ERROR(WriteFileAtomic(JoinPath(tmp, name), text));
  }
  CARMBA_RETURN_IF_ERROR(WriteObservationsCsv(run.observations, JoinPath(tmp, "observations.csv")));
  if (!run.detections.empty()) {
    const std::string dir = JoinPath(tmp, "overlays");
    CARMBA_RETURN_IF_ERROR(MakeDirs(dir));
    for (size_t i = 0; i < run.detections.size(); ++i) {
      const GridDetection& d = run.detections[i];
      auto image = ReadImageFile(d.view.image);
      if (!image.ok()) return image.status();
      std::string stem = fs::path(d.view.image).stem().string();
      for (char& c : stem) {
        if (c == '#') c = '_';  // a frame of a multi-frame DICOM file
      }
      char prefix[32];
      std::snprintf(prefix, sizeof(prefix), "%03zu_", i);
      const std::string path = JoinPath(dir, prefix + stem + ".png");
      try {
        if (!ImWrite(path, DrawDetectionOverlay(*image, run.observations.grid, d))) {
          return Status::Error(path + ": cannot write the overlay");
        }
      } catch (const cv::Exception& e) {
        return Status::Error(path + ": cannot write the overlay: " + e.what());
      }
    }
  }
  if (!mrcal_work_dir.empty() && IsDirectory(mrcal_work_dir)) {
    fs::copy(mrcal_work_dir, JoinPath(tmp, "mrcal"), fs::copy_options::recursive, ec);
    if (ec) return Status::Error("copying " + mrcal_work_dir + ": " + ec.message());
  }
  // Into place; an existing out_dir keeps its other files, a previous mrcal/ is replaced.
  CARMBA_RETURN_IF_ERROR(staged.Commit(/*replace_all=*/false));
  return Status::Ok();
}

}  // namespace carmba
