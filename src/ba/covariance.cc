#include "ba/covariance.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>
#include <string>

namespace carmba {
namespace ba {
namespace {

std::string JoinNames(const std::vector<std::string>& names) {
  std::string s;
  for (size_t i = 0; i < names.size(); ++i) s += (i ? ", " : "") + names[i];
  return s;
}

// Names of the free parameters that move most along `x` (free-state vector), scaled by the
// square root of the information's diagonal so that units do not matter; largest first.
std::string NullDirectionNames(const StateLayout& layout,
                               const Eigen::VectorXd& x,
                               const Eigen::VectorXd& diag) {
  Eigen::VectorXd s = (x.array() * diag.cwiseMax(0).cwiseSqrt().array()).abs();
  std::vector<int> idx(s.size());
  for (int i = 0; i < static_cast<int>(s.size()); ++i) idx[i] = i;
  std::sort(idx.begin(), idx.end(), [&](int a, int b) { return s[a] > s[b]; });
  std::vector<std::string> names;
  const double top = s.size() ? s[idx[0]] : 0.0;
  for (int i : idx) {
    if (names.size() == 8 || !(s[i] >= 0.2 * top)) break;
    names.push_back(layout.FreeName(i));
  }
  int more = 0;
  for (int i : idx) more += (s[i] >= 0.2 * top) ? 1 : 0;
  more -= static_cast<int>(names.size());
  return JoinNames(names) + (more > 0 ? " and " + std::to_string(more) + " more" : "");
}

}  // namespace

int SchurCovariance::num_eliminated_blocks() const {
  int n = 0;
  for (const auto& l : levels_) n += static_cast<int>(l.size());
  return n;
}

namespace {

using BlockRows = std::vector<std::map<int, Eigen::MatrixXd>>;

// H = J^T J in blocks over the linearisation's rows, and its diagonal over the free state. Every
// free block must be in some residual.
Status NormalBlocks(const StateLayout& layout,
                    const Linearization& lin,
                    BlockRows* H,
                    Eigen::VectorXd* diag) {
  const int nb = static_cast<int>(layout.blocks().size());
  H->assign(nb, {});
  *diag = Eigen::VectorXd::Zero(layout.num_free());
  for (const LinearizedBlock& r : lin.rows) {
    for (size_t i = 0; i < r.blocks.size(); ++i) {
      if (!r.J[i].allFinite())
        return Status::Error("covariance: non-finite Jacobian at the solution");
      for (size_t j = 0; j < r.blocks.size(); ++j) {
        auto& row = (*H)[r.blocks[i]];
        auto it = row.find(r.blocks[j]);
        if (it == row.end()) {
          row.emplace(r.blocks[j], r.J[i].transpose().lazyProduct(r.J[j]));
        } else {
          // Tiny blocks (2 x 6, 2 x 9): the coefficient-wise product beats the GEMM path.
          it->second.noalias() += r.J[i].transpose().lazyProduct(r.J[j]);
        }
      }
    }
  }
  for (int b = 0; b < nb; ++b) {
    const BlockInfo& bi = layout.block(b);
    if (bi.constant) continue;
    auto it = (*H)[b].find(b);
    if (it == (*H)[b].end()) {
      return Status::Error("covariance: " + layout.ParameterName(b, bi.free[0]) +
                           " is in no residual (not observed)");
    }
    diag->segment(bi.free_offset, bi.free.size()) = it->second.diagonal();
  }
  return Status::Ok();
}

// The first level: the free points (markers, plate points).
std::vector<int> PointBlocks(const StateLayout& layout) {
  std::vector<int> level;
  for (int b = 0; b < static_cast<int>(layout.blocks().size()); ++b) {
    const BlockInfo& bi = layout.block(b);
    if (!bi.constant && (bi.kind == BlockKind::kMarker || bi.kind == BlockKind::kPlatePoint))
      level.push_back(b);
  }
  return level;
}

// The second level: the free plate poses, if still mutually uncoupled (else none).
std::vector<int> UncoupledPlatePoses(const StateLayout& layout, const BlockRows& H) {
  std::vector<int> level;
  for (int b = 0; b < static_cast<int>(layout.blocks().size()); ++b) {
    const BlockInfo& bi = layout.block(b);
    if (bi.constant || bi.kind != BlockKind::kPlatePose) continue;
    level.push_back(b);
    for (auto& [c, m] : H[b]) {
      if (c != b && layout.block(c).kind == BlockKind::kPlatePose) return {};
    }
  }
  return level;
}

}  // namespace

Status SchurCovariance::EliminateLevel(const std::vector<int>& level,
                                       double min_rcond,
                                       BlockRows* H_ptr) {
  BlockRows& H = *H_ptr;
  const StateLayout& layout = *layout_;
  std::vector<Eliminated> done;
  const std::set<int> in_level(level.begin(), level.end());
  for (int e : level) {
    const BlockInfo& bi = layout.block(e);
    const Eigen::MatrixXd& Hee = H[e].at(e);
    Eigen::LLT<Eigen::MatrixXd> llt(Hee);
    const Eigen::VectorXd d = Hee.diagonal();
    bool ok = llt.info() == Eigen::Success && (d.array() > 0).all();
    if (ok) {
      const Eigen::VectorXd is = d.cwiseSqrt().cwiseInverse();
      Eigen::LLT<Eigen::MatrixXd> scaled(is.asDiagonal() * Hee * is.asDiagonal());
      ok = scaled.info() == Eigen::Success && scaled.rcond() > min_rcond;
    }
    if (!ok) {
      std::vector<std::string> names;
      for (int i : bi.free) names.push_back(layout.ParameterName(e, i));
      return Status::Error("rank-deficient: " + JoinNames(names) +
                           " not determined (too few observations and no prior)",
                           ErrorKind::kNotDetermined);
    }
    Eliminated el;
    el.block = e;
    el.H_inv = llt.solve(Eigen::MatrixXd::Identity(Hee.rows(), Hee.cols()));
    for (auto& [r, Her] : H[e]) {
      if (r == e) continue;
      if (in_level.count(r)) return Status::Error("covariance: coupled blocks in one level");
      el.H_er.emplace_back(r, Her);
    }
    for (auto& [r1, H1e] : el.H_er) {
      const Eigen::MatrixXd A = H1e.transpose() * el.H_inv;  // H_r1e H_ee^-1
      for (auto& [r2, He2] : el.H_er) {
        Eigen::MatrixXd upd = -A * He2;
        auto it = H[r1].find(r2);
        if (it == H[r1].end()) {
          H[r1].emplace(r2, std::move(upd));
        } else {
          it->second += upd;
        }
      }
      H[r1].erase(e);
    }
    H[e].clear();
    done.push_back(std::move(el));
  }
  levels_.push_back(std::move(done));
  return Status::Ok();
}

Status SchurCovariance::NullDirectionError(const Eigen::MatrixXd& S, const Eigen::VectorXd& is,
                                           double rcond, const Eigen::VectorXd& diag) const {
  const StateLayout& layout = *layout_;
  const Eigen::Index K = kept_dim_;
  Eigen::MatrixXd Sc = is.asDiagonal() * S * is.asDiagonal();
  if (!Sc.allFinite()) Sc = Eigen::MatrixXd::Identity(K, K);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Sc);
  const Eigen::VectorXd xk = is.asDiagonal() * es.eigenvectors().col(0);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(n_);
  for (size_t i = 0; i < kept_blocks_.size(); ++i) {
    const BlockInfo& bi = layout.block(kept_blocks_[i]);
    x.segment(bi.free_offset, bi.free.size()) = xk.segment(kept_offset_[i], bi.free.size());
  }
  for (auto l = levels_.rbegin(); l != levels_.rend(); ++l) {
    for (const auto& e : *l) {
      const BlockInfo& be = layout.block(e.block);
      Eigen::VectorXd rhs = Eigen::VectorXd::Zero(be.free.size());
      for (const auto& [r, Her] : e.H_er) {
        const BlockInfo& br = layout.block(r);
        rhs -= Her * x.segment(br.free_offset, br.free.size());
      }
      x.segment(be.free_offset, be.free.size()) = e.H_inv * rhs;
    }
  }
  char rc[32];
  std::snprintf(rc, sizeof rc, "%.1e", rcond);
  return Status::Error(
      std::string("rank-deficient (reciprocal condition ") + rc +
          "): a free direction (gauge) moves " + NullDirectionNames(layout, x, diag) +
          "; fix it with priors (CT priors on the markers, the plate prior, an intrinsics prior) "
          "or hold parameters",
      ErrorKind::kNotDetermined);
}

Status SchurCovariance::InvertKept(const BlockRows& H,
                                   const Eigen::VectorXd& diag,
                                   double min_rcond) {
  const StateLayout& layout = *layout_;
  const int nb = static_cast<int>(layout.blocks().size());
  std::set<int> eliminated;
  for (const auto& l : levels_) {
    for (const auto& e : l) eliminated.insert(e.block);
  }
  for (int b = 0; b < nb; ++b) {
    const BlockInfo& bi = layout.block(b);
    if (bi.constant || eliminated.count(b)) continue;
    kept_offset_.push_back(static_cast<int>(kept_dim_));
    kept_blocks_.push_back(b);
    kept_dim_ += static_cast<Eigen::Index>(bi.free.size());
  }
  const Eigen::Index K = kept_dim_;
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(K, K);
  std::map<int, int> kept_index;
  for (size_t i = 0; i < kept_blocks_.size(); ++i)
    kept_index[kept_blocks_[i]] = static_cast<int>(i);
  for (size_t i = 0; i < kept_blocks_.size(); ++i) {
    for (auto& [c, m] : H[kept_blocks_[i]]) {
      const int j = kept_index.at(c);
      S.block(kept_offset_[i], kept_offset_[j], m.rows(), m.cols()) = m;
    }
  }
  S = 0.5 * (S + S.transpose()).eval();
  if (K == 0) return Status::Ok();
  const Eigen::VectorXd d = S.diagonal();
  bool ok = S.allFinite() && (d.array() > 0).all();
  Eigen::VectorXd is = Eigen::VectorXd::Ones(K);
  Eigen::LLT<Eigen::MatrixXd> llt;
  if (ok) {
    is = d.cwiseSqrt().cwiseInverse();
    llt.compute(is.asDiagonal() * S * is.asDiagonal());
    ok = llt.info() == Eigen::Success && llt.rcond() > min_rcond;
  }
  if (!ok) {
    return NullDirectionError(S, is, llt.info() == Eigen::Success ? llt.rcond() : 0.0, diag);
  }
  const Eigen::MatrixXd Sc_inv = llt.solve(Eigen::MatrixXd::Identity(K, K));
  S_inv_ = is.asDiagonal() * Sc_inv * is.asDiagonal();
  S_inv_ = 0.5 * (S_inv_ + S_inv_.transpose()).eval();
  return Status::Ok();
}

Status SchurCovariance::AddConsideredCalibration(const Linearization& lin) {
  // Considered calibration: H_fc from the held intrinsics' columns, D = -H_ff^-1 H_fc.
  const StateLayout& layout = *layout_;
  const int nc = layout.num_consider();
  consider_covariance_ = layout.consider_covariance();
  D_ = Eigen::MatrixXd::Zero(n_, nc);
  if (nc == 0) return Status::Ok();
  Eigen::MatrixXd H_fc = Eigen::MatrixXd::Zero(n_, nc);
  for (const LinearizedBlock& r : lin.rows) {
    if (r.consider_block < 0) continue;
    if (!r.J_consider.allFinite())
      return Status::Error("covariance: non-finite Jacobian at the solution");
    const BlockInfo& bc = layout.block(r.consider_block);
    for (size_t i = 0; i < r.blocks.size(); ++i) {
      const BlockInfo& bi = layout.block(r.blocks[i]);
      H_fc.block(bi.free_offset, bc.consider_offset, bi.free.size(), bc.consider.size())
          .noalias() += r.J[i].transpose() * r.J_consider;
    }
  }
  D_ = -Solve(H_fc);
  return Status::Ok();
}

StatusOr<std::shared_ptr<SchurCovariance>> SchurCovariance::Compute(const StateLayout& layout,
                                                                    const Linearization& lin,
                                                                    double min_rcond) {
  std::shared_ptr<SchurCovariance> out(new SchurCovariance());
  out->layout_ = &layout;
  out->n_ = layout.num_free();
  BlockRows H;
  Eigen::VectorXd diag;
  CARMBA_RETURN_IF_ERROR(NormalBlocks(layout, lin, &H, &diag));
  const std::vector<int> points = PointBlocks(layout);
  if (!points.empty()) CARMBA_RETURN_IF_ERROR(out->EliminateLevel(points, min_rcond, &H));
  const std::vector<int> plate_poses = UncoupledPlatePoses(layout, H);
  if (!plate_poses.empty()) CARMBA_RETURN_IF_ERROR(out->EliminateLevel(plate_poses, min_rcond, &H));
  CARMBA_RETURN_IF_ERROR(out->InvertKept(H, diag, min_rcond));
  CARMBA_RETURN_IF_ERROR(out->AddConsideredCalibration(lin));
  return out;
}

Eigen::MatrixXd SchurCovariance::ConsiderGradient(const Eigen::MatrixXd& G,
                                                  const Eigen::MatrixXd& Gc) const {
  Eigen::MatrixXd T = G * D_;
  if (Gc.size() > 0) T += Gc;
  return T;
}

Eigen::MatrixXd SchurCovariance::Solve(const Eigen::MatrixXd& B_in) const {
  Eigen::MatrixXd B = B_in;
  const StateLayout& L = *layout_;
  auto seg = [&](Eigen::MatrixXd& M, int b) {
    const BlockInfo& bi = L.block(b);
    return M.middleRows(bi.free_offset, bi.free.size());
  };
  for (const auto& level : levels_) {
    for (const auto& e : level) {
      const Eigen::MatrixXd y = e.H_inv * seg(B, e.block);
      for (const auto& [r, Her] : e.H_er) seg(B, r).noalias() -= Her.transpose() * y;
    }
  }
  Eigen::MatrixXd X = Eigen::MatrixXd::Zero(B.rows(), B.cols());
  if (kept_dim_ > 0) {
    Eigen::MatrixXd bk(kept_dim_, B.cols());
    for (size_t i = 0; i < kept_blocks_.size(); ++i) {
      const BlockInfo& bi = L.block(kept_blocks_[i]);
      bk.middleRows(kept_offset_[i], bi.free.size()) = seg(B, kept_blocks_[i]);
    }
    const Eigen::MatrixXd xk = S_inv_ * bk;
    for (size_t i = 0; i < kept_blocks_.size(); ++i) {
      const BlockInfo& bi = L.block(kept_blocks_[i]);
      seg(X, kept_blocks_[i]) = xk.middleRows(kept_offset_[i], bi.free.size());
    }
  }
  for (auto l = levels_.rbegin(); l != levels_.rend(); ++l) {
    for (const auto& e : *l) {
      Eigen::MatrixXd rhs = seg(B, e.block);
      for (const auto& [r, Her] : e.H_er) rhs.noalias() -= Her * seg(X, r);
      seg(X, e.block) = e.H_inv * rhs;
    }
  }
  return X;
}

Eigen::MatrixXd SchurCovariance::BlockCovariance(const std::vector<int>& blocks) const {
  const StateLayout& L = *layout_;
  int ambient = 0, nfree = 0;
  for (int b : blocks) {
    ambient += L.block(b).size;
    nfree += static_cast<int>(L.block(b).free.size());
  }
  // E selects the blocks' free coordinates; B maps them to the ambient parameters (block-diagonal
  // of the blocks' bases: held parameters are zero rows, tied ones follow their free parameter).
  Eigen::MatrixXd E = Eigen::MatrixXd::Zero(n_, nfree);
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(ambient, nfree);
  int c = 0, a = 0;
  for (int b : blocks) {
    const BlockInfo& bi = L.block(b);
    const int k = static_cast<int>(bi.free.size());
    for (int i = 0; i < k; ++i) E(bi.free_offset + i, c + i) = 1.0;
    if (k > 0) B.block(a, c, bi.size, k) = bi.basis;
    c += k;
    a += bi.size;
  }
  const Eigen::MatrixXd X = E.transpose() * Solve(E);  // nfree x nfree
  const Eigen::MatrixXd C = B * X * B.transpose();
  return 0.5 * (C + C.transpose());
}

Eigen::MatrixXd SchurCovariance::BlockConsiderCovariance(const std::vector<int>& blocks) const {
  const StateLayout& L = *layout_;
  int ambient = 0;
  for (int b : blocks) ambient += L.block(b).size;
  // Rows of D for the blocks, mapped to the ambient parameters by the blocks' bases.
  Eigen::MatrixXd T = Eigen::MatrixXd::Zero(ambient, num_consider());
  if (num_consider() == 0) return Eigen::MatrixXd::Zero(ambient, ambient);
  int a = 0;
  for (int b : blocks) {
    const BlockInfo& bi = L.block(b);
    if (!bi.free.empty())
      T.middleRows(a, bi.size) = bi.basis * D_.middleRows(bi.free_offset, bi.free.size());
    a += bi.size;
  }
  const Eigen::MatrixXd C = T * consider_covariance_ * T.transpose();
  return 0.5 * (C + C.transpose());
}

ErrorBudget SchurCovariance::Budget(const Eigen::MatrixXd& G,
                                    const Linearization& lin,
                                    double scale,
                                    const Eigen::MatrixXd& Gc) const {
  const StateLayout& L = *layout_;
  const Eigen::MatrixXd A = Solve(G.transpose());  // n x q
  ErrorBudget out;
  out.by_source = Eigen::MatrixXd::Zero(G.rows(), kNumSources);
  for (const LinearizedBlock& r : lin.rows) {
    Eigen::MatrixXd JA = Eigen::MatrixXd::Zero(r.J.empty() ? 0 : r.J[0].rows(), G.rows());
    for (size_t i = 0; i < r.blocks.size(); ++i) {
      const BlockInfo& bi = L.block(r.blocks[i]);
      JA.noalias() += r.J[i] * A.middleRows(bi.free_offset, bi.free.size());
    }
    out.by_source.col(static_cast<int>(r.source)) += JA.colwise().squaredNorm().transpose();
  }
  out.by_source *= scale;
  out.total = (G * A).diagonal() * scale;
  if (num_consider() > 0) {
    const Eigen::MatrixXd T = ConsiderGradient(G, Gc);  // q x nc
    const Eigen::VectorXd var = (T * consider_covariance_).cwiseProduct(T).rowwise().sum();
    out.by_source.col(static_cast<int>(Source::kCalibration)) = var;
    out.total += var;
  }
  return out;
}

}  // namespace ba
}  // namespace carmba
