// The files `carmba calibrate` writes into its output directory:
//   camera.json          camera/camera.h's format plus: sigmas, rms_px (per coordinate),
//                        rms_opencv_px (sqrt(2) x), sigma_px, views [{image, num_points, rms_px,
//                        max_px, tilt_deg, distance_mm}], projection_uncertainty, options
//   camera.cameramodel   mrcal's format (a Python dict literal, LENSMODEL_OPENCV5): with the mrcal
//                        cross-check, written by mrcal from carmba's solution with mrcal's
//                        optimization_inputs (same observations), so that mrcal's uncertainty
//                        tools work on it directly; without it (--no-mrcal, or mrcal failed), the
//                        intrinsics alone at full precision (MrcalCameraModelText)
//   camera_opencv.yml    cv::FileStorage as OpenCV's calibration sample writes it: camera_matrix,
//                        distortion_coefficients, avg_reprojection_error (OpenCV's sqrt(2) figure)
//   observations.csv     detect/observations.h
//   corners.vnl          mrcal's corners format
//   report.md            the calibration, its statistics and the mrcal / OpenCV cross-checks;
//                        per image: points found, used or skipped and why
//   report.html          the same, with plots (report/plots.h)
//   overlays/NNN_<image stem>.png   per image (when detected here, not from --observations):
//                        report/overlays.h DrawDetectionOverlay (found points with ids,
//                        rejected blobs and why)
//   mrcal/               the mrcal cross-check's script, input and output, and
//                        camera_with_optimization_inputs.cameramodel: carmba's solution with
//                        mrcal's optimization_inputs, for mrcal's uncertainty tools
// The writer is report/calibration_report.h's WriteCalibrationOutputs. All are written into a
// temporary directory first and moved into place only when every file has been written, so an
// error leaves no partial output.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "calib/calibrate.h"
#include "calib/crosscheck.h"
#include "detect/grid_detector.h"

namespace carmba {

struct CalibrationRun {
  ObservationSet observations;
  CalibrationOptions options;
  CalibrationResult result;
  std::vector<std::string> skipped;  // "image: reason", images without a usable grid
  std::vector<GridDetection> detections;  // per image in order (empty with --observations)
  std::optional<OpenCvReference> opencv;
  std::string opencv_error;          // why OpenCV did not run (if it did not)
  std::optional<nlohmann::json> mrcal;
  std::string mrcal_error;
  std::string command_line;
  std::optional<Camera> truth;       // known truth (--truth), compared in the report
};

nlohmann::json CalibrationCameraJson(const CalibrationRun& run);
std::string MrcalCameraModelText(const CalibrationResult& result);
std::string OpenCvCalibrationYaml(const CalibrationRun& run);
}  // namespace carmba
