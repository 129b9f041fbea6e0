// Reading problem and config YAML files (formats in pose_problem.h).
#include <algorithm>
#include <cmath>
#include <set>

#include "problem/pixel_csv.h"
#include "problem/pose_problem.h"
#include "util/csv.h"
#include "util/file_util.h"
#include "util/plausible.h"
#include "util/yaml_reader.h"

namespace carmba {
namespace {

std::string FormatId(double v) {
  if (v == std::floor(v)) return std::to_string(static_cast<long long>(v));
  std::string s = std::to_string(v);
  return s;
}

// Reads `key` as a view id: a number or a string.
std::string ViewIdFrom(const YAML::Node& n) { return n.IsScalar() ? n.Scalar() : std::string(); }

Status ReadMarkers(YamlMap& m, const std::string& base, PoseProblem* p) {
  std::string file, id_column = "id";
  std::vector<std::string> columns = {"x_mm", "y_mm", "z_mm"};
  double sigma_mm = -1;
  m.Get("file", &file, true);
  m.Get("id_column", &id_column);
  m.Get("columns", &columns);
  m.GetInRange("sigma_mm", &sigma_mm, plausible::kCtSigmaMm);
  if (!m.status().ok()) return m.status();
  if (columns.size() != 3) {
    m.Fail("columns", "expected three column names (x, y, z)");
    return m.status();
  }
  auto markers = ReadMarkersCsv(JoinPath(base, file), id_column, columns, sigma_mm,
                                m.KeyPath("sigma_mm"));
  if (!markers.ok()) return markers.status();
  p->markers = std::move(*markers);
  return Status::Ok();
}

Status ReadObservations(YamlMap& m,
                        const std::string& base,
                        const std::vector<std::string>& wanted_views,
                        PoseProblem* p) {
  std::string file, format = "long", id_column = "marker";
  m.Get("file", &file, true);
  m.GetEnum("format", {"wide", "long"}, &format);
  m.Get("marker_column", &id_column);
  if (!m.status().ok()) return m.status();
  const std::string path = JoinPath(base, file);
  std::map<std::string, PoseView> views;
  std::vector<std::string> order;
  if (format == "wide") {
    // Columns u_<id>, v_<id> (the thesis's tables); the long format is problem/pixel_csv.h's.
    auto t = ReadCsv(path);
    if (!t.ok()) return t.status();
    std::vector<std::string> ids;
    for (const auto& h : t->header) {
      if (h.rfind("u_", 0) == 0) ids.push_back(h.substr(2));
    }
    for (const auto& id : ids) {
      auto vc = t->Column("v_" + id);
      if (!vc.ok()) return vc.status();
    }
    for (const auto& id : ids) {
      PoseView v;
      v.id = id;
      for (size_t r = 0; r < t->rows.size(); ++r) {
        Observation o;
        auto mid = t->Integer(r, id_column);
        if (!mid.ok()) return mid.status();
        o.marker_id = *mid;
        auto u = t->NumberIn(r, "u_" + id, plausible::kPixelCoordinatePx);
        if (!u.ok()) return u.status();
        auto vv = t->NumberIn(r, "v_" + id, plausible::kPixelCoordinatePx);
        if (!vv.ok()) return vv.status();
        o.uv_px = Eigen::Vector2d(*u, *vv);
        v.observations.push_back(o);
      }
      views[id] = v;
      order.push_back(id);
    }
  } else {
    PixelCsvColumns columns;
    columns.key = id_column;
    auto rows = ReadPixelCsv(path, columns);
    if (!rows.ok()) return rows.status();
    for (const PixelCsvRow& row : *rows) {
      Observation o;
      o.marker_id = row.id;
      o.uv_px = row.uv_px;
      o.covariance_px2 = row.covariance_px2;
      if (!views.count(row.view)) {
        order.push_back(row.view);
        views[row.view].id = row.view;
      }
      views[row.view].observations.push_back(o);
    }
  }
  if (!wanted_views.empty()) order = wanted_views;
  for (const auto& id : order) {
    if (!views.count(id)) {
      return Status::Error(p->path + ": view '" + id + "' has no observations in " + path);
    }
    p->views.push_back(views[id]);
  }
  if (p->views.empty()) return Status::Error(path + ": no views");
  return Status::Ok();
}

Status ReadReference(YamlMap& m, const std::string& base, PoseProblem* p) {
  if (m.Has("legacy_posit")) {
    YamlMap& l = m.Map("legacy_posit");
    LegacyPositReference r;
    l.GetInRange("focal_px", &r.focal_px, plausible::kFocalPx, true);
    l.GetInRange("cx_px", &r.cx_px, plausible::kPixelCoordinatePx, true);
    l.GetInRange("cy_px", &r.cy_px, plausible::kPixelCoordinatePx, true);
    l.Get("y_up", &r.y_up);
    p->legacy_reference = r;
  } else {
    m.Map("legacy_posit");
  }
  std::string rot_file, val_file;
  m.Get("rotations", &rot_file);
  m.Get("validation", &val_file);
  if (!m.status().ok()) return m.status();
  if (!rot_file.empty()) {
    auto t = ReadCsv(JoinPath(base, rot_file));
    if (!t.ok()) return t.status();
    const char* names[9] = {"r11", "r12", "r13", "r21", "r22", "r23", "r31", "r32", "r33"};
    for (size_t r = 0; r < t->rows.size(); ++r) {
      Eigen::Matrix3d R;
      for (int k = 0; k < 9; ++k) {
        auto v = t->Number(r, names[k]);
        if (!v.ok()) return v.status();
        R(k / 3, k % 3) = *v;
      }
      auto c = t->Column("orientation_deg");
      if (!c.ok()) return c.status();
      p->reference_rotations[t->rows[r][*c]] = R;
    }
  }
  if (!val_file.empty()) {
    auto t = ReadCsv(JoinPath(base, val_file));
    if (!t.ok()) return t.status();
    for (size_t r = 0; r < t->rows.size(); ++r) {
      auto a = t->Column("orientation_a_deg");
      auto b = t->Column("orientation_b_deg");
      if (!a.ok()) return a.status();
      if (!b.ok()) return b.status();
      auto v = t->Number(r, "achieved_deg");
      if (!v.ok()) return v.status();
      p->reference_angles_deg[{t->rows[r][*a], t->rows[r][*b]}] = *v;
    }
  }
  return Status::Ok();
}

Status ReadTruth(const std::string& path, PoseProblem* p) {
  auto text = ReadFile(path);
  if (!text.ok()) return text.status();
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(*text);
    for (const auto& v : j.at("views")) {
      Pose6 pose;
      const auto& cfo = v.contains("cam_from_object") ? v.at("cam_from_object") : v;
      for (int k = 0; k < 3; ++k) pose[k] = cfo.at("rvec").at(k).get<double>();
      for (int k = 0; k < 3; ++k) pose[3 + k] = cfo.at("t_mm").at(k).get<double>();
      std::string id = v.at("id").is_string() ? v.at("id").get<std::string>()
                                              : FormatId(v.at("id").get<double>());
      p->truth_poses[id] = pose;
    }
  } catch (const std::exception& e) {
    return Status::Error(path + ": expected {\"views\": [{\"id\", \"rvec\", \"t_mm\"}]}: " +
                         e.what());
  }
  return Status::Ok();
}

}  // namespace

