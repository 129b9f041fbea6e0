// CT fiducials: marker centres with covariance from a DICOM CT series (`carmba ct-fiducials`).
//
// Pipeline: ReadCtSeries (ct_volume.h) -> DetectMarkers (marker_detection.h) -> ids -> optional
// object frame -> CSV + report (the report and the writer: report/ct_fiducials_report.h).
//
// Ids. With a model CSV (marker_labelling.h), marker k is the model's point k (the labelling is
// by pairwise distances, so it is the same physical marker in every scan). With more
// marker-like candidates than model points, the subset that fits the model is selected and the
// others are listed as rejected; the expected count (given, else the model's) is checked on the
// labelled markers. Without a model, the
// markers are numbered 1..n in order of increasing patient z, then y, then x (DICOM LPS): a
// documented but scan-dependent rule (two markers at nearly the same z can swap between scans;
// use a model when ids must be stable).
//
// Output frame. "patient": DICOM patient coordinates (LPS, mm) of the series. "model": the
// object frame of the model CSV, via the rigid fit object_from_ct of the labelling (needs a
// model). "marker:K": origin at marker K, axes those of the patient frame (the thesis's object
// frame, origin marker 1 or 3): object_from_ct = [I | -c_K]. Covariances are rotated with the
// frame (C_object = R C R^T); the uncertainty of the frame itself (of c_K or of the fit) is not
// added to them.
//
// The CSV (read directly by the pose and joint problems; ReadFiducialsCsv below):
//   # comment lines (source, frame, object_from_ct, covariance model)
//   id,x_mm,y_mm,z_mm,cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz,volume_mm3,peak_hu
// with the centre in the output frame (mm), its covariance (mm^2), the core volume (voxels above
// the threshold, mm^3) and the peak HU. Beside it, <stem>.md: a short report (geometry,
// per-marker table with the bounding-box centre of the thesis's method and its difference,
// rejected components, labelling residuals, object_from_ct), <stem>.html (the same with a plot
// of the markers and their covariance ellipsoids) and, with an object frame,
// <stem>.object_from_ct.json: {"R": 3x3 row-major, "t_mm": [3], "frame": "..."}.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "ct/ct_volume.h"
#include "ct/marker_detection.h"
#include "ct/marker_labelling.h"
#include "util/status.h"

namespace carmba {

struct CtFiducialsOptions {
  CtReadOptions read;
  MarkerDetectionOptions detect;
  std::string model_csv;                    // optional model of nominal positions
  std::vector<std::string> model_columns;   // empty: auto (see ReadModelCsv)
  double label_tolerance_mm = 1.5;          // pairwise distance tolerance of the labelling
  std::string frame = "patient";            // "patient" | "model" | "marker:K"
  // Isotropic sigma (mm) added in quadrature to every covariance, for what the model leaves out
  // on real scans (streaks and beam hardening near metal, reconstruction kernel, marker shape):
  // C += extra_sigma_mm^2 I. 0 on simulated data.
  double extra_sigma_mm = 0;

  bool Check(std::string* error) const;
};

struct CtFiducialsResult {
  std::string dicom_dir;
  CtVolume geometry;                    // the series' geometry (hu left empty)
  int skipped_files = 0;
  std::vector<std::string> skipped;     // the skipped (non-image) files
  MarkerDetection detection;            // markers with final ids, sorted by id
  bool labelled = false;
  Labelling labelling;                  // when labelled; model_index re-ordered with the markers
  int candidates = 0;                   // > 0: markers selected among this many candidates
  std::vector<ModelPoint> model;
  std::string frame = "patient";
  bool has_object_frame = false;
  Rigid3 object_from_ct;
  double read_seconds = 0, detect_seconds = 0;
  MarkerDetectionOptions detect_options;
  std::string model_csv;
  double extra_sigma_mm = 0;
  // What makes the covariances less trustworthy than they say (SliceSamplingWarnings), one line
  // each; printed on stderr, in the CSV's header and in the report.
  std::vector<std::string> warnings;
};

// A series whose slices have gaps and lie more than half the nominal marker diameter apart: one or
// two slices through each marker, too few for its centre across the slices (on the real CT, every
// third slice put one sphere 1.35-2.79 mm apart in two such series, NEES per dof 8.5: see
// src/docs/results.md). One line naming the slices and the diameter, or none.
std::vector<std::string> SliceSamplingWarnings(const CtVolume& geometry, double diameter_mm);

StatusOr<CtFiducialsResult> ComputeCtFiducials(const std::string& dicom_dir,
                                               const CtFiducialsOptions& options);

// The CSV text (written with the report by report/ct_fiducials_report.h WriteCtFiducials).
std::string FormatFiducialsCsv(const CtFiducialsResult& result);

struct CtFiducialRow {
  int id = 0;
  Eigen::Vector3d p_mm = Eigen::Vector3d::Zero();
  Eigen::Matrix3d covariance_mm2 = Eigen::Matrix3d::Zero();
  double volume_mm3 = 0;
  double peak_hu = 0;
};

// Reads a fiducials CSV written above (header comments '#'); checks that every covariance is
// symmetric positive semi-definite. Errors name the file and line.
StatusOr<std::vector<CtFiducialRow>> ReadFiducialsCsv(const std::string& path);

}  // namespace carmba
