// PYBIND11_MODULE(carmba): the module's entry point, its exception and the conversions shared by
// the binding files (bind_*.cc).
#include "python/bindings.h"

namespace carmba::python {

py::array_t<double> ToNumpy(const Eigen::MatrixXd& m) {
  py::array_t<double> a({m.rows(), m.cols()});
  auto w = a.mutable_unchecked<2>();
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    for (Eigen::Index j = 0; j < m.cols(); ++j) w(i, j) = m(i, j);
  }
  return a;
}

py::array_t<double> ToNumpyVector(const Eigen::VectorXd& v) {
  py::array_t<double> a(v.size());
  auto w = a.mutable_unchecked<1>();
  for (Eigen::Index i = 0; i < v.size(); ++i) w(i) = v[i];
  return a;
}

py::object ToPython(const nlohmann::json& j) {
  switch (j.type()) {
    case nlohmann::json::value_t::null:
      return py::none();
    case nlohmann::json::value_t::boolean:
      return py::bool_(j.get<bool>());
    case nlohmann::json::value_t::number_integer:
      return py::int_(j.get<std::int64_t>());
    case nlohmann::json::value_t::number_unsigned:
      return py::int_(j.get<std::uint64_t>());
    case nlohmann::json::value_t::number_float:
      return py::float_(j.get<double>());
    case nlohmann::json::value_t::string:
      return py::str(j.get<std::string>());
    case nlohmann::json::value_t::array: {
      py::list l;
      for (const auto& e : j) l.append(ToPython(e));
      return l;
    }
    case nlohmann::json::value_t::object: {
      py::dict d;
      for (auto it = j.begin(); it != j.end(); ++it) d[py::str(it.key())] = ToPython(it.value());
      return d;
    }
    default:
      return py::none();
  }
}

}  // namespace carmba::python

PYBIND11_MODULE(carmba, m) {
  using namespace carmba::python;
  m.doc() =
      "carmba: C-arm calibration and pose bundle adjustment with covariance "
      "(src/docs/python.md). Conventions: camera x right, y down, z from the X-ray source "
      "towards the detector; intrinsics [fx, fy, cx, cy, k1, k2, p1, p2, k3]; poses "
      "cam_from_object = [rx, ry, rz (rad, Rodrigues), tx, ty, tz (mm)].";
  py::register_exception<Error>(m, "Error", PyExc_RuntimeError);
  BindCamera(m);
  BindSolve(m);
  BindCalibrate(m);
}
