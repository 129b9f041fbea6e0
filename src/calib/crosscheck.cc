#include "calib/crosscheck.h"

#include <opencv2/calib3d.hpp>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "util/file_util.h"
#include "util/format.h"
#include "util/python_worker.h"

namespace carmba {

StatusOr<OpenCvReference> RunOpenCvCalibration(const ObservationSet& obs,
                                               const CalibrationOptions& opt,
                                               const CalibrationResult& result) {
  OpenCvReference ref;
  std::vector<std::vector<cv::Point3f>> object_points;
  std::vector<std::vector<cv::Point2f>> image_points;
  for (const auto& v : obs.views) {
    std::vector<cv::Point3f> op;
    std::vector<cv::Point2f> ip;
    for (size_t j = 0; j < v.uv_px.size(); ++j) {
      const Eigen::Vector3d P = obs.grid.PointInPlate(v.point_ids[j]);
      op.emplace_back(P.x(), P.y(), P.z());
      ip.emplace_back(v.uv_px[j].x(), v.uv_px[j].y());
    }
    object_points.push_back(op);
    image_points.push_back(ip);
  }
  int flags = 0;
  std::string text;
  auto add = [&](int f, const char* name) {
    flags |= f;
    text += (text.empty() ? "" : "|") + std::string(name);
  };
  const auto& x0 = result.initial_intrinsics;
  cv::Mat K = (cv::Mat_<double>(3, 3) << x0[kFx], 0, x0[kCx], 0, x0[kFy], x0[kCy], 0, 0, 1);
  cv::Mat dist = cv::Mat::zeros(5, 1, CV_64F);
  if (opt.fix_aspect_ratio) add(cv::CALIB_FIX_ASPECT_RATIO, "FIX_ASPECT_RATIO");
  if (opt.zero_tangential) add(cv::CALIB_ZERO_TANGENT_DIST, "ZERO_TANGENT_DIST");
  if (opt.fix_principal_point) add(cv::CALIB_FIX_PRINCIPAL_POINT, "FIX_PRINCIPAL_POINT");
  if (opt.fix_k3) add(cv::CALIB_FIX_K3, "FIX_K3");
  bool fx = false, fy = false, p1 = false, p2 = false, cx = false, cy = false;
  for (const auto& n : opt.solve.fix) {
    if (n == "fx") fx = true;
    if (n == "fy") fy = true;
    if (n == "cx") cx = true;
    if (n == "cy") cy = true;
    if (n == "p1") p1 = true;
    if (n == "p2") p2 = true;
    if (n == "k1") add(cv::CALIB_FIX_K1, "FIX_K1");
    if (n == "k2") add(cv::CALIB_FIX_K2, "FIX_K2");
    if (n == "k3" && !opt.fix_k3) add(cv::CALIB_FIX_K3, "FIX_K3");
  }
  if ((cx || cy) && !opt.fix_principal_point) {
    if (cx && cy) {
      add(cv::CALIB_FIX_PRINCIPAL_POINT, "FIX_PRINCIPAL_POINT");
    } else {
      ref.equivalent = false;
      ref.note += "OpenCV cannot fix cx or cy alone; ";
    }
  }
  if (fx || fy) {
    add(cv::CALIB_FIX_FOCAL_LENGTH, "FIX_FOCAL_LENGTH");
    if (!(fx && fy)) {
      ref.equivalent = false;
      ref.note += "OpenCV fixes fx and fy together; ";
    }
  }
  if (p1 || p2) {
    if (!(p1 && p2 && x0[kP1] == 0 && x0[kP2] == 0)) {
      ref.equivalent = false;
      ref.note += "OpenCV fixes p1, p2 only together at zero; ";
    }
    if (!opt.zero_tangential) add(cv::CALIB_ZERO_TANGENT_DIST, "ZERO_TANGENT_DIST");
  }
  const bool guess = !opt.principal_point_px.empty() || !opt.initial_intrinsics.empty() ||
                     fx || fy || cx || cy;
  if (guess) {
    add(cv::CALIB_USE_INTRINSIC_GUESS, "USE_INTRINSIC_GUESS");
    for (int i = 0; i < 5; ++i) dist.at<double>(i) = x0[4 + i];
  }
  ref.flags = flags;
  ref.flags_text = text.empty() ? "0" : text;
  std::vector<cv::Mat> rvecs, tvecs;
  cv::Mat std_intr, std_extr, per_view;
  const auto t0 = std::chrono::steady_clock::now();
  try {
    ref.rms_returned_px =
        cv::calibrateCamera(object_points, image_points, cv::Size(obs.width, obs.height), K, dist,
                            rvecs, tvecs, std_intr, std_extr, per_view, flags,
                            cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100,
                                             DBL_EPSILON));
  } catch (const cv::Exception& e) {
    return Status::Error(std::string("cv::calibrateCamera failed: ") + e.what());
  }
  ref.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ref.rms_px = ref.rms_returned_px / std::sqrt(2.0);
  ref.intrinsics = {K.at<double>(0, 0), K.at<double>(1, 1), K.at<double>(0, 2),
                    K.at<double>(1, 2), dist.at<double>(0), dist.at<double>(1),
                    dist.at<double>(2), dist.at<double>(3), dist.at<double>(4)};
  for (int i = 0; i < kNumIntrinsics && i < std_intr.rows; ++i) {
    // OpenCV order: fx fy cx cy k1 k2 p1 p2 k3 ...
    ref.sigma[i] = std_intr.at<double>(i);
  }
  return ref;
}

