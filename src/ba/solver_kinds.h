// The engine's choices that configs name: robust loss, minimiser and covariance algorithm, each an
// enum with its one table of names (util/enum_names.h), and how a minimisation ended. Configs are
// read into these (problem/ solver_config.h); reports print NameOf(...).
#pragma once

#include <string>

#include "util/enum_names.h"

namespace carmba {
namespace ba {

// The robust loss on the reprojection blocks (ba/schur_lm.h MakeLossFunction).
enum class Loss { kTrivial, kHuber, kCauchy, kSoftL1 };
inline constexpr EnumName<Loss> kLossNames[] = {
    {Loss::kTrivial, "trivial"}, {Loss::kHuber, "huber"}, {Loss::kCauchy, "cauchy"},
    {Loss::kSoftL1, "soft_l1"}};

// The minimiser: Ceres, or carmba's own Schur Levenberg-Marquardt (ba/schur_lm.h) for
// calibration-structured problems.
enum class Backend { kCeres, kCarmbaLm };
inline constexpr EnumName<Backend> kBackendNames[] = {{Backend::kCeres, "ceres"},
                                                      {Backend::kCarmbaLm, "carmba_lm"}};

// The covariance: the engine's Schur complement (ba/covariance.h), or ceres::Covariance's
// algorithms, the references it is tested against.
enum class CovarianceAlgorithm { kSchur, kDenseSvd, kSparseQr, kEigenSparseQr };
inline constexpr EnumName<CovarianceAlgorithm> kCovarianceAlgorithmNames[] = {
    {CovarianceAlgorithm::kSchur, "schur"},
    {CovarianceAlgorithm::kDenseSvd, "dense_svd"},
    {CovarianceAlgorithm::kSparseQr, "sparse_qr"},
    {CovarianceAlgorithm::kEigenSparseQr, "eigen_sparse_qr"}};

// How a minimisation ended (Ceres's TerminationType; carmba's LM ends in the first two).
enum class Termination { kConvergence, kNoConvergence, kFailure, kUserSuccess, kUserFailure };
inline constexpr EnumName<Termination> kTerminationNames[] = {
    {Termination::kConvergence, "CONVERGENCE"},
    {Termination::kNoConvergence, "NO_CONVERGENCE"},
    {Termination::kFailure, "FAILURE"},
    {Termination::kUserSuccess, "USER_SUCCESS"},
    {Termination::kUserFailure, "USER_FAILURE"}};

// The termination as carmba prints it, with the minimiser that reached it:
// "CONVERGENCE (Ceres)", "NO_CONVERGENCE (carmba LM)".
inline std::string TerminationText(Termination termination, Backend backend) {
  return std::string(NameOf(kTerminationNames, termination)) +
         (backend == Backend::kCarmbaLm ? " (carmba LM)" : " (Ceres)");
}

}  // namespace ba
}  // namespace carmba
