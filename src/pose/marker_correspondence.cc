#include "pose/marker_correspondence.h"

#include <ceres/rotation.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <sstream>

#include "camera/camera_model.h"
#include "util/format.h"

namespace carmba {

bool CorrespondenceOptions::Check(std::string* error) const {
  if (!(gate_px > 0 && gate_px < 1000) ||
      !(predict_gate_px >= gate_px && predict_gate_px < 10000)) {
    *error = "gate_px: expected 0 < gate_px <= predict_gate_px < 10000";
    return false;
  }
  if (!(accept_rms_px > 0 && accept_rms_px <= gate_px)) {
    *error = "accept_rms_px: expected 0 < accept_rms_px <= gate_px";
    return false;
  }
  if (min_markers < 4) {
    *error = "min_markers: expected >= 4 (a pose and its check need 4 markers)";
    return false;
  }
  if (!(px_per_mm >= 0 && px_per_mm < 1000) || !(scale_tolerance >= 0 && scale_tolerance < 10)) {
    *error = "px_per_mm (0 = unknown .. 1000) and scale_tolerance (0 .. 10) expected";
    return false;
  }
  if (!(min_fraction >= 0 && min_fraction <= 1)) {
    *error = "min_fraction: expected 0 .. 1";
    return false;
  }
  if (!(ambiguity_margin_px >= 0) || max_blobs < min_markers || max_blobs > 200) {
    *error = "ambiguity_margin_px >= 0 and min_markers <= max_blobs <= 200 expected";
    return false;
  }
  return true;
}

namespace {

struct Scored {
  std::vector<int> marker_of_blob;
  std::vector<int> blob_of_marker;
  Pose6 pose = Pose6::Zero();
  int num_labelled = 0;
  double ss = 0;     // sum of squared distances of the pairs (px^2)
  double score = 0;  // MSAC
  int counted = 0;   // markers projecting inside the image
  double Rms() const { return num_labelled ? std::sqrt(ss / (2.0 * num_labelled)) : 0; }
  double ScoreRms() const { return counted ? std::sqrt(score / (2.0 * counted)) : 0; }
};

// The search's budget of P3P solves beyond its first pass (LabelMarkerBlobs; 9 markers and 7
// blobs are at most 84 x 210 = 17640).
constexpr int kMaxHypotheses = 50000;

// "60 %" of a fraction.
std::string Percent(double fraction) { return Fmt("%.0f", 100 * fraction) + " %"; }

// Why a labelling is not accepted (Labeller::Rejection), and the requirement it failed, stated.
struct Refusal {
  enum class Kind { kNone, kTooFewMarkers, kRms, kWrongDepth, kPairsDisagree };
  Kind kind = Kind::kNone;
  std::string why;
};

class Labeller {
 public:
  Labeller(const Camera& cam,
           const std::vector<Eigen::Vector3d>& markers,
           const std::vector<Eigen::Vector2d>& blobs,
           const CorrespondenceOptions& o,
           const ViewContext& context)
      : cam_(cam), P_(markers), q_(blobs), o_(o), context_(context) {
    proj_.resize(P_.size());
    ok_.resize(P_.size());
  }

  // Projects all markers; false entries in ok_ for points behind the source.
  void Project(const Pose6& pose) const {
    for (size_t a = 0; a < P_.size(); ++a) {
      ok_[a] = ProjectPoint(cam_.params.data(), pose.data(), P_[a].data(), proj_[a].data()) &&
               proj_[a].allFinite();
    }
  }
  bool InImage(size_t a) const {
    return ok_[a] && proj_[a].x() >= -0.5 && proj_[a].y() >= -0.5 &&
           proj_[a].x() <= cam_.width - 0.5 && proj_[a].y() <= cam_.height - 0.5;
  }

  // Markers with some blob within `gate` of their projection (after Project).
  int CountNear(double gate) const {
    const double g2 = gate * gate;
    int count = 0;
    for (size_t a = 0; a < P_.size(); ++a) {
      if (!ok_[a]) continue;
      for (const auto& q : q_) {
        if ((q - proj_[a]).squaredNorm() < g2) {
          ++count;
          break;
        }
      }
    }
    return count;
  }

  // Greedy gated pairing (after Project) and the MSAC score with gate_px.
  Scored Pair(const Pose6& pose, double gate) const {
    Scored s;
    s.pose = pose;
    s.marker_of_blob.assign(q_.size(), -1);
    s.blob_of_marker.assign(P_.size(), -1);
    struct Cand {
      double d2;
      int a, i;
    };
    std::vector<Cand> cands;
    const double g2 = gate * gate;
    for (size_t a = 0; a < P_.size(); ++a) {
      if (!ok_[a]) continue;
      for (size_t i = 0; i < q_.size(); ++i) {
        const double d2 = (q_[i] - proj_[a]).squaredNorm();
        if (d2 < g2) cands.push_back({d2, static_cast<int>(a), static_cast<int>(i)});
      }
    }
    std::sort(cands.begin(), cands.end(), [](const Cand& x, const Cand& y) { return x.d2 < y.d2; });
    for (const Cand& c : cands) {
      if (s.blob_of_marker[c.a] >= 0 || s.marker_of_blob[c.i] >= 0) continue;
      s.blob_of_marker[c.a] = c.i;
      s.marker_of_blob[c.i] = c.a;
      ++s.num_labelled;
      s.ss += c.d2;
    }
    const double G2 = o_.gate_px * o_.gate_px;
    for (size_t a = 0; a < P_.size(); ++a) {
      const int i = s.blob_of_marker[a];
      if (i >= 0) {
        const double d2 = (q_[i] - proj_[a]).squaredNorm();
        s.score += std::min(d2, G2);
        ++s.counted;
      } else if (InImage(a)) {
        s.score += G2;
        ++s.counted;
      }
    }
    return s;
  }