void ReadValidationPairs(YamlMap& root, std::vector<ValidationPair>* out) {
  for (YamlMap* pm : root.MapList("validation")) {
    ValidationPair vp;
    YAML::Node a = pm->Raw("a"), b = pm->Raw("b");
    if (!a.IsScalar() || !b.IsScalar()) {
      pm->Fail("a", "expected view ids a and b");
    } else {
      vp.a = a.Scalar();
      vp.b = b.Scalar();
    }
    double e = NAN;
    pm->GetInRange("expected_deg", &e, plausible::kAngleDeg);
    if (std::isfinite(e)) vp.expected_deg = e;
    out->push_back(vp);
  }
}

StatusOr<std::vector<Marker>> ReadMarkersCsv(const std::string& path,
                                             const std::string& id_column,
                                             const std::vector<std::string>& columns,
                                             double sigma_mm,
                                             const std::string& sigma_key) {
  auto t = ReadCsv(path);
  if (!t.ok()) return t.status();
  const char* cov_cols[6] = {"cov_xx", "cov_xy", "cov_xz", "cov_yy", "cov_yz", "cov_zz"};
  const bool has_cov = t->Column("cov_xx").ok();
  if (!has_cov && !(sigma_mm > 0)) {
    return Status::Error(sigma_key + ": missing: give the CT sigma or covariance columns "
                         "cov_xx..cov_zz in " + path);
  }
  std::vector<Marker> markers;
  std::set<int> ids;
  for (size_t r = 0; r < t->rows.size(); ++r) {
    Marker mk;
    auto id = t->Integer(r, id_column);
    if (!id.ok()) return id.status();
    mk.id = *id;
    if (!ids.insert(mk.id).second) {
      return Status::Error(path + ":" + std::to_string(t->line_numbers[r]) + ": marker id " +
                           std::to_string(mk.id) + " appears twice");
    }
    for (int c = 0; c < 3; ++c) {
      auto v = t->NumberIn(r, columns[c], plausible::kCoordinateMm);
      if (!v.ok()) return v.status();
      mk.p_in_object[c] = *v;
    }
    if (sigma_mm > 0) {
      mk.covariance = Eigen::Matrix3d::Identity() * sigma_mm * sigma_mm;
    } else {
      double c6[6];
      for (int k = 0; k < 6; ++k) {
        auto v = t->Number(r, cov_cols[k]);
        if (!v.ok()) return v.status();
        c6[k] = *v;
      }
      mk.covariance << c6[0], c6[1], c6[2], c6[1], c6[3], c6[4], c6[2], c6[4], c6[5];
      for (int k : {0, 3, 5}) {  // the variances: their square roots are sigmas in mm
        const double sigma = c6[k] >= 0 ? std::sqrt(c6[k]) : c6[k];
        if (!InRange(sigma, plausible::kCtSigmaMm)) {
          return Status::Error(path + ":" + std::to_string(t->line_numbers[r]) + ": column '" +
                               cov_cols[k] + "': expected a variance whose square root is " +
                               FormatRange(plausible::kCtSigmaMm) + ", got " +
                               FormatCompact(c6[k]));
        }
      }
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(mk.covariance);
      if (!(es.eigenvalues().minCoeff() > 0)) {
        return Status::Error(path + ":" + std::to_string(t->line_numbers[r]) +
                             ": marker covariance is not positive definite");
      }
    }
    markers.push_back(mk);
  }
  if (markers.empty()) return Status::Error(path + ": no markers");
  return markers;
}