nlohmann::json MrcalFreeBasis(const CalibrationResult& result) {
  if (result.num_free_intrinsics == kNumIntrinsics || result.loss != ba::Loss::kTrivial)
    return nullptr;
  return JsonRows(result.intrinsics_from_free);
}

std::string HeldIntrinsicsText(const std::array<bool, kNumIntrinsics>& free, bool fy_tied) {
  std::string held;
  for (int i = 0; i < kNumIntrinsics; ++i) {
    if (!free[i]) held += (held.empty() ? "" : " ") + std::string(kIntrinsicNames[i]);
  }
  const std::string tie = fy_tied ? "fy = r fx" : "";
  if (held.empty()) return tie;
  return held + " held" + (tie.empty() ? "" : ", " + tie);
}

StatusOr<nlohmann::json> RunMrcalCrossCheck(
    const ObservationSet& obs,
    const CalibrationResult& result,
    const std::map<std::string, std::array<double, kNumIntrinsics>>& others,
    const MrcalCrossCheckOptions& opt) {
  if (obs.grid.pattern == GridPattern::kAsymmetricCircles) {
    return Status::Error("mrcal models only regular grids; not run for an asymmetric circle grid");
  }
  CARMBA_RETURN_IF_ERROR(MakeDirs(opt.work_dir));
  nlohmann::json in;
  in["image_size"] = {obs.width, obs.height};
  in["grid"] = {{"rows", obs.grid.rows}, {"cols", obs.grid.cols},
                {"spacing_mm", obs.grid.spacing_mm}};
  nlohmann::json views = nlohmann::json::array();
  for (const auto& v : obs.views) {
    nlohmann::json pts = nlohmann::json::array();
    for (size_t j = 0; j < v.uv_px.size(); ++j) {
      pts.push_back({v.point_ids[j], v.uv_px[j].x(), v.uv_px[j].y()});
    }
    views.push_back(pts);
  }
  in["views"] = views;
  in["carmba"] = {{"intrinsics", result.camera.params},
                  {"poses", result.cam_from_plate},
                  {"sigma_px", result.sigma_px},
                  {"distance_mm", result.uncertainty_distance_mm},
                  {"free_basis", MrcalFreeBasis(result)}};
  nlohmann::json o = nlohmann::json::object();
  for (const auto& [name, x] : others) o[name] = x;
  in["others"] = o;
  return RunMrcalScript(in, opt);
}

std::unique_ptr<PythonWorker> StartMrcalPython(const std::string& python) {
  // scripts/mrcal_crosscheck.py's imports.
  return std::make_unique<PythonWorker>(python, "import numpy\nimport mrcal\n");
}

StatusOr<nlohmann::json> RunMrcalScript(const nlohmann::json& in,
                                        const MrcalCrossCheckOptions& opt) {
  CARMBA_RETURN_IF_ERROR(MakeDirs(opt.work_dir));
  const std::string script = JoinPath(opt.work_dir, "mrcal_crosscheck.py");
  const std::string in_path = JoinPath(opt.work_dir, "mrcal_in.json");
  const std::string out_path = JoinPath(opt.work_dir, "mrcal_out.json");
  const std::string err_path = JoinPath(opt.work_dir, "mrcal_err.txt");
  CARMBA_RETURN_IF_ERROR(WriteFileAtomic(script, MrcalCrossCheckScript()));
  CARMBA_RETURN_IF_ERROR(WriteFileAtomic(in_path, in.dump()));
  std::unique_ptr<PythonWorker> own;
  PythonWorker* worker = opt.warm;
  if (!worker) {
    own = StartMrcalPython(opt.python);
    worker = own.get();
  }
  worker->Start(script, {in_path, out_path}, "", err_path);
  const int rc = worker->Wait();
  if (rc != 0) {
    auto err = ReadFile(err_path);
    std::string msg = err.ok() ? *err : "";
    while (!msg.empty() && (msg.back() == '\n' || msg.back() == '\r')) msg.pop_back();
    const auto nl = msg.rfind('\n');
    if (nl != std::string::npos) msg = msg.substr(nl + 1);
    return Status::Error("mrcal cross-check failed (" + opt.python + "): " +
                         (msg.empty() ? "exit status " + std::to_string(rc) : msg));
  }
  auto text = ReadFile(out_path);
  if (!text.ok()) return text.status();
  try {
    return nlohmann::json::parse(*text);
  } catch (const std::exception& e) {
    return Status::Error(out_path + ": invalid JSON from the mrcal script: " + e.what());
  }
}


}  // namespace carmba