  // Gauss-Newton on the pose over the pairs of `s`.
  Pose6 Refine(const Scored& s) const {
    Pose6 pose = s.pose;
    for (int it = 0; it < 8; ++it) {
      Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
      Eigen::Matrix<double, 6, 1> g = Eigen::Matrix<double, 6, 1>::Zero();
      for (size_t a = 0; a < P_.size(); ++a) {
        const int i = s.blob_of_marker[a];
        if (i < 0) continue;
        Eigen::Vector2d uv;
        Eigen::Matrix<double, 2, 6, Eigen::RowMajor> J;
        if (!ProjectPointWithJac(cam_.params.data(), pose.data(), P_[a].data(), uv.data(), nullptr,
                                 J.data(), nullptr)) {
          return s.pose;
        }
        const Eigen::Vector2d r = uv - q_[i];
        H += J.transpose() * J;
        g += J.transpose() * r;
      }
      H.diagonal() *= 1.0 + 1e-9;
      const Eigen::Matrix<double, 6, 1> step = H.ldlt().solve(-g);
      if (!step.allFinite()) return s.pose;
      pose += step;
      if (step.norm() < 1e-10 * (1 + pose.norm())) break;
    }
    return pose;
  }

  // `pose` moved across the view so that its projections shift by the image offset that most
  // markers agree on: among the offsets from a marker's projection to a blob within `gate`, the
  // one that puts the most markers within gate_px of a blob (then the smallest sum of squares).
  // A nominal geometry's error moves the whole layout by several px (a C-arm's positioner, the
  // table), which a greedy pairing within the wide gate can take for other blobs; the vote needs
  // no pairing. The translation moves the markers' centroid by that offset at its depth.
  Pose6 ShiftVoted(const Pose6& pose, double gate) const {
    Project(pose);
    const double g2 = gate * gate, G2 = o_.gate_px * o_.gate_px;
    Eigen::Vector2d best = Eigen::Vector2d::Zero();
    int best_count = 0;
    double best_ss = 0;
    for (size_t a = 0; a < P_.size(); ++a) {
      if (!ok_[a]) continue;
      for (const auto& qa : q_) {
        const Eigen::Vector2d d = qa - proj_[a];
        if (d.squaredNorm() >= g2) continue;
        int count = 0;
        double ss = 0;
        for (size_t b = 0; b < P_.size(); ++b) {
          if (!ok_[b]) continue;
          double nearest = G2;
          for (const auto& q : q_) nearest = std::min(nearest, (q - proj_[b] - d).squaredNorm());
          if (nearest < G2) ++count, ss += nearest;
        }
        if (count > best_count || (count == best_count && ss < best_ss)) {
          best = d, best_count = count, best_ss = ss;
        }
      }
    }
    const double z = CentroidDepth(pose);
    Pose6 moved = pose;
    if (z > 0) {
      moved[3] += best.x() * z / cam_.params[kFx];
      moved[4] += best.y() * z / cam_.params[kFy];
    }
    return moved;
  }

  // Pair with `gate`, refine, re-pair with gate_px (twice).
  Scored Verify(const Pose6& pose, double gate) {
    Project(pose);
    Scored s = Pair(pose, gate);
    for (int round = 0; round < 2 && s.num_labelled >= 3; ++round) {
      const Pose6 refined = Refine(s);
      Project(refined);
      s = Pair(refined, o_.gate_px);
    }
    return s;
  }

  // `s` without its off-pose pairs (ViewContext, OffPoseBlob), which go to *off: the worst one
  // first, then the check again on the rest (one bad pair spoils the others' leave-one-out poses).
  Scored WithoutOffPose(const Scored& s, std::vector<OffPoseBlob>* off) {
    off->clear();
    const double median_sigma = MedianBlobSigma();
    Scored kept = s;
    while (kept.num_labelled >= 5 && kept.num_labelled > o_.min_markers) {
      double worst_m2 = kOffPoseChi2;
      OffPoseBlob worst{-1, -1, 0};
      for (size_t i = 0; i < q_.size(); ++i) {
        if (kept.marker_of_blob[i] < 0) continue;
        double m2 = 0, d = 0;
        LeftOut(kept, i, median_sigma, &m2, &d);
        if (d > kOffPoseFloorPx && m2 > worst_m2) {
          worst_m2 = m2;
          worst = {static_cast<int>(i), kept.marker_of_blob[i], d};
        }
      }
      if (worst.blob < 0) break;
      off->push_back(worst);
      kept.marker_of_blob[worst.blob] = -1;
      kept.blob_of_marker[worst.marker] = -1;
      --kept.num_labelled;
    }
    if (off->empty()) return s;
    Rescore(&kept);
    return kept;
  }