Status PoseProblem::Check() const {
  std::string e;
  if (!CheckRange("key 'sigma_px'", sigma_px, plausible::kPixelSigmaPx, &e)) {
    return Status::Error(path + ": " + e);
  }
  for (const auto& m : markers) {
    for (int c = 0; c < 3; ++c) {
      if (!CheckRange("marker " + std::to_string(m.id) + ": coordinate " + "xyz"[c],
                      m.p_in_object[c], plausible::kCoordinateMm, &e)) {
        return Status::Error(path + ": " + e);
      }
    }
  }
  std::set<int> ids;
  for (const auto& m : markers) ids.insert(m.id);
  std::set<std::string> vids;
  for (const auto& v : views) {
    if (!vids.insert(v.id).second) return Status::Error(path + ": view '" + v.id + "' twice");
    std::set<int> seen;
    for (const auto& o : v.observations) {
      if (!ids.count(o.marker_id)) {
        return Status::Error(path + ": view '" + v.id + "' observes marker " +
                             std::to_string(o.marker_id) + " which is not among the markers");
      }
      if (!seen.insert(o.marker_id).second) {
        return Status::Error(path + ": view '" + v.id + "' observes marker " +
                             std::to_string(o.marker_id) + " twice");
      }
      for (int c = 0; c < 2; ++c) {
        if (!CheckRange("view '" + v.id + "': marker " + std::to_string(o.marker_id) + ": " +
                            (c == 0 ? "u" : "v"),
                        o.uv_px[c], plausible::kPixelCoordinatePx, &e)) {
          return Status::Error(path + ": " + e);
        }
      }
    }
    if (v.observations.size() < 4) {
      return Status::Error(path + ": view '" + v.id + "' has " +
                           std::to_string(v.observations.size()) +
                           " observed markers; a pose needs at least 4");
    }
  }
  for (const auto& pr : validation) {
    if (!vids.count(pr.a) || !vids.count(pr.b)) {
      return Status::Error(path + ": validation pair " + pr.a + "-" + pr.b +
                           " names a view that is not in the problem");
    }
  }
  return Status::Ok();
}

