// Shared pieces of the Python module `carmba` (src/docs/python.md): the exception carrying
// carmba's one-line message, numpy and JSON conversions, and the per-file Bind* functions
// module.cc calls.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <Eigen/Dense>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>

#include "util/status.h"

namespace carmba::python {

namespace py = pybind11;

// Raised as carmba.Error (a RuntimeError) with the Status's one-line message.
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

inline void ThrowIfError(const Status& s) {
  if (!s.ok()) throw Error(s.message());
}

template <typename T>
T ValueOrThrow(StatusOr<T> v) {
  ThrowIfError(v.status());
  return std::move(*v);
}

// A copy of an Eigen matrix as a C-ordered numpy array (rows x cols, or a vector (n,)).
py::array_t<double> ToNumpy(const Eigen::MatrixXd& m);
py::array_t<double> ToNumpyVector(const Eigen::VectorXd& v);

// nlohmann::json -> Python (dict, list, str, float, int, bool, None).
py::object ToPython(const nlohmann::json& j);

void BindCamera(py::module_& m);
void BindSolve(py::module_& m);
void BindCalibrate(py::module_& m);

}  // namespace carmba::python
