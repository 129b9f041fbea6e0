// The plots of report.html, drawn by matplotlib: scripts/report_plots.py (embedded in the
// library, so any working directory works) run with /usr/bin/python3 on a JSON of the data a
// command gathered (the keys are listed at the top of the script). Plus the gatherers shared by
// the pose and joint solves (ba/ engine results), and the report writer used by every command.
//
// Plot generation never fails a command: without python3 or matplotlib, or when the script
// errs, the report still gets written, report.html says why it has no plots, and the caller
// prints the one-line warning in ReportFiles::warning.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "ba/bundle_adjuster.h"
#include "ba/quantities.h"
#include "report/report_doc.h"

namespace carmba {

// The embedded scripts/report_plots.py (generated at configure time, src/CMakeLists.txt).
const char* ReportPlotsScript();

class PythonWorker;

struct PlotOptions {
  std::string python = "/usr/bin/python3";  // Debian's, which has python3-matplotlib
  int timeout_s = 120;
  bool enabled = true;  // false (--no-plots): no Python at all; report.html says why
};

struct PlotSet {
  std::vector<ReportPlot> plots;
  std::vector<std::string> notes;  // plots not drawn for want of data, and why
  std::string unavailable;         // non-empty: no plots at all, and why (one line)
  std::vector<std::string> errors; // plots that failed (a bug), "function: exception"
  bool disabled = false;           // not asked for (--no-plots): no warning
  double seconds = 0;              // the plot interpreter's wall time (start to result)
};

// All plots of one report drawn by one Python interpreter that starts (and imports matplotlib)
// when this is constructed: construct it before the work whose results it plots, Draw when the
// data is ready (returns at once; the drawing overlaps what the caller does next) and take the
// Result when writing the report. Never fails (see above).
class PlotProcess {
 public:
  explicit PlotProcess(const PlotOptions& options = {});
  ~PlotProcess();
  PlotProcess(const PlotProcess&) = delete;
  PlotProcess& operator=(const PlotProcess&) = delete;
  // Hands `data` (`data["kind"]` says which plots) to the interpreter. Once.
  void Draw(const nlohmann::json& data);
  // Waits for the plots (an empty set with `unavailable` if Draw was not called).
  PlotSet Result();

 private:
  PlotOptions options_;
  std::unique_ptr<PythonWorker> worker_;
  std::string dir_;    // scratch directory of the script, its input, output and stderr
  int dir_slot_ = -1;  // its registration with util/temp_paths.h
  PlotSet set_;        // filled by Draw on failure, by Result otherwise
  bool drawn_ = false;
  bool done_ = false;
};

// PlotProcess's Draw and Result at once.
PlotSet MakePlots(const nlohmann::json& data, const PlotOptions& options = {});

// report.md and report.html of one report, and the warning to print if the plots are missing.
struct ReportFiles {
  std::string markdown;
  std::string html;
  std::string warning;  // "" or one line, e.g. "report.html has no plots: matplotlib is not ..."
};
ReportFiles RenderReport(const ReportDoc& doc,
                         const std::string& title,
                         const nlohmann::json& plot_data,
                         const PlotOptions& options = {});
// The same with plots drawn beforehand (PlotProcess::Result).
ReportFiles RenderReport(const ReportDoc& doc, const std::string& title, const PlotSet& plots);

// 1-sigma projection uncertainty (worst direction, px) over an nx x ny pixel grid of a camera
// whose intrinsics have covariance `cov` (9 x 9, LENSMODEL_OPENCV5 order, zero rows for held
// ones): the point at `distance_mm` along each pixel's ray, fixed in the camera frame, projected
// with the uncertain intrinsics, Cov(q) = J_q C J_q^T (intrinsics only: the calibration's own
// uncertainty, as ba/quantities.h's centre projection). Pixels that cannot be unprojected get NaN.
// Returns {name, distance_mm, definition, nx, ny, u[], v[], worst_px[]} for the script.
nlohmann::json IntrinsicsProjectionUncertainty(const std::string& name,
                                               const double* intrinsics,
                                               const Eigen::MatrixXd& cov,
                                               int width,
                                               int height,
                                               double distance_mm,
                                               int nx = 32,
                                               int ny = 24);

// The plot data of a solved bundle adjustment: residual_views (per view, at the solution),
// scenes (source positions of plate views in the plate frame and of object views in the object
// frame), markers (with covariance, when estimated), cameras, projection_uncertainty (per group
// with free intrinsics) and, if given, budget. `image_size` from the first group that has one.
nlohmann::json BaPlotData(const ba::BaProblem& problem,
                          const ba::BaResult& result,
                          const std::vector<ba::BudgetRow>* budget);

}  // namespace carmba