StatusOr<PoseProblem> LoadPoseProblem(const std::string& yaml_path) {
  YamlMap root = YamlMap::Load(yaml_path);
  if (!root.status().ok()) return root.status();
  PoseProblem p;
  p.path = yaml_path;
  const std::string base = DirName(yaml_path);
  std::string camera_file, handedness = "as_given", truth_file, description;
  root.Get("name", &p.name, true);
  root.Get("description", &description);
  root.Get("camera", &camera_file, true);
  root.GetInRange("sigma_px", &p.sigma_px, plausible::kPixelSigmaPx, true);
  root.GetEnum("handedness", {"as_given", "mirrored"}, &handedness);
  root.Get("truth", &truth_file);
  std::vector<std::string> views;
  {
    const bool has_views = root.Has("views");
    YAML::Node vn = root.Raw("views");
    if (has_views) {
      if (!vn.IsSequence()) {
        root.Fail("views", "expected a list of view ids");
      } else {
        for (const auto& v : vn) views.push_back(ViewIdFrom(v));
        if (views.empty()) {
          root.Fail("views", "expected a non-empty list of view ids (omit the key for all views)");
        }
      }
    }
  }
  YamlMap& markers = root.Map("markers", true);
  YamlMap& observations = root.Map("observations", true);
  YamlMap& reference = root.Map("reference");
  ReadValidationPairs(root, &p.validation);
  if (!root.status().ok()) return root.status();
  p.handedness = handedness == "mirrored" ? Handedness::kMirrored : Handedness::kAsGiven;
  CARMBA_RETURN_IF_ERROR(ReadMarkers(markers, base, &p));
  CARMBA_RETURN_IF_ERROR(ReadObservations(observations, base, views, &p));
  CARMBA_RETURN_IF_ERROR(ReadReference(reference, base, &p));
  CARMBA_RETURN_IF_ERROR(root.Finish());
  auto cam = ReadCameraJson(JoinPath(base, camera_file));
  if (!cam.ok()) return cam.status();
  p.camera = *cam;
  if (!truth_file.empty()) CARMBA_RETURN_IF_ERROR(ReadTruth(JoinPath(base, truth_file), &p));
  CARMBA_RETURN_IF_ERROR(p.Check());
  return p;
}

const char* InitializerName(Initializer i) {
  switch (i) {
    case Initializer::kLegacyPosit: return "legacy_posit";
    case Initializer::kPosit: return "posit";
    case Initializer::kEpnp: return "epnp";
    case Initializer::kSqpnp: return "sqpnp";
  }
  return "?";
}

ba::BaOptions SolverConfig::ToBaOptions() const {
  ba::BaOptions o;
  o.backend = backend;
  o.analytic_jacobians = analytic_jacobians;
  o.loss = loss;
  o.loss_scale_px = loss_scale_px;
  o.linear_solver = linear_solver;
  o.max_iterations = refine ? max_iterations : 0;
  o.function_tolerance = function_tolerance;
  o.gradient_tolerance = gradient_tolerance;
  o.parameter_tolerance = parameter_tolerance;
  o.num_threads = num_threads;
  o.covariance_scale = covariance_scale;
  // The engine's covariance, for every covariance algorithm: the variance components
  // (covariance.scale) and a considered calibration's term rest on it.
  o.compute_covariance = refine;
  o.outlier_sigma = outlier_sigma;
  o.reject_sigma = refine ? reject_sigma : 0;
  return o;
}

bool SolverConfig::Check(std::string* error) const {
  namespace pl = plausible;
  if (!CheckRange("max_iterations", max_iterations, pl::kMaxIterations, error) ||
      !CheckRange("function_tolerance", function_tolerance, pl::kSolverTolerance, error) ||
      !CheckRange("gradient_tolerance", gradient_tolerance, pl::kSolverTolerance, error) ||
      !CheckRange("parameter_tolerance", parameter_tolerance, pl::kSolverTolerance, error) ||
      !CheckRange("loss.scale_px", loss_scale_px, pl::kLossScalePx, error) ||
      !CheckRange("num_threads", num_threads, pl::kThreads, error)) {
    return false;
  }
  if (distortion_auto) {
    for (const auto& n : fix) {
      if (n == "k1" || n == "k2" || n == "p1" || n == "p2" || n == "k3") {
        return *error = "fix: '" + n + "' with distortion: auto (the selection decides the " +
                        "distortion terms: remove it from fix, or set distortion: given)",
               false;
      }
    }
  }
  if (covariance_algorithm != "schur" && covariance_algorithm != "dense_svd" &&
      covariance_algorithm != "sparse_qr" && covariance_algorithm != "eigen_sparse_qr") {
    return *error = "covariance.algorithm '" + covariance_algorithm +
                    "' is not one of schur, dense_svd, sparse_qr, eigen_sparse_qr",
           false;
  }
  return true;
}

