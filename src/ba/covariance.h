// Covariance of any set of parameter blocks, and error budgets, from ONE module (COLMAP's
// estimators/covariance.cc is the model).
//
// Input: the problem linearised at the solution -- every residual block's whitened Jacobian with
// respect to the FREE parameters of the blocks it touches (held intrinsics are dropped columns,
// constant blocks are absent), corrected for a robust loss as Ceres corrects it
// (ceres/internal/corrector.cc), and the noise source the block belongs to (ba/problem.h).
//
// Information H = J^T J, kept block-sparse. It is reduced by the Schur complement in two levels:
//   1. the points (markers, free plate points): each touches only poses, intrinsics and its own
//      prior, so H restricted to them is block-diagonal (3x3 blocks);
//   2. then the plate poses, when after level 1 they are still uncoupled from each other (they
//      are unless the plate points are free): 6x6 blocks coupled only to the intrinsics;
//   S = H_KK - H_KE H_EE^-1 H_EK over what is kept (intrinsics and object poses; for a
//   calibration only the 9 intrinsics), dense, Jacobi-scaled and Cholesky-factored.
// Any block or cross-block of H^-1 then follows by forward reduction and back-substitution
// (`Solve`). Point covariances are MARGINAL (not conditioned on the poses as COLMAP's are).
//
// Gauge and rank: a singular 3x3 / 6x6 block (a marker seen in one view without a prior) or a
// singular S (markers free without priors: a similarity gauge) is refused, naming the parameters
// that move along the null direction (the smallest eigenvector of the Jacobi-scaled S, carried
// back through the eliminated blocks): never a covariance full of noise.
//
// Error budget (shared/notes/joint-ba.md): for derived quantities f with gradient G = df/dx (rows
// over the free state) and whitened rows grouped by independent source s,
//   Var(f) = sum_s G H^-1 J_s^T J_s H^-1 G^T,
// computed as a = H^-1 G^T once, then |J_b a|^2 accumulated per residual block b into its source.
// The shares add up to the total G H^-1 G^T (the sources cover all rows).
//
// Considered calibration (Schmidt's consider covariance; Tapley, Schutz & Born, "Statistical
// Orbit Determination", sec. 6.3). Held intrinsics c with a covariance Sigma_c
// (IntrinsicsGroup::consider_*) stay held in the solve, so the estimate x_f of the free
// parameters minimises |r(x_f, c0)|^2 at the held c0. To first order an error dc = c0 - c_true
// moves it by  dx_f = D dc,  D = -H_ff^-1 H_fc,  H_fc = sum_b J_b,f^T J_b,c (the whitened
// Jacobians' columns of the held intrinsics, loss-corrected like the free ones). Independent of
// the pixel noise, so
//   Sigma_f = s H_ff^-1 + D Sigma_c D^T
// with s the covariance scale (1, or sigma0^2 a posteriori: it scales the residuals' noise
// only; Sigma_c is the calibration's own covariance in physical units, never rescaled). D is
// computed once, n x |c| (`consider_sensitivity`). A quantity f(x_f, c) with gradients G (over
// the free state) and Gc (over c, for a direct dependence on the held intrinsics) has
//   Var f = s G H^-1 G^T + (G D + Gc) Sigma_c (G D + Gc)^T,
// the second term the budget's kCalibration share.
#pragma once

#include <Eigen/Dense>
#include <map>
#include <memory>
#include <vector>

#include "ba/problem.h"
#include "util/status.h"

namespace carmba {
namespace ba {

struct LinearizedBlock {
  Source source = Source::kPlatePixels;
  NoiseGroup group = NoiseGroup::kPlatePixels;  // for the variance components
  Eigen::VectorXd r;              // the whitened residuals at the solution (no loss)
  std::vector<int> blocks;        // layout blocks (free ones only) this residual block touches
  std::vector<Eigen::MatrixXd> J; // per block: rows x |free parameters of the block|
  // The considered intrinsics block it touches (-1: none) and the Jacobian over its considered
  // parameters (rows x |BlockInfo::consider|).
  int consider_block = -1;
  Eigen::MatrixXd J_consider;
};

struct Linearization {
  std::vector<LinearizedBlock> rows;
};

struct ErrorBudget {
  Eigen::VectorXd total;       // q variances, s G H^-1 G^T + the considered calibration's
  Eigen::MatrixXd by_source;   // q x kNumSources variances; rows add up to `total`
};

class SchurCovariance {
 public:
  // Errors: rank deficiency (naming the null direction), non-finite Jacobians.
  static StatusOr<std::shared_ptr<SchurCovariance>> Compute(
      const StateLayout& layout, const Linearization& lin, double min_reciprocal_condition = 1e-14);

