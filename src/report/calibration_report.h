// The outputs of `carmba calibrate` above the calibration layer: the report (report.md and
// report.html, report/report_doc.h) with its plots (report/plots.h), the detection overlays, and
// the writer of the whole output directory (the files are listed in calib/calib_output.h).
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "calib/calib_output.h"
#include "report/plots.h"
#include "report/report_doc.h"
#include "util/status.h"

namespace carmba {

// The report (report.md and report.html; report/report_doc.h) and its plot data (report/plots.h:
// residuals, distortion, mrcal's projection uncertainty over the image, source positions).
ReportDoc CalibrationReportDoc(const CalibrationRun& run);
nlohmann::json CalibrationPlotData(const CalibrationRun& run);

// Acceptance thresholds of the mrcal cross-check, stated in the report.
constexpr double kMrcalRmsRelTol = 0.01;         // RMS equal within 1 %
constexpr double kMrcalProjectionDiffPx = 0.05;  // projection difference RMS over the image
constexpr double kMrcalSigmaRelTol = 0.10;       // sigmas of fx fy cx cy within 10 %

// camera.json: calib/calib_output.h's CalibrationCameraJson with the engine's shadow correction
// (`shadow_correction`, when the plate's sphere diameter is known).
nlohmann::json CalibrationResultJson(const CalibrationRun& run);

// Writes all files to `out_dir` (see above). `mrcal_work_dir`, if not empty, is copied as
// out_dir/mrcal/ (script, input and output of the cross-check). `plots`: report.html's plots
// drawn beforehand from CalibrationPlotData(run) (PlotProcess); null: drawn here.
Status WriteCalibrationOutputs(const CalibrationRun& run,
                               const std::string& out_dir,
                               const std::string& mrcal_work_dir = "",
                               std::string* report_warning = nullptr,
                               const PlotSet* plots = nullptr);

}  // namespace carmba