  // The blobs' median centre sigma (px; 0 when unknown).
  double MedianBlobSigma() const {
    std::vector<double> sig = context_.blob_sigma_px;
    if (sig.empty()) return 0;
    std::nth_element(sig.begin(), sig.begin() + sig.size() / 2, sig.end());
    return sig[sig.size() / 2];
  }

  // A labelling of 4 pairs has none to spare for WithoutOffPose; instead each pair left out must
  // lie where the other three put it: within kOffPoseFloorPx, or a Mahalanobis distance squared up
  // to kOffPoseChi2 as there. Returns why not ("" when every pair agrees). A bead paired with a
  // hidden marker bends a 4-pair pose to itself, and the RMS alone does not show it (randomised
  // real-CT scene 13003: RMS 0.64 px, with a correct pair at 13 sigma).
  std::string DisagreeingPair(const Scored& s) const {
    const double d = DisagreementPx(s);
    if (d == 0) return "";
    return "its 4 pairs disagree: one lies " + Fmt("%.2f", d) +
           " px from where the other three put it";
  }
  // The distance (px) of the first pair of a 4-pair labelling that DisagreeingPair finds off, or 0.
  double DisagreementPx(const Scored& s) const {
    if (s.num_labelled != 4) return 0;
    const double median_sigma = MedianBlobSigma();
    for (size_t i = 0; i < q_.size(); ++i) {
      if (s.marker_of_blob[i] < 0) continue;
      double m2 = 0, d = 0;
      LeftOut(s, i, median_sigma, &m2, &d);
      if (d > kOffPoseFloorPx && m2 > kOffPoseChi2) return d;
    }
    return 0;
  }

  // The pose of `s` refined on its pairs, and their sum of squares there.
  void Rescore(Scored* s) {
    s->pose = Refine(*s);
    Project(s->pose);
    s->ss = PairSquares(*s);
  }

  // The sum of squared distances of the pairs of `s` (after Project).
  double PairSquares(const Scored& s) const {
    double ss = 0;
    for (size_t a = 0; a < P_.size(); ++a) {
      if (s.blob_of_marker[a] >= 0) ss += (q_[s.blob_of_marker[a]] - proj_[a]).squaredNorm();
    }
    return ss;
  }

  // Pair i of `s` left out: the pose refined on the others, and the blob's distance from its
  // marker's prediction (*d, px) and its Mahalanobis distance squared (*m2) with the others'
  // per-coordinate noise (from their residuals, at least the blobs' median sigma) through the
  // refined pose to the prediction, plus that noise and the blob's own sigma.
  void LeftOut(const Scored& s, size_t i, double median_sigma, double* m2, double* d) const {
    const int a = s.marker_of_blob[i];
    Scored t = s;
    t.marker_of_blob[i] = -1;
    t.blob_of_marker[a] = -1;
    --t.num_labelled;
    const Pose6 pose = Refine(t);
    Project(pose);
    if (!ok_[a]) return;
    const double ss = PairSquares(t);
    // Per coordinate, over the fit's redundancy (2 n - 6: the pose took 6).
    const double s2 =
        std::max(ss / std::max(1, 2 * t.num_labelled - 6), median_sigma * median_sigma);
    const double sigma = i < context_.blob_sigma_px.size() ? context_.blob_sigma_px[i] : 0.0;
    const Eigen::Matrix2d C =
        s2 * PredictionCovariance(t, pose, a) + (s2 + sigma * sigma) * Eigen::Matrix2d::Identity();
    const Eigen::Vector2d e = q_[i] - proj_[a];
    *d = e.norm();
    *m2 = e.dot(C.ldlt().solve(e));
  }

  // J_a H^-1 J_a^T: the 2x2 covariance of marker a's projection at `pose` per unit pixel variance
  // of the pairs of `t` (H = sum J^T J over them).
  Eigen::Matrix2d PredictionCovariance(const Scored& t, const Pose6& pose, size_t a) const {
    Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 2, 6, Eigen::RowMajor> J;
    Eigen::Vector2d uv;
    for (size_t b = 0; b < P_.size(); ++b) {
      if (t.blob_of_marker[b] < 0) continue;
      if (!ProjectPointWithJac(cam_.params.data(),
                               pose.data(),
                               P_[b].data(),
                               uv.data(),
                               nullptr,
                               J.data(),
                               nullptr)) {
        continue;
      }
      H += J.transpose() * J;
    }
    if (!ProjectPointWithJac(
            cam_.params.data(), pose.data(), P_[a].data(), uv.data(), nullptr, J.data(), nullptr)) {
      return Eigen::Matrix2d::Identity() * 1e6;
    }
    const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(H);
    if (ldlt.info() != Eigen::Success) return Eigen::Matrix2d::Identity() * 1e6;
    return J * ldlt.solve(J.transpose());
  }

  // The pairs `x` and `y` share (same blob, same marker), the pose refined on them from x's.
  Scored Shared(const Scored& x, const Scored& y) {
    Scored s;
    s.pose = x.pose;
    s.marker_of_blob.assign(q_.size(), -1);
    s.blob_of_marker.assign(P_.size(), -1);
    for (size_t i = 0; i < q_.size(); ++i) {
      const int a = x.marker_of_blob[i];
      if (a < 0 || y.marker_of_blob[i] != a) continue;
      s.marker_of_blob[i] = a;
      s.blob_of_marker[a] = static_cast<int>(i);
      ++s.num_labelled;
    }
    if (s.num_labelled >= 3) Rescore(&s);
    return s;
  }

