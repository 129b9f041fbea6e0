// The outputs of a joint solve (joint/joint_solver.h) above the engine: result.json,
// geometry.json's content, report.md / report.html and the report's plot data, the C-arm flex
// sections (flex_report.cc) and the mrcal cross-check's section.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "export/view_geometry.h"
#include "joint/joint_solver.h"
#include "report/report_doc.h"

namespace carmba {

nlohmann::json JointSolutionToJson(const Problem& problem,
                                   const SolverConfig& config,
                                   const JointSolution& solution);
// geometry.json's content (export/view_geometry.h): the object views, each with the
// intrinsics of its group (the full model) and its cam_from_object (the object frame is the CT
// frame of the fiducials); the reference point the fiducials' centroid.
GeometrySet JointSolutionGeometry(const Problem& problem, const JointSolution& solution);

// The report (report.md and report.html; report/report_doc.h) and its plot data (report/plots.h).
ReportDoc JointReportDoc(const Problem& problem,
                         const SolverConfig& config,
                         const JointSolution& solution);
nlohmann::json JointPlotData(const JointSolution& solution);
// Warnings about the solution, one sentence each (in the report, in result.json "warnings" and on
// stderr): intrinsics of a group that correlate beyond kIntrinsicsCorrelationWarn
// (calib/conditioning.h).
std::vector<std::string> JointWarnings(const JointSolution& solution);

// The report's section on the cross-check (its JSON as JointMrcalCrossCheck returns it, or
// {"error": ...}).
ReportDoc JointMrcalDoc(const nlohmann::json& crosscheck);

// C-arm flex (flex_report.cc): every view's intrinsics (at its angles, with covariance, as
// camera.json writes them) into result.json's views, the smooth model's coefficients and
// covariance ("intrinsics_model"), the model selection ("model_selection") and the intrinsics
// along the primary angle with their sigma ("intrinsics_curve", for the plot).
void AddFlexJson(const Problem& problem, const JointSolution& solution, nlohmann::json* j);
nlohmann::json FlexModelJson(const JointSolution& solution);
// The report's sections on the intrinsics per view (against the truth when it has them) and on
// the model selection, with the place of the plot "intrinsics-vs-angle" (report.html).
ReportDoc FlexReportDoc(const Problem& problem, const JointSolution& solution);
// The plot's data from result.json (AddFlexJson's keys) into the report's plot data
// ("intrinsics_vs_angle", drawn by scripts/report_plots.py); nothing without angles.
void AddFlexPlotData(const nlohmann::json& result, nlohmann::json* plot_data);

}  // namespace carmba