  int num_free() const { return n_; }
  // H^-1 B, B num_free x k.
  Eigen::MatrixXd Solve(const Eigen::MatrixXd& B) const;
  // Covariance of the concatenated blocks in their full (ambient) parameters, held parameters as
  // zero rows and columns. Blocks are layout indices; constant blocks give zero blocks.
  // H^-1 only (the residuals' noise, unscaled): BaResult::Covariance adds the consider term.
  Eigen::MatrixXd BlockCovariance(const std::vector<int>& blocks) const;
  // The considered calibration's part D Sigma_c D^T of the same blocks (zero without one).
  Eigen::MatrixXd BlockConsiderCovariance(const std::vector<int>& blocks) const;
  // The budget of quantities with gradient rows G (q x num_free) over `lin`'s rows, the residual
  // sources scaled by `scale` (the covariance scale), plus the considered calibration's share
  // (kCalibration) with the direct gradient Gc (q x num_consider; empty: zero).
  ErrorBudget Budget(const Eigen::MatrixXd& G,
                     const Linearization& lin,
                     double scale = 1.0,
                     const Eigen::MatrixXd& Gc = Eigen::MatrixXd()) const;
  // Considered calibration: D = d x_f / d c (num_free x num_consider) and Sigma_c.
  int num_consider() const { return static_cast<int>(consider_covariance_.rows()); }
  const Eigen::MatrixXd& consider_sensitivity() const { return D_; }
  const Eigen::MatrixXd& consider_covariance() const { return consider_covariance_; }
  // The total consider gradient G D + Gc of quantities (q x num_consider).
  Eigen::MatrixXd ConsiderGradient(const Eigen::MatrixXd& G,
                                   const Eigen::MatrixXd& Gc = Eigen::MatrixXd()) const;
  // Sizes of the eliminated and kept parts (for tests and reports).
  int num_eliminated_blocks() const;
  int kept_size() const { return static_cast<int>(kept_dim_); }

 private:
  // Block-sparse symmetric matrix over layout blocks: H[b][c] = H_bc (both directions).
  using BlockRows = std::vector<std::map<int, Eigen::MatrixXd>>;
  SchurCovariance() = default;
  struct Eliminated {
    int block;                         // layout block
    Eigen::MatrixXd H_inv;             // (H_ee)^-1 at its level
    std::vector<std::pair<int, Eigen::MatrixXd>> H_er;  // neighbours at its level
  };
  // The stages of Compute: eliminate one level of mutually uncoupled blocks from H (into
  // levels_), invert the Schur complement of the blocks kept (diag: H's diagonal, to name a null
  // direction), and the considered calibration's sensitivity D.
  Status EliminateLevel(const std::vector<int>& level, double min_rcond, BlockRows* H);
  Status InvertKept(const BlockRows& H, const Eigen::VectorXd& diag, double min_rcond);
  // The rank-deficiency error naming the free direction: the smallest eigenvector of the scaled
  // complement Sc (scaling `is`), carried back through the eliminated levels.
  Status NullDirectionError(const Eigen::MatrixXd& S, const Eigen::VectorXd& is, double rcond,
                            const Eigen::VectorXd& diag) const;
  Status AddConsideredCalibration(const Linearization& lin);
  const StateLayout* layout_ = nullptr;
  int n_ = 0;
  std::vector<std::vector<Eliminated>> levels_;
  std::vector<int> kept_blocks_;              // layout blocks of S, in order
  std::vector<int> kept_offset_;              // their offsets in S
  Eigen::Index kept_dim_ = 0;
  Eigen::MatrixXd S_inv_;                     // (S)^-1 over the kept blocks
  Eigen::MatrixXd D_;                         // -H_ff^-1 H_fc (num_free x num_consider)
  Eigen::MatrixXd consider_covariance_;       // Sigma_c
};

}  // namespace ba
}  // namespace carmba