  // Where a marker projected at `uv` could show as a blob of its own: in the image and the field
  // of view.
  bool Visible(const Eigen::Vector2d& uv) const {
    const bool in_image = uv.allFinite() && uv.x() >= -0.5 && uv.y() >= -0.5 &&
                          uv.x() <= cam_.width - 0.5 && uv.y() <= cam_.height - 0.5;
    return in_image &&
           (context_.fov_radius <= 0 || (uv - context_.fov_centre).norm() <= context_.fov_radius);
  }
  // Markers predicted visible and separable at `pose`: Visible, farther than separation_px from
  // every other visible marker's projection and from every obstruction, and farther than gate_px
  // from every faint blob.
  int Separable(const Pose6& pose) const {
    std::vector<Eigen::Vector2d> uv(P_.size());
    std::vector<char> in(P_.size(), 0);
    for (size_t a = 0; a < P_.size(); ++a) {
      in[a] = ProjectPoint(cam_.params.data(), pose.data(), P_[a].data(), uv[a].data()) &&
              Visible(uv[a]);
    }
    const double hidden_within = o_.separation_px > 0 ? o_.separation_px : o_.gate_px;
    int n = 0;
    for (size_t a = 0; a < P_.size(); ++a) {
      if (!in[a]) continue;
      bool apart = true;
      for (size_t b = 0; b < P_.size() && apart; ++b) {
        apart = b == a || !in[b] || (uv[a] - uv[b]).norm() >= o_.separation_px;
      }
      for (size_t k = 0; k < context_.obstructions.size() && apart; ++k) {
        apart = (uv[a] - context_.obstructions[k]).norm() >= hidden_within;
      }
      for (size_t k = 0; k < context_.faint_blobs.size() && apart; ++k) {
        apart = (uv[a] - context_.faint_blobs[k]).norm() >= o_.gate_px;
      }
      n += apart;
    }
    return n;
  }
  // The markers a labelling at `pose` must pair: min_markers, and min_fraction of the separable.
  int Needed(const Pose6& pose) const {
    return std::max(o_.min_markers,
                    static_cast<int>(std::ceil(o_.min_fraction * Separable(pose) - 1e-9)));
  }
  // Why `s` is not accepted (kind kNone when it is).
  Refusal Rejection(const Scored& s) const {
    const int needed = Needed(s.pose);
    if (s.num_labelled < needed) {
      return {Refusal::Kind::kTooFewMarkers,
              "needs " + std::to_string(needed) + " markers (at least " +
                  std::to_string(o_.min_markers) + ", and " + Percent(o_.min_fraction) +
                  " of the " + std::to_string(Separable(s.pose)) +
                  " its pose predicts visible and apart from other markers and rejected blobs)"};
    }
    if (!(s.Rms() <= o_.accept_rms_px))
      return {Refusal::Kind::kRms, "needs an RMS within " + Fmt("%.2f", o_.accept_rms_px) + " px"};
    if (!AtNominalDepth(s)) {
      return {Refusal::Kind::kWrongDepth,
              "its magnification " + Fmt("%.2f", Magnification(s.pose)) + " px/mm is not within " +
                  Percent(o_.scale_tolerance) + " of the nominal " + Fmt("%.2f", o_.px_per_mm)};
    }
    const std::string disagree = DisagreeingPair(s);
    if (!disagree.empty()) return {Refusal::Kind::kPairsDisagree, disagree};
    return {};
  }
  // The pose of `s` puts the markers at the nominal magnification (within scale_tolerance), or
  // the magnification is unknown.
  bool AtNominalDepth(const Scored& s) const {
    if (!(o_.px_per_mm > 0)) return true;
    const double mag = Magnification(s.pose);
    const double k = 1 + o_.scale_tolerance;
    return mag > o_.px_per_mm / k && mag < o_.px_per_mm * k;
  }
  bool Accepted(const Scored& s) const { return Rejection(s).kind == Refusal::Kind::kNone; }

  // fx / depth of the markers' centroid at `pose`.
  double Magnification(const Pose6& pose) const {
    const double z = CentroidDepth(pose);
    return z > 0 ? cam_.params[kFx] / z : 0;
  }
  // The depth (camera z, mm) of the markers' centroid at `pose`.
  double CentroidDepth(const Pose6& pose) const {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (const auto& p : P_) c += p;
    c /= static_cast<double>(P_.size());
    Eigen::Vector3d c_cam;
    ceres::AngleAxisRotatePoint(pose.data(), c.data(), c_cam.data());
    return c_cam.z() + pose[5];
  }

  const Camera& camera() const { return cam_; }
  const std::vector<Eigen::Vector3d>& markers() const { return P_; }
  const std::vector<Eigen::Vector2d>& blobs() const { return q_; }
  const CorrespondenceOptions& options() const { return o_; }

