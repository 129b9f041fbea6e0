// `carmba ct-fiducials --dicom DIR [--model markers.csv] [--diameter_mm 2] [--expected 9]
//  [--frame patient|model|marker:K] --out fiducials.csv`: marker centres with covariance from a
// DICOM CT series (ct/ct_fiducials.h). Writes the CSV, a report beside it (<stem>.md, and
// <stem>.html with the markers' covariance ellipsoids)
// and, with an object frame, <stem>.object_from_ct.json. Nothing is written on error.
#include <gflags/gflags.h>

#include <cstdio>
#include <iostream>
#include <sstream>

#include "cli/command.h"
#include "cli/common_flags.h"
#include "ct/ct_fiducials.h"
#include "report/ct_fiducials_report.h"
#include "report/plots.h"
#include "util/file_util.h"

DEFINE_string(dicom, "", "Directory of the DICOM CT series (files in any order, any names).");
DEFINE_string(series_uid, "", "SeriesInstanceUID to read when the directory mixes several series.");
DEFINE_string(model, "", "Model CSV of nominal marker positions (id or marker column, x/y/z "
                         "columns): labels the markers by pairwise distances.");
DEFINE_string(model_columns, "", "Model coordinate columns, e.g. 'x_o,y_o,z_o' (default: the "
                                 "first of x_mm.., x.., x_o.., x_ct.. present).");
DEFINE_double(diameter_mm, 2.0, "Nominal marker diameter, mm.");
DEFINE_int32(expected, 0, "Number of markers expected (0: the model's count, or any).");
DEFINE_double(threshold_hu, 1500, "HU threshold of the marker cores (candidates).");
DEFINE_double(min_metal_hu, 2500, "A marker's fitted ball HU (partial volume removed) is at least "
                                  "this (metal, not bone).");
DEFINE_double(clip_hu, 0, "The scanner's largest HU (metal above it is clipped): 0 reads it from "
                          "the data (the largest value, when at least 8 voxels hold it), < 0: "
                          "no clip.");
DEFINE_double(label_tolerance_mm, 1.5, "Pairwise distance tolerance of the labelling, mm.");
DEFINE_double(extra_sigma_mm, 0, "Isotropic sigma (mm) added in quadrature to every covariance "
                                 "for effects the model leaves out on real scans (metal "
                                 "streaks, kernel); 0 for simulated data.");
DEFINE_string(frame, "patient", "Output frame: patient | model (rigid fit to --model) | "
                                "marker:K (origin at marker K, patient axes).");
// --out (the fiducials CSV) is shared: cli/common_flags.h.

namespace {

int RunCtFiducials() {
  const std::string cmd = "ct-fiducials";
  // --dicom and --out are required (checked before this runs: cli/command.h).
  if (const carmba::Status s = carmba::cli::CheckOutFile(); !s.ok()) {
    return carmba::cli::Fail(cmd, s);
  }
  carmba::CtFiducialsOptions options;
  options.read.series_uid = FLAGS_series_uid;
  options.model_csv = FLAGS_model;
  if (!FLAGS_model_columns.empty()) {
    std::stringstream ss(FLAGS_model_columns);
    std::string c;
    while (std::getline(ss, c, ',')) options.model_columns.push_back(c);
  }
  options.detect.diameter_mm = FLAGS_diameter_mm;
  options.detect.expected_count = FLAGS_expected;
  options.detect.threshold_hu = FLAGS_threshold_hu;
  options.detect.min_metal_hu = FLAGS_min_metal_hu;
  options.detect.clip_hu = FLAGS_clip_hu;
  options.label_tolerance_mm = FLAGS_label_tolerance_mm;
  options.frame = FLAGS_frame;
  options.extra_sigma_mm = FLAGS_extra_sigma_mm;
  std::string error;
  if (!options.Check(&error)) return carmba::cli::FailUsage(cmd, error);
  carmba::PlotOptions plot_options;
  plot_options.enabled = FLAGS_plots;
  carmba::PlotProcess plots(plot_options);  // imports matplotlib while the CT is read
  carmba::cli::Step(cmd, "reading " + FLAGS_dicom + " and finding the markers");
  auto result = carmba::ComputeCtFiducials(FLAGS_dicom, options);
  if (!result.ok()) return carmba::cli::Fail(cmd, result.status());
  for (const auto& w : result->warnings)
    std::cerr << "carmba " << cmd << ": warning: " << w << "\n";
  plots.Draw(carmba::FiducialsPlotData(*result));
  carmba::cli::Step(cmd, "waiting for the plot");
  const carmba::PlotSet plot_set = plots.Result();
  carmba::cli::Step(cmd, "writing the outputs");
  std::string report_warning;
  carmba::Status s = carmba::MakeParentDirs(FLAGS_out);
  if (s.ok()) s = carmba::WriteCtFiducials(*result, FLAGS_out, &report_warning, &plot_set);
  if (!s.ok()) return carmba::cli::Fail(cmd, s);
  if (!report_warning.empty())
    std::cerr << "carmba " << cmd << ": warning: " << report_warning << std::endl;
  std::cout << "ct-fiducials: " << result->detection.markers.size() << " markers -> "
            << FLAGS_out;
  if (result->labelled) {
    char b[80];
    std::snprintf(b, sizeof(b), " (labelled, model fit RMS %.4f mm)", result->labelling.rms_mm);
    std::cout << b;
  }
  std::cout << std::endl;
  return 0;
}

const bool kCtFiducialsRegistered [[maybe_unused]] = carmba::cli::RegisterCommand(
    "ct-fiducials",
    "Marker centres with covariance from a DICOM CT series (--out: the fiducials CSV; a report "
    "<stem>.md beside it).",
    __FILE__,
    RunCtFiducials);
const bool kCtFiducialsFlags [[maybe_unused]] =
    carmba::cli::RegisterCommandFlags("ct-fiducials", "out,force,plots");
const bool kCtFiducialsRequired [[maybe_unused]] =
    carmba::cli::RegisterRequiredFlags("ct-fiducials", "dicom,out");

}  // namespace
