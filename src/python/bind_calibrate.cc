// carmba.calibrate -> carmba.Calibration: the intrinsic calibration `carmba calibrate` runs
// (src/cli/cmd_calibrate.cc: detection, calib/calibrate.h Calibrate, camera.json), from
// observation arrays, an observations.csv or images; without the mrcal and OpenCV cross-checks.
#include <cmath>

#include "calib/calib_output.h"
#include "calib/calibrate.h"
#include "detect/grid_detector.h"
#include "detect/observations.h"
#include "problem/problem.h"
#include "python/bindings.h"
#include "report/calibration_report.h"
#include "util/file_util.h"

namespace carmba::python {
namespace {

using Array = py::array_t<double, py::array::c_style | py::array::forcecast>;

// observations (V, rows*cols, 2): point k of view v at [v, k]; NaN where not seen. The array's
// shape is checked here; its values as an observations.csv's (detect/observations.h
// ObservationsFromArray).
ObservationSet FromArray(const py::object& o, const GridSpec& grid, const py::object& image_size) {
  Array a = Array::ensure(o);
  if (!a || a.ndim() != 3 || a.shape(1) != grid.NumPoints() || a.shape(2) != 2) {
    throw Error("observations: expected an array (views, rows*cols = " +
                std::to_string(grid.NumPoints()) + ", 2) of pixels, NaN where a point is not seen");
  }
  if (a.shape(0) == 0) throw Error("observations: no views (the array's first dimension is 0)");
  if (image_size.is_none()) throw Error("image_size: (width, height) is required with arrays");
  auto wh = image_size.cast<std::vector<double>>();
  if (wh.size() != 2) wh.assign(2, std::nan(""));  // refused as the library refuses any bad size
  return ValueOrThrow(ObservationsFromArray(
      a.data(), static_cast<int>(a.shape(0)), grid, wh[0], wh[1], "observations"));
}

CalibrationRun Calibrate(const py::object& observations,
                         const py::object& images,
                         const py::object& image_size,
                         const std::string& pattern,
                         int rows,
                         int cols,
                         const py::object& spacing,
                         const py::object& config,
                         const py::object& detection) {
  const double spacing_mm = spacing.is_none() ? 0.0 : spacing.cast<double>();
  if (observations.is_none() == images.is_none()) {
    throw Error("give exactly one of observations (array or observations.csv) and images");
  }
  CalibrationRun run;
  DetectionOptions detect;
  if (!detection.is_none()) {
    if (images.is_none()) throw Error("detection: give it with images (observations are detected)");
    ThrowIfError(LoadDetectionOptions(py::str(detection), &detect));
  }
  if (!config.is_none()) {
    ThrowIfError(LoadCalibrationOptions(py::str(config), &run.options));
  }
  GridSpec grid;
  grid.pattern = ValueOrThrow(ParseGridPattern(pattern));
  grid.rows = rows;
  grid.cols = cols;
  grid.spacing_mm = spacing_mm > 0 ? spacing_mm : 20.0;
  std::string err;
  if (!grid.Check(&err)) throw Error(err);
  if (!observations.is_none() && !py::isinstance<py::str>(observations)) {
    run.observations = FromArray(observations, grid, image_size);
  } else {
    // A file or images: the problem's plate-view reader, as `carmba calibrate` reads its flags.
    PlateViewsInput plate;
    plate.key = [](const std::string& input) { return input; };
    plate.fail = [](const std::string& input, const std::string& what) {
      return Status::Error(input + ": " + what);
    };
    if (observations.is_none()) {
      plate.images = py::str(images);
      plate.grid = grid;
      plate.detection = detect;
    } else {
      plate.observations = py::str(observations);
      plate.spacing_mm_override = spacing_mm;
    }
    Problem p;
    {
      py::gil_scoped_release release;
      ThrowIfError(LoadPlateViews(plate, &p));
    }
    run.observations = p.plate;
    run.skipped = p.skipped_images;
    run.detections = p.plate_detections;
  }
  {
    py::gil_scoped_release release;
    run.result = ValueOrThrow(carmba::Calibrate(run.observations, run.options));
  }
  run.opencv_error = "disabled";
  run.mrcal_error = "disabled";
  return run;
}

}  // namespace

void BindCalibrate(py::module_& m) {
  py::class_<CalibrationRun>(m,
                             "Calibration",
                             "An intrinsic calibration: camera (with its 9 x 9 covariance over "
                             "fx fy cx cy k1 k2 p1 p2 k3, marginal over the plate poses) and the "
                             "plate poses cam_from_plate [rx ry rz (rad), tx ty tz (mm)].")
      .def_property_readonly("camera", [](const CalibrationRun& r) { return r.result.camera; })
      .def_property_readonly("covariance",
                             [](const CalibrationRun& r) { return ToNumpy(r.result.covariance); })
      .def_property_readonly("sigmas",
                             [](const CalibrationRun& r) {
                               return ToNumpyVector(Eigen::Map<const Eigen::VectorXd>(
                                   r.result.sigma.data(), kNumIntrinsics));
                             })
      .def_property_readonly("cam_from_plate",
                             [](const CalibrationRun& r) {
                               Eigen::MatrixXd p(r.result.cam_from_plate.size(), 6);
                               for (size_t v = 0; v < r.result.cam_from_plate.size(); ++v) {
                                 for (int i = 0; i < 6; ++i)
                                   p(v, i) = r.result.cam_from_plate[v][i];
                               }
                               return ToNumpy(p);
                             })
      .def_property_readonly("free", [](const CalibrationRun& r) { return r.result.free; })
      .def_property_readonly("rms_px", [](const CalibrationRun& r) { return r.result.rms_px; })
      .def_property_readonly("sigma_px", [](const CalibrationRun& r) { return r.result.sigma_px; })
      .def_property_readonly("sigma_px_estimated",
                             [](const CalibrationRun& r) { return r.result.sigma_estimated; })
      .def_property_readonly("num_points",
                             [](const CalibrationRun& r) { return r.result.num_points; })
      .def_property_readonly("images",
                             [](const CalibrationRun& r) {
                               std::vector<std::string> out;
                               for (const auto& v : r.result.views) out.push_back(v.image);
                               return out;
                             })
      .def_readonly("skipped", &CalibrationRun::skipped)
      .def(
          "camera_json",
          [](const CalibrationRun& r) { return CalibrationResultJson(r).dump(2) + "\n"; },
          "camera.json's text as `carmba calibrate --no-mrcal --no-opencv` writes it");
  m.def("calibrate",
        &Calibrate,
        py::arg("observations") = py::none(),
        py::arg("images") = py::none(),
        py::arg("image_size") = py::none(),
        py::arg("pattern") = "circles",
        py::arg("rows") = 5,
        py::arg("cols") = 5,
        py::arg("spacing_mm") = py::none(),
        py::arg("config") = py::none(),
        py::arg("detection") = py::none(),
        "Calibrates the intrinsics from observations (an array (views, rows*cols, 2) with NaN "
        "for points not seen and image_size=(w, h), or an observations.csv path) or from "
        "images (a directory or glob; the grid detected as `carmba calibrate --images`). "
        "spacing_mm: the grid pitch (default: the CSV's, else 20). config: a calibration "
        "config YAML (configs/calib_*.yaml). detection: a detection options YAML for the "
        "images (`carmba calibrate --detection`).");
}

}  // namespace carmba::python