 private:
  const Camera& cam_;
  const std::vector<Eigen::Vector3d>& P_;
  const std::vector<Eigen::Vector2d>& q_;
  const CorrespondenceOptions& o_;
  const ViewContext& context_;
  // Project's output (scratch: the const checks project too).
  mutable std::vector<Eigen::Vector2d> proj_;
  mutable std::vector<char> ok_;
};

// Two labellings contradict each other: a blob with two different markers or a marker with two
// different blobs.
bool Contradict(const Scored& x, const Scored& y) {
  for (size_t i = 0; i < x.marker_of_blob.size(); ++i) {
    if (x.marker_of_blob[i] >= 0 && y.marker_of_blob[i] >= 0 &&
        x.marker_of_blob[i] != y.marker_of_blob[i])
      return true;
  }
  for (size_t a = 0; a < x.blob_of_marker.size(); ++a) {
    if (x.blob_of_marker[a] >= 0 && y.blob_of_marker[a] >= 0 &&
        x.blob_of_marker[a] != y.blob_of_marker[a])
      return true;
  }
  return false;
}

// Marker triples for the search: disjoint ones first, compact (smallest perimeter) among the
// well-shaped ones (roundness 4 sqrt(3) area / sum of squared sides >= 0.3; equilateral = 1),
// so that the magnification bound prunes most blob triples; then every other triple, in the same
// order.
std::vector<std::array<int, 3>> MarkerTriples(const std::vector<Eigen::Vector3d>& P,
                                              int* num_disjoint) {
  const int m = static_cast<int>(P.size());
  struct T {
    double key;
    std::array<int, 3> idx;
  };
  std::vector<T> all;
  for (int a = 0; a < m; ++a) {
    for (int b = a + 1; b < m; ++b) {
      for (int c = b + 1; c < m; ++c) {
        const double area = 0.5 * (P[b] - P[a]).cross(P[c] - P[a]).norm();
        const double s2 =
            (P[b] - P[a]).squaredNorm() + (P[c] - P[a]).squaredNorm() + (P[c] - P[b]).squaredNorm();
        if (!(area > 1e-6)) continue;
        const double round = 4 * std::sqrt(3.0) * area / s2;
        const double perimeter = (P[b] - P[a]).norm() + (P[c] - P[a]).norm() + (P[c] - P[b]).norm();
        // Well-shaped triples by perimeter, then the others by decreasing roundness.
        all.push_back({round >= 0.3 ? perimeter : 1e12 * (2 - round), {a, b, c}});
      }
    }
  }
  std::sort(all.begin(), all.end(), [](const T& x, const T& y) { return x.key < y.key; });
  std::vector<std::array<int, 3>> out;
  std::vector<char> used(m, 0);
  for (const T& t : all) {
    if (used[t.idx[0]] || used[t.idx[1]] || used[t.idx[2]]) continue;
    out.push_back(t.idx);
    for (int k : t.idx) used[k] = 1;
  }
  *num_disjoint = static_cast<int>(out.size());
  for (const T& t : all) {
    if (std::find(out.begin(), out.begin() + *num_disjoint, t.idx) == out.begin() + *num_disjoint) {
      out.push_back(t.idx);
    }
  }
  return out;
}

// More markers labelled, then the smaller RMS.
bool Better(const Scored& x, const Scored& y) {
  return x.num_labelled != y.num_labelled ? x.num_labelled > y.num_labelled : x.Rms() < y.Rms();
}

// The P3P hypotheses of marker triples against every ordered blob triple within the
// magnification bound, each verified (Labeller::Verify); the distinct accepted labellings and the
// best labelling seen, accepted or not.
class TripleSearch {
 public:
  // Over the labeller's camera, markers, blobs and options.
  explicit TripleSearch(Labeller* lab)
      : markers_(lab->markers()),
        o_(lab->options()),
        lab_(lab),
        n_(static_cast<int>(lab->blobs().size())),
        rays_(n_),
        ray_ok_(n_, 0),
        D_(n_, n_),
        s_max_(o_.px_per_mm > 0 ? o_.px_per_mm * (1 + o_.scale_tolerance) : 0) {
    const std::vector<Eigen::Vector2d>& blobs = lab->blobs();
    for (int i = 0; i < n_; ++i) {
      double xy[2];
      ray_ok_[i] = UnprojectToNormalized(lab->camera().params.data(), blobs[i].data(), xy);
      rays_[i] = cv::Point2d(xy[0], xy[1]);
    }
    // Blob distances (px) for the magnification bound: a projection never makes a marker pair
    // longer than magnification x its length.
    for (int i = 0; i < n_; ++i)
      for (int j = 0; j < n_; ++j) D_(i, j) = (blobs[i] - blobs[j]).norm();
  }

  // Every blob triple for the marker triple `tri`.
  void Try(const std::array<int, 3>& tri) {
    for (int k = 0; k < 3; ++k)
      obj_[k] = cv::Point3d(markers_[tri[k]].x(), markers_[tri[k]].y(), markers_[tri[k]].z());
    const double l01 = Bound(tri[0], tri[1]), l02 = Bound(tri[0], tri[2]),
                 l12 = Bound(tri[1], tri[2]);
    for (int i = 0; i < n_; ++i) {
      if (!ray_ok_[i]) continue;
      for (int j = 0; j < n_; ++j) {
        if (j == i || !ray_ok_[j] || D_(i, j) > l01) continue;
        for (int k = 0; k < n_; ++k) {
          if (k == i || k == j || !ray_ok_[k] || D_(i, k) > l02 || D_(j, k) > l12) continue;
          img_[0] = rays_[i], img_[1] = rays_[j], img_[2] = rays_[k];
          TryBlobs();
        }
      }
    }
  }