StatusOr<SolverConfig> LoadSolverConfig(const std::string& yaml_path) {
  YamlMap root = YamlMap::Load(yaml_path);
  if (!root.status().ok()) return root.status();
  SolverConfig c;
  c.path = yaml_path;
  for (const char* k : {"robust_loss", "pixel_sigma_px", "detection", "crosscheck", "min_views",
                        "fix_aspect_ratio", "zero_tangential", "fix_principal_point", "fix_k3"}) {
    if (root.Has(k)) {
      return Status::Error(yaml_path + ": this is a calibration config (key '" + k +
                           "'), for `carmba calibrate`; `carmba solve` needs a solver config "
                           "(initializer, loss, linear_solver, covariance; configs/posit_*.yaml)");
    }
  }
  std::string init = "posit", jac = "analytic", description;
  root.Get("name", &c.name, true);
  root.Get("description", &description);
  root.GetEnum("initializer", {"legacy_posit", "posit", "epnp", "sqpnp"}, &init);
  root.Get("refine", &c.refine);
  root.GetEnum("jacobians", {"analytic", "autodiff"}, &jac);
  YamlMap& loss = root.Map("loss");
  loss.GetEnum("type", {"trivial", "huber", "cauchy", "soft_l1"}, &c.loss);
  loss.GetInRange("scale_px", &c.loss_scale_px, plausible::kLossScalePx);
  root.GetEnum("linear_solver",
               {"dense_qr", "dense_normal_cholesky", "dense_schur", "sparse_schur",
                "sparse_normal_cholesky", "iterative_schur"},
               &c.linear_solver);
  root.GetInRange("max_iterations", &c.max_iterations, plausible::kMaxIterations);
  root.GetInRange("function_tolerance", &c.function_tolerance, plausible::kSolverTolerance);
  root.GetInRange("gradient_tolerance", &c.gradient_tolerance, plausible::kSolverTolerance);
  root.GetInRange("parameter_tolerance", &c.parameter_tolerance, plausible::kSolverTolerance);
  YamlMap& cov = root.Map("covariance");
  std::string scale = "per_group";
  cov.GetEnum("algorithm", {"schur", "dense_svd", "sparse_qr", "eigen_sparse_qr"},
              &c.covariance_algorithm);
  cov.GetEnum("scale", {"per_group", "apriori", "global", "aposteriori"}, &scale);
  root.GetInRange("num_threads", &c.num_threads, plausible::kThreads);
  root.Get("fix", &c.fix);
  std::string distortion = "given";
  root.GetEnum("distortion", {"given", "auto"}, &distortion);
  c.distortion_auto = distortion == "auto";
  for (const auto& n : c.fix) {
    if (std::find(kIntrinsicNames, kIntrinsicNames + kNumIntrinsics, n) ==
        kIntrinsicNames + kNumIntrinsics) {
      root.Fail("fix", "'" + n + "' is not an intrinsic (fx fy cx cy k1 k2 p1 p2 k3)");
    }
  }
  root.GetEnum("backend", {"ceres", "carmba_lm"}, &c.backend);
  root.Get("tre", &c.tre);
  root.Get("consider_calibration", &c.consider_calibration);
  YamlMap& outliers = root.Map("outliers");
  outliers.GetPositive("list_sigma", &c.outlier_sigma);
  outliers.GetNonNegative("reject_sigma", &c.reject_sigma);
  CARMBA_RETURN_IF_ERROR(root.Finish());
  ba::ParseCovarianceScale(scale, &c.covariance_scale);
  c.analytic_jacobians = jac == "analytic";
  c.initializer = init == "legacy_posit" ? Initializer::kLegacyPosit
                  : init == "epnp"       ? Initializer::kEpnp
                  : init == "sqpnp"      ? Initializer::kSqpnp
                                         : Initializer::kPosit;
  std::string err;
  if (!c.Check(&err)) return Status::Error(yaml_path + ": " + err);
  return c;
}

}  // namespace carmba
