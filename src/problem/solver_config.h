// The solver configuration: HOW a problem (problem/problem.h) is solved, for every problem kind,
// read from YAML. The reference of every key with its units is src/docs/formats.md.
//
// CONFIG FILE (configs/*.yaml):
//   name: posit_ba_analytic
//   initializer: posit            # legacy_posit | posit | epnp | sqpnp
//   refine: true                  # false: report the initialiser's poses (no bundle adjustment)
//   jacobians: analytic           # analytic | autodiff
//   loss: {type: trivial, scale_px: 1.0}   # trivial | huber | cauchy | soft_l1
//   linear_solver: dense_schur    # dense_qr | dense_normal_cholesky | dense_schur | sparse_schur |
//                                 # sparse_normal_cholesky | iterative_schur
//   max_iterations: 100
//   function_tolerance: 1e-12
//   gradient_tolerance: 1e-12
//   parameter_tolerance: 1e-12
//   covariance: {algorithm: schur, scale: apriori}  # or ceres::Covariance's dense_svd,
//                                                 # sparse_qr, eigen_sparse_qr;
//                                                 # aposteriori scales by s0^2
//   num_threads: 1
//   fix: [p1, p2, k3]             # joint problems: intrinsics held (default: none)
//   backend: ceres                # or carmba_lm (calibration-structured problems only)
//   outliers: {list_sigma: 4, reject_sigma: 0}   # list above 4 sigma; reject_sigma > 0 drops
//                                 # the worst above it and solves again, until none is left
//   tre: false                    # true: leave-one-marker-out target registration error
//                                 # (analysis/tre.h; one more solve per marker) in
//                                 result.json/report
//   consider_calibration: true    # pose problems: camera.json's covariance enters the
//                                 # covariances (intrinsics held, their uncertainty considered)
// A calibration config given here (it has keys such as robust_loss, detection, crosscheck) is an
// error saying so.
#pragma once

#include <string>
#include <vector>

#include "ba/bundle_adjuster.h"
#include "ba/solver_kinds.h"
#include "ba/variance_components.h"
#include "util/status.h"

namespace carmba {

class YamlMap;

enum class Initializer { kLegacyPosit, kPosit, kEpnp, kSqpnp };
inline constexpr EnumName<Initializer> kInitializerNames[] = {
    {Initializer::kLegacyPosit, "legacy_posit"},
    {Initializer::kPosit, "posit"},
    {Initializer::kEpnp, "epnp"},
    {Initializer::kSqpnp, "sqpnp"}};

struct SolverConfig {
  std::string name = "default";
  std::string path;
  Initializer initializer = Initializer::kPosit;
  bool refine = true;              // run the bundle adjustment
  bool analytic_jacobians = true;  // false: autodiff twin
  ba::Loss loss = ba::Loss::kTrivial;
  double loss_scale_px = 1.0;
  std::string linear_solver = "dense_schur";
  int max_iterations = 100;
  double function_tolerance = 1e-12;
  double gradient_tolerance = 1e-12;
  double parameter_tolerance = 1e-12;
  // schur: the engine's, from the residuals' Jacobians with the markers eliminated
  //        (ba/covariance.h; the fastest);
  // dense_svd | sparse_qr (SuiteSparse) | eigen_sparse_qr: ceres::Covariance (references).
  ba::CovarianceAlgorithm covariance_algorithm = ba::CovarianceAlgorithm::kSchur;
  // per_group: each observation group's sigmas scaled by its estimated variance factor where its
  // redundancy allows (ba/variance_components.h); apriori: the stated sigmas; global: sigma0^2.
  ba::CovarianceScale covariance_scale = ba::CovarianceScale::kPerGroup;
  int num_threads = 1;
  // Joint problems (joint/joint_solver.h): intrinsics held at their initial values, by name
  // (fx fy cx cy k1 k2 p1 p2 k3); pose problems hold all of them.
  std::vector<std::string> fix;
  // Joint problems with plate views: auto selects the distortion terms (k1 k2 | + p1 p2 | + k3 |
  // all) by AIC with held-out plate views (analysis/lens_models.h); `fix` then names none of them.
  // given: the terms `fix` leaves free (the selection is still run and warns when the given
  // model's principal point is more than 2 sigma from the recommended one's).
  bool distortion_auto = false;
  // Observations whose whitened residual exceeds outlier_sigma are listed; reject_sigma > 0
  // drops them one at a time and solves again (ba/bundle_adjuster.h).
  double outlier_sigma = 4.0;
  double reject_sigma = 0;
  // The engine's minimiser: ceres, or carmba_lm for calibration-structured problems
  // (ba/bundle_adjuster.h).
  ba::Backend backend = ba::Backend::kCeres;
  // Leave-one-marker-out target registration error (analysis/tre.h): one more solve per marker.
  bool tre = false;
  // Pose problems: when camera.json has a covariance, the intrinsics (held at its values) are
  // CONSIDERED: the poses' covariance (and everything derived from it) includes the
  // calibration's uncertainty (ba/covariance.h). false: the residuals' part only.
  bool consider_calibration = true;

  bool Check(std::string* error) const;
  // The engine's options: the one mapping of a solver config onto ba::BaOptions, for every
  // problem kind. refine: false gives a solve of 0 iterations with no covariance and no
  // rejection (the initial poses evaluated).
  ba::BaOptions ToBaOptions() const;
};

StatusOr<SolverConfig> LoadSolverConfig(const std::string& yaml_path);

// The keys a solver config and a calibration config share, read here only: loss {type,
// scale_px}, max_iterations, num_threads, fix, distortion, backend, outliers {list_sigma,
// reject_sigma}. A key that is absent keeps c's value.
void ReadSolveKeys(YamlMap& root, SolverConfig* c);

}  // namespace carmba
