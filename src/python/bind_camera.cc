// carmba.Camera, carmba.read_camera and carmba.project (camera/camera.h, camera/camera_model.h).
#include <sstream>

#include "camera/camera.h"
#include "camera/camera_model.h"
#include "python/bindings.h"
#include "util/plausible.h"

namespace carmba::python {
namespace {

using Array = py::array_t<double, py::array::c_style | py::array::forcecast>;

Array IntrinsicsArray(const Camera& c) {
  Array a(kNumIntrinsics);
  std::copy(c.params.begin(), c.params.end(), a.mutable_data());
  return a;
}

void SetIntrinsics(Camera* c, const Array& a) {
  if (a.ndim() != 1 || a.shape(0) != kNumIntrinsics) {
    throw Error("intrinsics: expected 9 values [fx, fy, cx, cy, k1, k2, p1, p2, k3], got shape " +
                std::to_string(a.ndim()) + "-d with " + std::to_string(a.size()) + " values");
  }
  std::copy(a.data(), a.data() + kNumIntrinsics, c->params.begin());
}

py::object CovarianceArray(const Camera& c) {
  if (c.covariance.empty()) return py::none();
  const size_t n = c.covariance.size();
  Eigen::MatrixXd m(n, n);
  for (size_t i = 0; i < n; ++i) {
    for (size_t j = 0; j < n; ++j) m(i, j) = c.covariance[i][j];
  }
  return ToNumpy(m);
}

std::string Repr(const Camera& c) {
  std::ostringstream s;
  s << "carmba.Camera(" << c.width << "x" << c.height << ", fx " << c.params[kFx] << ", fy "
    << c.params[kFy] << ", cx " << c.params[kCx] << ", cy " << c.params[kCy]
    << (c.covariance.empty() ? ", no covariance)" : ", with covariance)");
  return s.str();
}

// "points[2, 5]" for the flat index k of leading shape `lead`.
std::string IndexName(size_t k, const std::vector<py::ssize_t>& lead) {
  std::vector<py::ssize_t> idx(lead.size());
  for (size_t d = lead.size(); d-- > 0;) {
    idx[d] = static_cast<py::ssize_t>(k % lead[d]);
    k /= lead[d];
  }
  std::string s = "points[";
  for (size_t d = 0; d < idx.size(); ++d) s += (d ? ", " : "") + std::to_string(idx[d]);
  return s + "]";
}

Array AsLastDim(const py::object& o, int n, const char* what) {
  Array a = Array::ensure(o);
  if (!a || a.ndim() < 1 || a.shape(a.ndim() - 1) != n) {
    throw Error(std::string(what) + ": expected an array of shape (..., " + std::to_string(n) +
                ")");
  }
  return a;
}

// mrcal's project(): points (..., 3) in the camera frame and intrinsics (..., 9) broadcast
// against each other over the leading dimensions.
py::object Project(const py::object& points, const py::object& camera, bool get_gradients) {
  Array p = AsLastDim(points, 3, "points");
  Array in = py::isinstance<Camera>(camera) ? IntrinsicsArray(camera.cast<const Camera&>())
                                            : AsLastDim(camera, kNumIntrinsics, "camera");
  py::module_ np = py::module_::import("numpy");
  auto leading = [](const Array& a) {
    py::tuple t(a.ndim() - 1);
    for (py::ssize_t d = 0; d + 1 < a.ndim(); ++d) t[d] = py::int_(a.shape(d));
    return t;
  };
  const py::tuple p_lead = leading(p), i_lead = leading(in);
  py::tuple lead_t;
  try {
    lead_t = py::tuple(np.attr("broadcast_shapes")(p_lead, i_lead));
  } catch (const py::error_already_set&) {
    throw Error("points " + py::repr(p_lead).cast<std::string>() + " and intrinsics " +
                py::repr(i_lead).cast<std::string>() + ": leading shapes do not broadcast");
  }
  std::vector<py::ssize_t> lead;
  for (auto d : lead_t) lead.push_back(d.cast<py::ssize_t>());
  auto shape = [&](int last) {
    std::vector<py::ssize_t> s = lead;
    s.push_back(last);
    return s;
  };
  auto full = [&](const Array& a, int last) {
    return Array::ensure(
        np.attr("ascontiguousarray")(np.attr("broadcast_to")(a, py::tuple(py::cast(shape(last))))));
  };
  const Array P = full(p, 3), I = full(in, kNumIntrinsics);
  size_t count = 1;
  for (auto d : lead) count *= static_cast<size_t>(d);
  Array q(shape(2));
  std::vector<py::ssize_t> s23 = lead, s29 = lead;
  s23.insert(s23.end(), {2, 3});
  s29.insert(s29.end(), {2, 9});
  Array dq_dp(get_gradients ? s23 : std::vector<py::ssize_t>{0});
  Array dq_di(get_gradients ? s29 : std::vector<py::ssize_t>{0});
  const double* pp = P.data();
  const double* ip = I.data();
  double* qp = q.mutable_data();
  for (size_t k = 0; k < count; ++k) {
    const bool ok = ProjectCamPointWithJac(ip + k * kNumIntrinsics, pp + 3 * k, qp + 2 * k,
                                           get_gradients ? dq_di.mutable_data() + 18 * k : nullptr,
                                           get_gradients ? dq_dp.mutable_data() + 6 * k : nullptr);
    if (!ok) {
      throw Error(IndexName(k, lead) + ": not in front of the source (z = " +
                  FormatCompact(pp[3 * k + 2]) + ", needs z > 0 and finite values)");
    }
  }
  if (!get_gradients) return q;
  return py::make_tuple(q, dq_dp, dq_di);
}

}  // namespace

void BindCamera(py::module_& m) {
  py::class_<Camera>(m, "Camera",
                     "A C-arm camera (camera.json): image size and OPENCV5 intrinsics "
                     "[fx, fy, cx, cy, k1, k2, p1, p2, k3] (px for fx..cy), with an optional "
                     "covariance over covariance_names.")
      .def(py::init([](const Array& intrinsics, int width, int height) {
             Camera c;
             SetIntrinsics(&c, intrinsics);
             c.width = width;
             c.height = height;
             return c;
           }),
           py::arg("intrinsics"), py::arg("width") = 0, py::arg("height") = 0)
      .def_readwrite("width", &Camera::width)
      .def_readwrite("height", &Camera::height)
      .def_property("intrinsics", &IntrinsicsArray, &SetIntrinsics,
                    "numpy (9,): fx, fy, cx, cy (px), k1, k2, p1, p2, k3")
      .def_property_readonly("covariance", &CovarianceArray,
                             "numpy (k, k) over covariance_names (px^2 etc.), or None")
      .def_readonly("covariance_names", &Camera::covariance_names)
      .def("to_json", [](const Camera& c) { return CameraToJson(c).dump(2) + "\n"; },
           "camera.json's text")
      .def("__repr__", &Repr);
  m.attr("INTRINSIC_NAMES") =
      py::make_tuple("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3");
  m.def(
      "read_camera",
      [](const std::string& path) { return ValueOrThrow(ReadCameraJson(path)); },
      py::arg("path"),
      "Reads camera.json (camera/camera.h). Raises carmba.Error naming the key.");
  m.def("project", &Project, py::arg("points"), py::arg("camera"),
        py::arg("get_gradients") = false,
        "Projects points (..., 3) given in the camera frame (mm) with `camera` (a Camera or "
        "intrinsics (..., 9), broadcast against the points) to pixels (..., 2). With "
        "get_gradients=True returns (q, dq_dpoints (..., 2, 3), dq_dintrinsics (..., 2, 9)) "
        "as mrcal.project does. Raises carmba.Error for a point with z <= 0.");
}

}  // namespace carmba::python
