// Comparisons and the markdown report of a pose solve (`carmba solve`).
//
// Besides the bundle adjustment, the report shows what the thesis's method gives on the same
// data (legacy POSIT, reproduced as cvPOSIT computed it) and the fit under the other object-frame
// handedness, so a user sees (a) how much the bundle adjustment improves on the thesis and (b)
// whether the object frame's handedness is right.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "ba/quantities.h"
#include "detect/marker_views.h"
#include "problem/pose_solver.h"
#include "report/report_doc.h"

namespace carmba {

struct LegacyPositView {
  std::string id;
  Eigen::Matrix3d R;       // as cvPOSIT returns it (rows not exactly orthogonal)
  Eigen::Vector3d t;       // reference marker (first observed) in the legacy camera, mm
  double rms_px = 0;       // per-coordinate reprojection RMS in the legacy model
  std::optional<double> max_diff_to_reference;  // vs the printed matrix, if any
};

struct PoseComparison {
  // Legacy POSIT with the problem's `reference.legacy_posit` settings (the thesis's single focal
  // length, centre and y-up image axis) or, without them, with (fx+fy)/2, (cx, cy), y down.
  std::vector<LegacyPositView> legacy;
  std::map<std::pair<std::string, std::string>, double> legacy_view_dirs_deg;
  std::string legacy_settings;  // a one-line description
  std::string legacy_error;     // why legacy POSIT could not run, if it could not
  // The same bundle adjustment under the other handedness.
  std::optional<PoseSolution> other_handedness;
  std::string other_handedness_error;
  std::string handedness_warning;  // non-empty when the other handedness fits markedly better
};

// Ratio of RMS above which the other handedness is said to fit markedly better.
constexpr double kHandednessWarnRatio = 1.5;

PoseComparison ComparePoseMethods(const Problem& problem,
                                  const SolverConfig& config,
                                  const PoseSolution& solution);

nlohmann::json PoseComparisonToJson(const Problem& problem, const PoseComparison& c);

// result.json (the schema in the foundation issue: views[], validation[], statistics, solver);
// report/pose_json.cc (an output beside report.md, so it sits with the reports).
nlohmann::json PoseSolutionToJson(const Problem& problem, const PoseSolution& solution);

// result.json as `carmba solve` writes it for a pose problem: PoseSolutionToJson with the
// comparison (legacy POSIT, the other handedness) under "comparison". The CLI and the Python
// module (src/python/) both write it through this.
nlohmann::json PoseResultJson(const Problem& problem,
                              const PoseSolution& solution,
                              const PoseComparison& comparison);

// The report (report.md and report.html) and its plot data (report/plots.h).
ReportDoc PoseReportDoc(const Problem& problem,
                        const SolverConfig& config,
                        const PoseSolution& solution,
                        const PoseComparison& comparison);
nlohmann::json PosePlotData(const Problem& problem, const PoseSolution& solution);

// The report's section on the marker detection and labelling of views read from images
// (`carmba pose --images`): per view the blobs, the markers labelled, the rejected candidates.
void AppendObjectViews(ReportDoc* doc, const std::vector<ObjectView>& views);

// The error budget of a pose solve (ba/quantities.h): the poses and the validation pairs (rows
// without a sigma, such as the held intrinsics' centre projection, left out); empty without the
// engine's covariance.
std::vector<ba::BudgetRow> PoseErrorBudget(const PoseSolution& solution);

}  // namespace carmba
