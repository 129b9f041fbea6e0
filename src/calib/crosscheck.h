// Cross-checks of a carmba calibration, run on the same observations in the same run:
//   * mrcal (python3-mrcal through /usr/bin/python3, script scripts/mrcal_crosscheck.py, embedded
//     in the binary): LENSMODEL_OPENCV5, no board warp, no regularization, no outlier rejection,
//     seeded by mrcal itself. Yields mrcal's intrinsics, RMS, covariance (same pixel sigma),
//     projection uncertainty and mrcal.projection_diff against carmba's solution.
//   * OpenCV: cv::calibrateCamera with the flags equivalent to carmba's options.
// mrcal cannot fix single parameters: when carmba held some, the script also solves the same
// observations with carmba's free set on mrcal's residuals and Jacobian (like with like, OUT.json
// `held`). OpenCV cannot fix every subset: then its comparison is marked "not equivalent" and its
// numbers are for information only.
#pragma once

#include <array>
#include <map>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "calib/calibrate.h"

namespace carmba {

struct OpenCvReference {
  std::array<double, kNumIntrinsics> intrinsics{};
  std::array<double, kNumIntrinsics> sigma{};  // stdDeviationsIntrinsics (OpenCV's own estimate)
  double rms_returned_px = 0;  // what calibrateCamera returns: sqrt(SSR / N) (the sqrt(2) figure)
  double rms_px = 0;           // per coordinate, rms_returned_px / sqrt(2)
  int flags = 0;
  std::string flags_text;
  bool equivalent = true;      // the flags express carmba's options exactly
  std::string note;
  double seconds = 0;
};

// cv::calibrateCamera on the same observations (plate points, same ids). OpenCV's own
// initialisation unless the principal point is given (then CALIB_USE_INTRINSIC_GUESS with
// carmba's initial intrinsics).
StatusOr<OpenCvReference> RunOpenCvCalibration(const ObservationSet& observations,
                                               const CalibrationOptions& options,
                                               const CalibrationResult& result);

class PythonWorker;

struct MrcalCrossCheckOptions {
  std::string python = "/usr/bin/python3";
  std::string work_dir;  // where the script, its input and output go (created if needed)
  // An interpreter started early with StartMrcalPython (its imports overlap the solve), used
  // once; null: one is started when the script runs.
  PythonWorker* warm = nullptr;
};

// A Python interpreter importing numpy and mrcal, for MrcalCrossCheckOptions::warm.
std::unique_ptr<PythonWorker> StartMrcalPython(const std::string& python);

// The like-with-like input of the mrcal script: carmba's basis of its free intrinsics (9 x k,
// CalibrationResult::intrinsics_from_free) when it held or tied some and used no robust loss (the
// script then also solves with that free set: OUT.json `held`); null otherwise.
nlohmann::json MrcalFreeBasis(const CalibrationResult& result);

// The intrinsics a solve held or tied, e.g. "cx cy p1 p2 held, fy = r fx"; "" when all nine are
// free. Both cross-checks and the calibration report name carmba's free set with it.
std::string HeldIntrinsicsText(const std::array<bool, kNumIntrinsics>& free, bool fy_tied);

// Runs the mrcal script. `others` are extra intrinsics to diff against carmba's (e.g. "opencv",
// "truth"). Returns the script's JSON (see scripts/mrcal_crosscheck.py for the keys).
StatusOr<nlohmann::json> RunMrcalCrossCheck(
    const ObservationSet& observations,
    const CalibrationResult& result,
    const std::map<std::string, std::array<double, kNumIntrinsics>>& others,
    const MrcalCrossCheckOptions& options);

// Writes `in` as the script's IN.json into options.work_dir, runs the embedded script and returns
// its OUT.json. Errors: the script's last stderr line.
StatusOr<nlohmann::json> RunMrcalScript(const nlohmann::json& in,
                                        const MrcalCrossCheckOptions& options);

// The embedded script text.
const char* MrcalCrossCheckScript();

}  // namespace carmba
