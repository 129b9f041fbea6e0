// Reading solver configuration files (format in solver_config.h).
#include "problem/solver_config.h"


#include "camera/camera.h"
#include "util/plausible.h"
#include "util/yaml_reader.h"

namespace carmba {

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
      !CheckRange("num_threads", num_threads, pl::kThreads, error) ||
      !CheckRange("outliers.list_sigma", outlier_sigma, pl::kSigmaMultiple, error)) {
    return false;
  }
  if (!(reject_sigma >= 0)) {
    return *error = "outliers.reject_sigma: expected >= 0 (0: list only)", false;
  }
  for (const auto& n : fix) {
    if (IntrinsicIndexOf(n) < 0) {
      return *error = "fix: unknown intrinsic '" + n + "' (expected fx fy cx cy k1 k2 p1 p2 k3)",
             false;
    }
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
  return true;
}

StatusOr<SolverConfig> LoadSolverConfig(const std::string& yaml_path) {
  YamlMap root = YamlMap::Load(yaml_path);
  if (!root.status().ok()) return root.status();
  SolverConfig c;
  c.path = yaml_path;
  for (const char* k : {"robust_loss",
                        "pixel_sigma_px",
                        "detection",
                        "crosscheck",
                        "min_views",
                        "fix_aspect_ratio",
                        "zero_tangential",
                        "fix_principal_point",
                        "fix_k3"}) {
    if (root.Has(k)) {
      return Status::Error(yaml_path + ": this is a calibration config (key '" + k +
                           "'), for `carmba calibrate`; `carmba solve` needs a solver config "
                           "(initializer, loss, linear_solver, covariance; configs/posit_*.yaml)");
    }
  }
  std::string jac = "analytic", description;
  root.Get("name", &c.name, true);
  root.Get("description", &description);
  root.GetEnum("initializer", kInitializerNames, &c.initializer);
  root.Get("refine", &c.refine);
  root.GetEnum("jacobians", {"analytic", "autodiff"}, &jac);
  ReadSolveKeys(root, &c);
  root.GetEnum("linear_solver",
               {"dense_qr",
                "dense_normal_cholesky",
                "dense_schur",
                "sparse_schur",
                "sparse_normal_cholesky",
                "iterative_schur"},
               &c.linear_solver);
  root.GetInRange("function_tolerance", &c.function_tolerance, plausible::kSolverTolerance);
  root.GetInRange("gradient_tolerance", &c.gradient_tolerance, plausible::kSolverTolerance);
  root.GetInRange("parameter_tolerance", &c.parameter_tolerance, plausible::kSolverTolerance);
  YamlMap& cov = root.Map("covariance");
  cov.GetEnum("algorithm", ba::kCovarianceAlgorithmNames, &c.covariance_algorithm);
  cov.GetEnum("scale", ba::kCovarianceScaleNames, &c.covariance_scale);
  root.Get("tre", &c.tre);
  root.Get("consider_calibration", &c.consider_calibration);
  CARMBA_RETURN_IF_ERROR(root.Finish());
  c.analytic_jacobians = jac == "analytic";
  std::string err;
  if (!c.Check(&err)) return Status::Error(yaml_path + ": " + err);
  return c;
}

void ReadSolveKeys(YamlMap& root, SolverConfig* c) {
  YamlMap& loss = root.Map("loss");
  loss.GetEnum("type", ba::kLossNames, &c->loss);
  loss.GetInRange("scale_px", &c->loss_scale_px, plausible::kLossScalePx);
  root.GetInRange("max_iterations", &c->max_iterations, plausible::kMaxIterations);
  root.GetInRange("num_threads", &c->num_threads, plausible::kThreads);
  root.Get("fix", &c->fix);
  for (const auto& n : c->fix) {
    if (IntrinsicIndexOf(n) < 0) {
      root.Fail("fix", "'" + n + "' is not an intrinsic (fx fy cx cy k1 k2 p1 p2 k3)");
    }
  }
  std::string distortion = c->distortion_auto ? "auto" : "given";
  root.GetEnum("distortion", {"given", "auto"}, &distortion);
  c->distortion_auto = distortion == "auto";
  root.GetEnum("backend", ba::kBackendNames, &c->backend);
  YamlMap& outliers = root.Map("outliers");
  outliers.GetInRange("list_sigma", &c->outlier_sigma, plausible::kSigmaMultiple);
  outliers.GetNonNegative("reject_sigma", &c->reject_sigma);
}

}  // namespace carmba
