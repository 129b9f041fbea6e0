#include "report/pose_report.h"

#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>

#include "geometry/rotation.h"
#include "pose/posit.h"
#include "util/format.h"
#include "report/plots.h"
#include "report/relative_tre_report.h"
#include "report/variance_report.h"

namespace carmba {
namespace {

const char* HandName(Handedness h) { return h == Handedness::kMirrored ? "mirrored" : "as_given"; }

}  // namespace

PoseComparison ComparePoseMethods(const Problem& problem,
                                  const SolverConfig& config,
                                  const PoseSolution& solution) {
  PoseComparison c;
  LegacyPositReference ref;
  if (problem.legacy_reference) {
    ref = *problem.legacy_reference;
  } else {
    ref.focal_px = 0.5 * (problem.camera->params[kFx] + problem.camera->params[kFy]);
    ref.cx_px = problem.camera->params[kCx];
    ref.cy_px = problem.camera->params[kCy];
    ref.y_up = false;
  }
  c.legacy_settings = "cvPOSIT (float32, non-orthonormal), focal " + Fmt("%.4f", ref.focal_px) +
                      " px, centre (" + Fmt("%.3f", ref.cx_px) + ", " + Fmt("%.3f", ref.cy_px) +
                      ") px, image y axis " + (ref.y_up ? "up (thesis)" : "down") +
                      ", object frame as given, no distortion";
  std::map<int, Eigen::Vector3d> as_given;
  for (const auto& m : problem.fiducials) as_given[m.id] = m.p_in_object;
  std::map<std::string, Eigen::Matrix3d> legacy_R;
  for (const auto& v : problem.object_views) {
    std::vector<Eigen::Vector3d> pts;
    std::vector<Eigen::Vector2d> img;
    for (const auto& o : v.observations) {
      pts.push_back(as_given.at(o.marker_id));
      img.emplace_back(o.uv_px.x() - ref.cx_px,
                       ref.y_up ? ref.cy_px - o.uv_px.y() : o.uv_px.y() - ref.cy_px);
    }
    PositOptions po;
    po.mode = PositMode::kLegacy;
    auto r = Posit(pts, img, ref.focal_px, po);
    if (!r.ok()) {
      c.legacy_error = "view '" + v.id + "': " + r.status().message();
      c.legacy.clear();
      break;
    }
    LegacyPositView lv;
    lv.id = v.id;
    lv.R = r->R;
    lv.t = r->t;
    double ss = 0;
    for (size_t i = 0; i < pts.size(); ++i) {
      const Eigen::Vector3d q = r->R * (pts[i] - pts[0]) + r->t;
      const Eigen::Vector2d e(ref.focal_px * q.x() / q.z() - img[i].x(),
                              ref.focal_px * q.y() / q.z() - img[i].y());
      ss += e.squaredNorm();
    }
    lv.rms_px = std::sqrt(ss / (2.0 * pts.size()));
    if (problem.reference_rotations.count(v.id)) {
      lv.max_diff_to_reference =
          (r->R - problem.reference_rotations.at(v.id)).cwiseAbs().maxCoeff();
    }
    legacy_R[v.id] = r->R;
    c.legacy.push_back(lv);
  }
  if (c.legacy_error.empty()) {
    for (const auto& p : problem.validation) {
      c.legacy_view_dirs_deg[{p.a, p.b}] =
          ViewDirectionAngleOfMatrices(legacy_R.at(p.a), legacy_R.at(p.b)) * kRadToDeg;
    }
  }
  // The other handedness.
  Problem other = problem;
  other.handedness =
      problem.handedness == Handedness::kMirrored ? Handedness::kAsGiven : Handedness::kMirrored;
  // Both handednesses are compared after the bundle adjustment, also when this config does not
  // refine (its initial poses would be compared with a refined fit otherwise).
  SolverConfig oc = config;
  oc.refine = true;
  auto os = SolvePoseProblem(other, oc);
  if (os.ok()) {
    c.other_handedness = *os;
    double this_rms = solution.ba_result->rms_object_px;
    if (!config.refine) {
      auto refined = SolvePoseProblem(problem, oc);
      this_rms = refined.ok() ? refined->ba_result->rms_object_px : std::nan("");
    }
    if (os->ba_result->rms_object_px * kHandednessWarnRatio < this_rms) {
      c.handedness_warning = std::string("the ") + HandName(other.handedness) +
                             " object frame fits markedly better (RMS " +
                             Fmt("%.3f", os->ba_result->rms_object_px) + " px vs " +
                             Fmt("%.3f", this_rms) + " px with " + HandName(problem.handedness) +
                             ", both after bundle adjustment): check the object frame's "
                             "handedness";
    }
  } else {
    c.other_handedness_error = os.status().message();
  }
  return c;
}

nlohmann::json PoseResultJson(const Problem& problem,
                              const PoseSolution& solution,
                              const PoseComparison& comparison) {
  nlohmann::json j = PoseSolutionToJson(problem, solution);
  j["comparison"] = PoseComparisonToJson(problem, comparison);
  return j;
}

nlohmann::json PoseComparisonToJson(const Problem& problem, const PoseComparison& c) {
  nlohmann::json j;
  nlohmann::json lv = nlohmann::json::array();
  for (const auto& v : c.legacy) {
    nlohmann::json R = nlohmann::json::array();
    for (int i = 0; i < 3; ++i) {
      for (int k = 0; k < 3; ++k) R.push_back(v.R(i, k));
    }
    nlohmann::json e = {{"id", v.id}, {"R", R}, {"t_mm", {v.t.x(), v.t.y(), v.t.z()}},
                        {"rms_px", v.rms_px}};
    if (v.max_diff_to_reference) e["max_abs_diff_to_printed"] = *v.max_diff_to_reference;
    lv.push_back(e);
  }
  nlohmann::json pairs = nlohmann::json::array();
  for (const auto& [k, v] : c.legacy_view_dirs_deg) {
    pairs.push_back({{"a", k.first}, {"b", k.second}, {"angle_view_dirs_deg", v}});
  }
  j["legacy_posit"] = {{"settings", c.legacy_settings},
                       {"views", lv},
                       {"validation", pairs},
                       {"error", c.legacy_error}};
  const Handedness oh =
      problem.handedness == Handedness::kMirrored ? Handedness::kAsGiven : Handedness::kMirrored;
  if (c.other_handedness) {
    j["other_handedness"] = {{"handedness", HandName(oh)},
                             {"rms_px", c.other_handedness->ba_result->rms_object_px},
                             {"warning", c.handedness_warning}};
  } else {
    j["other_handedness"] = {{"handedness", HandName(oh)}, {"error", c.other_handedness_error}};
  }
  return j;
}

namespace {

// The thesis's printed angles and the legacy POSIT comparison are shown where the problem has
// them (the thesis problems: `reference`), not for data that has neither.
bool HasThesisAngles(const Problem& problem) { return !problem.reference_angles_deg.empty(); }
bool HasLegacyReference(const Problem& problem) { return problem.legacy_reference.has_value(); }

// The validation pairs' angles, when the problem has validation pairs.
void PoseValidationDoc(const Problem& problem,
                       const SolverConfig& config,
                       const PoseSolution& s,
                       const PoseComparison& c,
                       const std::string& sigma_used,
                       ReportDoc* doc) {
  if (s.validation.empty()) return;
  ReportDoc& d = *doc;
  d.Heading(2, "Validation: angles between views (deg)");
  d.Paragraph(
      std::string("Viewing-direction angle is the thesis's metric (angle between inv(R_a)(0,0,1) "
                  "and inv(R_b)(0,0,1)); relative rotation is the angle of R_a^T R_b. ") +
      (config.refine ? "Bundle-adjustment values +- 1 sigma propagated from the joint covariance, "
                       "from " + sigma_used + "."
                     : "This config does not refine (refine: false): the values are the "
                       "initializer's, without uncertainty."));
  const bool thesis = HasThesisAngles(problem), legacy = HasLegacyReference(problem);
  const std::string result_column =
      config.refine ? "bundle adjustment"
                    : std::string(NameOf(kInitializerNames, config.initializer));
  std::vector<std::vector<std::string>> rows;
  for (const auto& p : s.validation) {
    const auto key = std::make_pair(p.a, p.b);
    std::string within = "n/a";
    if (p.expected_deg && std::isfinite(p.sigma_view_dirs_deg)) {
      within = std::fabs(p.angle_view_dirs_deg - *p.expected_deg) <= 2 * p.sigma_view_dirs_deg
                   ? "yes"
                   : "no";
    }
    std::vector<std::string> row = {p.a + "-" + p.b,
                                    p.expected_deg ? Fmt("%.1f", *p.expected_deg) : "n/a"};
    if (thesis) {
      const auto it = problem.reference_angles_deg.find(key);
      row.push_back(
          Fmt("%.4f", it != problem.reference_angles_deg.end() ? it->second : std::nan("")));
    }
    if (legacy) {
      const auto it = c.legacy_view_dirs_deg.find(key);
      row.push_back(Fmt("%.4f", it != c.legacy_view_dirs_deg.end() ? it->second : std::nan("")));
    }
    row.push_back(Fmt("%.3f", p.angle_view_dirs_deg) + " +- " + Fmt("%.3f", p.sigma_view_dirs_deg));
    row.push_back(within);
    row.push_back(Fmt("%.3f", p.relative_rotation_deg) + " +- " +
                  Fmt("%.3f", p.sigma_relative_rotation_deg));
    rows.push_back(row);
  }
  std::vector<std::string> header = {"pair", "expected"};
  if (thesis) header.push_back("thesis");
  if (legacy) header.push_back("legacy POSIT");
  for (const std::string& h : {result_column + " (view dirs)", std::string("within 2 sigma"),
                               std::string("relative rotation")}) {
    header.push_back(h);
  }
  d.Table(header, rows);
}

// The reprojection RMS per view: the initializer's and the solution's, legacy POSIT's where the
// problem has a legacy reference, and the other handedness's.
void PoseRmsDoc(const Problem& problem,
                const SolverConfig& config,
                const PoseSolution& s,
                const PoseComparison& c,
                ReportDoc* doc) {
  ReportDoc& d = *doc;
  const bool legacy = HasLegacyReference(problem);
  d.Heading(2, "Reprojection RMS per view (px, per coordinate)");
  std::vector<std::vector<std::string>> rows;
  for (size_t v = 0; v < s.views.size(); ++v) {
    const auto& vs = s.views[v];
    const double other = c.other_handedness ? c.other_handedness->views[v].rms_px : std::nan("");
    std::vector<std::string> row = {vs.id, std::to_string(vs.num_observations)};
    if (legacy) row.push_back(Fmt("%.3f", v < c.legacy.size() ? c.legacy[v].rms_px : std::nan("")));
    for (const std::string& cell :
         {Fmt("%.3f", vs.initial_rms_px), Fmt("%.3f", vs.rms_px), Fmt("%.3f", other)}) {
      row.push_back(cell);
    }
    rows.push_back(row);
  }
  std::vector<std::string> all = {"all", ""};
  if (legacy) all.push_back("");
  all.push_back("");
  all.push_back(Fmt("%.3f", s.ba_result->rms_object_px));
  all.push_back(c.other_handedness ? Fmt("%.3f", c.other_handedness->ba_result->rms_object_px)
                                   : "n/a");
  rows.push_back(all);
  std::vector<std::string> header = {"view", "markers"};
  if (legacy) header.push_back("legacy POSIT");
  header.push_back(std::string("initializer (") + NameOf(kInitializerNames, config.initializer) +
                   ")");
  header.push_back(config.refine ? "bundle adjustment" : "final (not refined)");
  header.push_back("other handedness BA");
  d.Table(header, rows);
  if (legacy) {
    d.Paragraph("Legacy POSIT: " + c.legacy_settings + "." +
                (c.legacy_error.empty() ? "" : " Could not run: " + c.legacy_error + "."));
  }
  d.Figures({"residuals-per-view", "residual-field"});
}

}  // namespace

ReportDoc PoseReportDoc(const Problem& problem,
                        const SolverConfig& config,
                        const PoseSolution& s,
                        const PoseComparison& c) {
  ReportDoc d;
  d.Heading(1, "carmba pose report: " + problem.name);
  d.List({"Problem: `" + problem.path + "`; config: `" + config.name + "` (initializer " +
              NameOf(kInitializerNames, config.initializer) + ", " +
              (config.analytic_jacobians ? "analytic" : "autodiff") + " Jacobians, loss " +
              NameOf(ba::kLossNames, config.loss) + ", " + config.linear_solver + ")",
          "Camera: fx " + Fmt("%.3f", problem.camera->params[kFx]) + ", fy " +
              Fmt("%.3f", problem.camera->params[kFy]) + ", cx " +
              Fmt("%.3f", problem.camera->params[kCx]) + ", cy " +
              Fmt("%.3f", problem.camera->params[kCy]) + " px (held fixed); pixel sigma " +
              Fmt("%.3g", problem.object_sigma_px) + " px; object frame " +
              HandName(problem.handedness),
          "Solver: " + s.termination + " after " + std::to_string(s.ba_result->iterations) +
              " iterations, " + Fmt("%.2f", s.time_s * 1e3) + " ms; cost " +
              Fmt("%.4g", s.ba_result->initial_cost) + " -> " + Fmt("%.4g", s.final_cost)});
  if (!c.handedness_warning.empty()) d.Warning(c.handedness_warning + ".");
  if (!s.converged) {
    d.Warning("the bundle adjustment did not converge (" + s.termination +
              "): the poses, sigmas and verdicts below are not at a minimum.");
  }

  // Which pixel sigma the uncertainties below rest on (said wherever an uncertainty is shown).
  const std::string sigma_used = CovarianceScaleNote(config.covariance_scale) + " (pixel sigma " +
                                 Fmt("%.3g", problem.object_sigma_px) + " px as stated)";
  PoseValidationDoc(problem, config, s, c, sigma_used, &d);
  PoseRmsDoc(problem, config, s, c, &d);

  d.Heading(2, "Poses (cam_from_object) with 1-sigma uncertainty");
  std::vector<std::vector<std::string>> rows;
  d.Paragraph("Sigmas from " + sigma_used + ".");
  for (const auto& vs : s.views) {
    const auto& t = vs.cam_from_object;
    rows.push_back({vs.id, Fmt("%.2f", t[3]) + ", " + Fmt("%.2f", t[4]) + ", " + Fmt("%.2f", t[5]),
                    Fmt("%.3f", vs.sigma_translation_mm[0]) + ", " +
                        Fmt("%.3f", vs.sigma_translation_mm[1]) + ", " +
                        Fmt("%.3f", vs.sigma_translation_mm[2]),
                    Fmt("%.3f", vs.sigma_rotation_deg[0]) + ", " +
                        Fmt("%.3f", vs.sigma_rotation_deg[1]) + ", " +
                        Fmt("%.3f", vs.sigma_rotation_deg[2])});
  }
  d.Table({"view", "t (mm)", "sigma t (mm)", "sigma rotation about camera x, y, z (deg)"}, rows);
  d.Figures({"poses", "markers", "distortion"});
  const std::vector<ba::BudgetRow> budget = PoseErrorBudget(s);
  if (!budget.empty()) d.Append(ErrorBudgetDoc(budget, "Sigmas from " + sigma_used + "."));
  if (!c.legacy.empty() && c.legacy.front().max_diff_to_reference) {
    d.Heading(2, "Legacy POSIT against the printed matrices");
    rows.clear();
    for (const auto& l : c.legacy) {
      rows.push_back({l.id, l.max_diff_to_reference ? Fmt("%.2e", *l.max_diff_to_reference)
                                                    : "n/a"});
    }
    d.Table({"view", "max abs element difference"}, rows);
  }
  d.Heading(2, "Statistics");
  const ba::BaResult& r = *s.ba_result;
  d.List({"Residuals: " + std::to_string(r.num_residuals) +
              " (reprojection and CT prior), free parameters " + std::to_string(r.num_free) +
              ", degrees of freedom " + std::to_string(r.dof),
          "Reprojection RMS " + Fmt("%.3f", s.ba_result->rms_object_px) +
              " px per coordinate; a-posteriori sigma " +
              Fmt("%.3f", r.sigma0 * problem.object_sigma_px) + " px (a-priori " +
              Fmt("%.3f", problem.object_sigma_px) + " px, factor s0 = " + Fmt("%.3f", r.sigma0) +
              ")",
          "Chi-square " + Fmt("%.2f", r.chi2) + " on " + std::to_string(r.dof) +
              " dof, P(X > chi2) = " + Fmt("%.3f", r.chi2_p_value) +
              (r.chi2_p_value < 0.01 ? " (residuals larger than the stated sigmas explain)"
               : r.chi2_p_value > 0.99
                   ? " (residuals smaller than the stated sigmas: sigmas too large?)"
                   : " (consistent with the stated sigmas)"),
          "Covariance: " +
              std::string(NameOf(ba::kCovarianceAlgorithmNames, config.covariance_algorithm)) +
              ", " + CovarianceScaleNote(config.covariance_scale)});
  if (s.ba_result) {
    d.Append(VarianceComponentsDoc(*s.ba_result));
    d.Append(ShadowCorrectionDoc(*s.ba_result));
  }
  {
    const auto warnings = PoseWarnings(s);
    if (warnings.empty()) d.Paragraph("The solve checked itself and found nothing to warn about.");
    for (const auto& w : warnings) d.Warning(w);
  }
  if (s.ba_problem) {
    AppendRelativePoses(&d, *s.ba_problem, s.relative_poses, problem.truth.object_poses);
    d.Paragraph(ba::CalibrationUncertaintyNote(ba::CalibrationUncertaintyOf(*s.ba_problem)));
  }
  if (s.tre) AppendTre(&d, *s.tre);
  return d;
}

nlohmann::json PosePlotData(const Problem& problem, const PoseSolution& s) {
  if (!s.ba_problem || !s.ba_result) return {{"kind", "pose"}};
  const std::vector<ba::BudgetRow> budget = PoseErrorBudget(s);
  nlohmann::json d = BaPlotData(*s.ba_problem, *s.ba_result, &budget);
  d["kind"] = "pose";
  if (!d.contains("image_size") && problem.camera->width > 0) {
    d["image_size"] = {problem.camera->width, problem.camera->height};
  }
  return d;
}

void AppendObjectViews(ReportDoc* d, const std::vector<ObjectView>& views) {
  d->Heading(2, "Marker detection and labelling");
  std::vector<std::vector<std::string>> rows;
  for (const ObjectView& v : views) {
    std::map<std::string, int> reasons;
    for (const RejectedBlob& b : v.detection.rejected) ++reasons[b.why];
    std::string rej;
    for (const auto& [why, k] : reasons)
      rej += (rej.empty() ? "" : ", ") + std::to_string(k) + " " + why;
    if (!v.labelled) {
      rows.push_back({v.id,
                      std::to_string(v.detection.blobs.size()),
                      "skipped: " + v.skipped,
                      "",
                      "",
                      "",
                      "",
                      rej});
      continue;
    }
    int unlabelled = 0;
    for (int id : v.marker_id_of_blob) unlabelled += id < 0;
    rows.push_back({v.id,
                    std::to_string(v.detection.blobs.size()),
                    std::to_string(v.labelling.num_labelled),
                    std::to_string(unlabelled),
                    v.labelling.method,
                    Fmt("%.3g", v.labelling.rms_px),
                    Fmt("%.4f", LargestBlurCorrectionPx(v.detection)),
                    rej});
  }
  d->Table(
      {"view", "blobs", "labelled", "not markers", "method", "RMS px", "blur pull px", "rejected"},
      rows);
  d->Paragraph(
      "Each observation is weighted in the bundle adjustment by its blob's 2x2 covariance "
      "plus the sigma floor squared (the engine whitens it with that covariance). "
      "Each centre has been moved back by the detector blur's pull towards the darker side of "
      "its background (the blur's variance from the image noise's correlation; 'blur pull px' is "
      "the largest per view; `correct_blur_pull: false` keeps the raw centres). "
      "The overlays (`overlay_<view>.png`) show the blobs, labels, reprojected markers and "
      "rejected blobs with their reason.");
}

}  // namespace carmba