  // Markers in the best accepted labelling (0: none yet).
  int best_accepted_markers() const { return best_markers_; }

  std::vector<Scored> accepted;  // distinct accepted labellings
  Scored best_any;               // the best seen, accepted or not
  // The best seen at the nominal magnification (for the error: one at a wrong depth is a chance
  // fit, and the reason it was refused says nothing about the view).
  Scored best_at_depth;
  // The best refused only because its 4 pairs disagree (Labeller::DisagreeingPair).
  Scored best_disagreeing;
  int hypotheses = 0;            // P3P solves

 private:
  // The longest blob distance a marker pair can project to (infinite without px_per_mm).
  double Bound(int a, int b) const {
    return s_max_ > 0 ? s_max_ * (markers_[a] - markers_[b]).norm()
                      : std::numeric_limits<double>::infinity();
  }

  // The poses of the marker triple obj_ seen along the blob rays img_.
  void TryBlobs() {
    int ns = 0;
    try {
      ns = cv::solveP3P(
          obj_, img_, cv::Matx33d::eye(), cv::noArray(), rvecs_, tvecs_, cv::SOLVEPNP_AP3P);
    } catch (const cv::Exception&) {
      ns = 0;
    }
    ++hypotheses;
    for (int s = 0; s < ns; ++s) {
      Pose6 pose;
      for (int c = 0; c < 3; ++c)
        pose[c] = rvecs_[s].at<double>(c), pose[3 + c] = tvecs_[s].at<double>(c);
      if (!pose.allFinite() || !(pose[5] > 0)) continue;
      lab_->Project(pose);
      if (lab_->CountNear(o_.gate_px) < o_.min_markers) continue;
      Consider(lab_->Verify(pose, o_.gate_px));
    }
  }

  void Consider(const Scored& sc) {
    if (Better(sc, best_any)) best_any = sc;
    if (Better(sc, best_at_depth) && lab_->AtNominalDepth(sc)) best_at_depth = sc;
    const Refusal::Kind refused = lab_->Rejection(sc).kind;
    if (refused == Refusal::Kind::kPairsDisagree && Better(sc, best_disagreeing))
      best_disagreeing = sc;
    if (refused != Refusal::Kind::kNone) return;
    bool same = false;
    for (Scored& a : accepted) {
      if (!Contradict(a, sc)) {
        same = true;
        if (sc.score < a.score) a = sc;
        break;
      }
    }
    if (!same) accepted.push_back(sc);
    best_markers_ = std::max(best_markers_, sc.num_labelled);
  }

