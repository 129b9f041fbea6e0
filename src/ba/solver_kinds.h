// The engine's choices that configs name: robust loss, minimiser and covariance algorithm, each an
// enum with its one table of names (util/enum_names.h). Configs are read into these (problem/
// solver_config.h); reports print NameOf(...).
#pragma once

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

}  // namespace ba
}  // namespace carmba