  const std::vector<Eigen::Vector3d>& markers_;
  const CorrespondenceOptions& o_;
  Labeller* lab_;
  const int n_;
  std::vector<cv::Point2d> rays_;
  std::vector<char> ray_ok_;
  Eigen::MatrixXd D_;
  const double s_max_;
  int best_markers_ = 0;
  std::vector<cv::Point3d> obj_ = std::vector<cv::Point3d>(3);
  std::vector<cv::Point2d> img_ = std::vector<cv::Point2d>(3);
  std::vector<cv::Mat> rvecs_, tvecs_;
};

// A labelling of 4 pairs has none to spare to tell a pulled centre from a chance fit. When
// another labelling of 4 pairs contradicts it, fits within kRivalRmsRatio times its RMS (and
// within ambiguity_margin_px of it), and was refused only because one of its pairs lies off by as
// much as an edge or a bead in line can pull a centre (up to kPlausiblePull x separation_px, about
// 0.3 of a diameter; 1.5 px when the separation is unknown), either could be the true one
// (randomised scene 2011, view 4: a wrong labelling at RMS 0.023 px (XA frame) / 0.037 px (real
// CT) accepted, the true one at 0.103 / 0.096 px with a centre about 1 px off refused: ratios
// 4.5 and 2.6). A best labelling that fits far better than such a rival stands (true labellings
// on the XA frame's seed sets 9 and 16: 0.003-0.013 px against 0.13-0.20 px, ratios 9.8-63; the
// gap between 4.5 and 9.8 is all the data give for kRivalRmsRatio). That rival, or nullptr.
constexpr double kRivalRmsRatio = 6;
const Scored* DisagreeingRival(const Labeller& lab, const TripleSearch& search) {
  constexpr double kPlausiblePull = 0.25;
  const CorrespondenceOptions& o = lab.options();
  const Scored& best = search.accepted.front();
  const Scored& rival = search.best_disagreeing;  // 4 pairs, or none
  if (rival.num_labelled == 0 || best.num_labelled > rival.num_labelled) return nullptr;
  if (!Contradict(best, rival) || rival.Rms() - best.Rms() >= o.ambiguity_margin_px ||
      rival.Rms() > kRivalRmsRatio * best.Rms())
    return nullptr;
  const double pull = o.separation_px > 0 ? kPlausiblePull * o.separation_px : 1.5;
  return lab.DisagreementPx(rival) <= pull ? &rival : nullptr;
}

std::string Describe(const Scored& s) {
  std::ostringstream os;
  os.precision(3);
  os << s.num_labelled << " markers at RMS " << s.Rms() << " px";
  return os.str();
}

// When the most complete labellings (`best` and `rival`, contradicting each other) leave too few
// shared pairs: the best accepted labelling of fewer markers, if it fits kRivalRmsRatio times
// better than both and no labelling of as many markers contradicts it within `margin_px`; else
// nullptr. Two labellings of the same markers that cannot both be true, each off by many times
// the blobs' noise, are chance fits that took spurious beads; a labelling that fits at the noise
// level without them is the view's (randomised XA-frame scene 16004, view 1: the 4 markers
// visible apart at RMS 0.02 px; two contradicting 5-marker labellings with beads at 0.75 px). The
// ratio is DisagreeingRival's kRivalRmsRatio, whose rival is this case's mirror image.
const Scored* FarBetterFit(const std::vector<Scored>& accepted,  // sorted by Better
                           const Scored& best,
                           const Scored& rival,
                           double margin_px) {
  const Scored* fewer = nullptr;
  for (const Scored& s : accepted) {
    if (s.num_labelled >= best.num_labelled) continue;
    if (!fewer) {
      fewer = &s;
      if (kRivalRmsRatio * s.Rms() >= std::min(best.Rms(), rival.Rms())) return nullptr;
    } else if (s.num_labelled == fewer->num_labelled && Contradict(s, *fewer) &&
               s.Rms() - fewer->Rms() < margin_px) {
      return nullptr;  // contested too
    }
  }
  return fewer;
}

// Why no labelling of the `m` markers to the `n` blobs was taken: the best one found (preferring
// one at the nominal magnification; when `outvoted`, the one that outvoted the accepted ones),
// with the reason it was refused (stated at its own pose) and what that reason suggests.
std::string NoLabelling(
    const Labeller& lab, const TripleSearch& search, int m, int n, bool outvoted) {
  const Scored& best =
      !outvoted && search.best_at_depth.num_labelled ? search.best_at_depth : search.best_any;
  const std::string head = "no labelling of the " + std::to_string(m) + " fiducials explains the " +
                           std::to_string(n) + " blobs (best: ";
  if (!best.num_labelled) {
    return head + "none; a labelling needs " + std::to_string(lab.options().min_markers) +
           " markers): fiducials of another object, or a wrong camera?";
  }
  const Refusal refusal = lab.Rejection(best);
  std::string hint = "fiducials of another object, or a wrong camera?";
  if (outvoted) {
    hint = "the accepted labellings of fewer markers contradict it";
  } else if (refusal.kind == Refusal::Kind::kTooFewMarkers) {
    hint =
        "too few markers seen apart (merged, hidden by anatomy or metal), or fiducials of "
        "another object?";
  } else if (refusal.kind == Refusal::Kind::kPairsDisagree) {
    hint =
        "a marker's centre pulled by an edge or a shadow in line, with no fifth marker to "
        "tell which";
  }
  return head + Describe(best) + "; refused: " + refusal.why + "): " + hint;
}

}  // namespace

StatusOr<MarkerLabelling> LabelMarkerBlobs(const Camera& camera,
                                           const std::vector<Eigen::Vector3d>& markers,
                                           const std::vector<Eigen::Vector2d>& blobs,
                                           const CorrespondenceOptions& o,
                                           const std::optional<Pose6>& predicted,
                                           const ViewContext& context) {
  std::string err;
  if (!o.Check(&err)) return Status::Error("correspondence options: " + err);
  const int n = static_cast<int>(blobs.size()), m = static_cast<int>(markers.size());
  if (m < o.min_markers) {
    return Status::Error(std::to_string(m) + " fiducials, at least " +
                         std::to_string(o.min_markers) + " needed");
  }
  if (n < o.min_markers) {
    return Status::Error("only " + std::to_string(n) + " marker blobs found, at least " +
                         std::to_string(o.min_markers) + " needed");
  }
  if (n > o.max_blobs) {
    return Status::Error(std::to_string(n) + " marker blobs found, more than max_blobs " +
                         std::to_string(o.max_blobs) + " (clutter taken for markers?)");
  }
  Labeller lab(camera, markers, blobs, o, context);
  MarkerLabelling out;
  auto finish = [&](const Scored& labelled, const std::string& method) {
    const Scored s = lab.WithoutOffPose(labelled, &out.off_pose);
    out.marker_of_blob = s.marker_of_blob;
    out.cam_from_object = s.pose;
    out.num_labelled = s.num_labelled;
    out.rms_px = s.Rms();
    out.score_px2 = s.score;
    out.method = method;
  };
  if (predicted) {
    // Paired within predict_gate_px (the nominal geometry's error) and within gate_px, each
    // refined and re-paired within gate_px. When the tight pairing already holds 3 or more markers
    // (an accurate prediction), the wide one is taken only where it pairs the same: a pair only
    // the wide gate made (a bead beside a hidden marker, another marker's blob) bends a pose of
    // few pairs to itself and keeps it (randomised real-CT scene 13003: a bead 15-26 px from its
    // marker, labelled in two views at RMS 0.4-0.6 px). Else the tight one, else the search.
    const Scored tight = lab.Verify(*predicted, o.gate_px);
    const Scored wide =
        o.predict_gate_px > o.gate_px ? lab.Verify(*predicted, o.predict_gate_px) : tight;
    const bool confirmed = tight.num_labelled < 3 || wide.marker_of_blob == tight.marker_of_blob;
    const Scored* taken = confirmed && lab.Accepted(wide) ? &wide
                          : lab.Accepted(tight)           ? &tight
                                                          : nullptr;
    // Neither accepted: the prediction moved by the offset most markers agree on, paired within
    // gate_px (a nominal geometry off by a few mm).
    Scored voted;
    if (!taken) {
      voted = lab.Verify(lab.ShiftVoted(*predicted, o.predict_gate_px), o.gate_px);
      if (lab.Accepted(voted)) taken = &voted;
    }
    if (taken) {
      finish(*taken, "predicted");
      return out;
    }
  }
  TripleSearch search(&lab);
  int num_disjoint = 0;
  const auto triples = MarkerTriples(markers, &num_disjoint);
  // The first pass: the disjoint triples and at least 8 in all. A labelling at least as complete
  // as the best accepted one leaves out at most m - best markers, so once d >= m - best + 1
  // disjoint triples are searched, one of them was complete in it and found it: the search stops.
  // When the disjoint triples cannot give that guarantee (many markers hidden or merged, or
  // nothing accepted), every further triple is tried, within the hypotheses budget: any labelling
  // of 3 or more markers contains a complete triple.
  const size_t first_pass = std::min(triples.size(), std::max<size_t>(8, num_disjoint));
  for (size_t t = 0; t < triples.size(); ++t) {
    const int best = search.best_accepted_markers();
    if (t >= first_pass &&
        ((best > 0 && m - best + 1 <= num_disjoint) || search.hypotheses >= kMaxHypotheses)) {
      break;
    }
    search.Try(triples[t]);
    const int found = search.best_accepted_markers();
    if (found > 0 && static_cast<int>(t) + 1 <= num_disjoint &&
        static_cast<int>(t) + 1 >= m - found + 1)
      break;
  }
  out.hypotheses = search.hypotheses;
  std::vector<Scored>& accepted = search.accepted;
  const Scored& best_any = search.best_any;
  std::sort(accepted.begin(), accepted.end(), Better);
  // The labelling of the most markers seen is not accepted, and every accepted one labels fewer
  // and contradicts it: the accepted ones are not trusted either (a wrong pose can put the markers
  // it does not pair outside the image, and so pass min_fraction).
  const bool outvoted = !accepted.empty() &&
                        best_any.num_labelled > accepted.front().num_labelled &&
                        Contradict(best_any, accepted.front());
  if (accepted.empty() || outvoted) return Status::Error(NoLabelling(lab, search, m, n, outvoted));
  if (const Scored* rival = DisagreeingRival(lab, search)) {
    return Status::Error("ambiguous marker labelling: " + Describe(accepted.front()) +
                         " against a contradicting one of " + Describe(*rival) + " refused as " +
                         lab.Rejection(*rival).why +
                         ": a marker's centre pulled by an edge or a shadow in line would explain "
                         "the worse fit of either, and 4 markers leave none to tell which; "
                         "refusing to guess");
  }
  // The best and the labellings contradicting it that explain the blobs about as well. When there
  // are such, only the pairs they all share are kept (the markers they agree on are certain; the
  // others are contested), if those are still enough for min_markers and min_fraction; else the
  // view is ambiguous.
  const Scored& b = accepted.front();
  finish(b, "search");
  Scored agreed = b;
  const Scored* rival = nullptr;
  for (size_t k = 1; k < accepted.size(); ++k) {
    if (!Contradict(b, accepted[k])) continue;
    if (out.second_num_labelled == 0) {
      out.second_num_labelled = accepted[k].num_labelled;
      out.second_rms_px = accepted[k].Rms();
    }
    if (accepted[k].num_labelled < b.num_labelled ||
        accepted[k].Rms() - b.Rms() >= o.ambiguity_margin_px)
      continue;
    if (!rival) rival = &accepted[k];
    agreed = lab.Shared(agreed, accepted[k]);
  }
  if (!rival) return out;
  if (agreed.num_labelled >= 3 && lab.Accepted(agreed)) {
    finish(agreed,
           "search, the " + std::to_string(agreed.num_labelled) + " markers of " +
               std::to_string(b.num_labelled) + " that equally good labellings share");
    return out;
  }
  if (const Scored* fewer = FarBetterFit(accepted, b, *rival, o.ambiguity_margin_px)) {
    finish(*fewer,
           "search, " + Describe(*fewer) + ": the labellings of " + std::to_string(b.num_labelled) +
               " markers contradict each other (" + Describe(b) + " vs " + Describe(*rival) +
               ") and fit far worse");
    return out;
  }
  return Status::Error(
      "ambiguous marker labelling: two labellings explain the blobs about equally "
      "well (" +
      Describe(b) + " vs " + Describe(*rival) + ", " + std::to_string(agreed.num_labelled) +
      " markers shared" +
      "): the marker layout is (nearly) symmetric in this view; refusing to guess");
}

}  // namespace carmba
