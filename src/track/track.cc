#include "track/track.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <numeric>
#include <opencv2/imgproc.hpp>
#include <random>
#include <set>

#include "ba/bundle_adjuster.h"
#include "detect/blob_pair_fit.h"
#include "geometry/rotation.h"
#include "util/image_codecs.h"
#include "util/plausible.h"
#include "util/random.h"
#include "util/stats.h"

namespace carmba {

namespace {

using Clock = std::chrono::steady_clock;
double Seconds(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

Pose6 PoseOf(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  return Rigid3{R, t}.ToPose();
}

// The point nearest to all optical axes (least squares): where a biplane system's fields meet.
Eigen::Vector3d CommonFieldCentre(const std::vector<TrackCamera>& cameras) {
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const TrackCamera& c : cameras) {
    const Eigen::Vector3d a = c.AxisInLab();
    const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - a * a.transpose();
    A += P;
    b += P * c.CentreInLab();
  }
  return A.ldlt().solve(b);
}

// The camera model's projection through cam_from_lab, with d uv / d p_lab.
bool Project(const TrackCamera& cam, const Eigen::Vector3d& p_lab, Eigen::Vector2d* uv,
             Eigen::Matrix<double, 2, 3>* J_lab = nullptr) {
  Eigen::Matrix<double, 2, 3, Eigen::RowMajor> J;
  if (!ProjectPointWithJac(cam.intrinsics.data(),
                           cam.cam_from_lab.data(),
                           p_lab.data(),
                           uv->data(),
                           nullptr,
                           nullptr,
                           J_lab ? J.data() : nullptr)) {
    return false;
  }
  if (J_lab) *J_lab = J;
  return true;
}

// The ray of pixel uv in the lab frame: origin (the source) and unit direction.
bool Ray(const TrackCamera& cam,
         const Eigen::Vector2d& uv,
         Eigen::Vector3d* origin,
         Eigen::Vector3d* dir) {
  double xy[2];
  if (!UnprojectToNormalized(cam.intrinsics.data(), uv.data(), xy)) return false;
  const Eigen::Matrix3d R = RotationOf(cam.cam_from_lab.data());
  *origin = cam.CentreInLab();
  *dir = (R.transpose() * Eigen::Vector3d(xy[0], xy[1], 1.0)).normalized();
  return true;
}

// Distances of the points of `a` against those of `b`, all pairs.
double Distance(const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return (a - b).norm(); }

// The compatibility graph of stage 3: which correspondences agree (adjacent) and by how much
// their distances differ (mm).
struct CompatibilityGraph {
  std::vector<std::vector<char>> adj;
  std::vector<std::vector<float>> mismatch_mm;
};

// How well the correspondences of clique `r` agree: the sum of their distance differences (mm).
double CliqueMismatch(const CompatibilityGraph& g, const std::vector<int>& r) {
  double sum = 0;
  for (size_t a = 0; a < r.size(); ++a)
    for (size_t b = a + 1; b < r.size(); ++b) sum += g.mismatch_mm[r[a]][r[b]];
  return sum;
}

// Bron-Kerbosch with pivoting: the largest clique of `g.adj` among `nodes`; of equally large ones
// the one whose distances agree best (CliqueMismatch). Taking the first one found instead let a
// distance crossing the tolerance by 0.001 mm, far from the chosen clique, swap two bodies' beads
// (the wrist radiographs, tests/cli/track_cli_test.cc).
void LargestClique(const CompatibilityGraph& g,
                   std::vector<int> R,
                   std::vector<int> P,
                   std::vector<int> X,
                   std::vector<int>* best,
                   double* best_mismatch) {
  if (P.empty() && X.empty()) {
    const double mismatch = CliqueMismatch(g, R);
    if (R.size() > best->size() || (R.size() == best->size() && mismatch < *best_mismatch)) {
      *best = R;
      *best_mismatch = mismatch;
    }
    return;
  }
  if (R.size() + P.size() < best->size()) return;
  int pivot = P.empty() ? X[0] : P[0];
  size_t pivot_degree = 0;
  for (const std::vector<int>* s : {&P, &X}) {
    for (int u : *s) {
      size_t d = 0;
      for (int v : P) d += g.adj[u][v];
      if (d > pivot_degree) pivot_degree = d, pivot = u;
    }
  }
  const std::vector<int> candidates = P;
  for (int v : candidates) {
    if (g.adj[pivot][v]) continue;
    std::vector<int> R2 = R, P2, X2;
    R2.push_back(v);
    for (int u : P)
      if (g.adj[v][u]) P2.push_back(u);
    for (int u : X)
      if (g.adj[v][u]) X2.push_back(u);
    LargestClique(g, R2, P2, X2, best, best_mismatch);
    P.erase(std::find(P.begin(), P.end(), v));
    X.push_back(v);
  }
}

// Two candidates share a blob (in any camera).
bool ShareBlob(const TrackCandidate& a, const TrackCandidate& b) {
  for (const auto& oa : a.observations)
    for (const auto& ob : b.observations)
      if (oa.camera == ob.camera && oa.blob == ob.blob) return true;
  return false;
}

// A rigid correspondence between the reference frame's candidates and frame f's: pairs (i, k).
using Correspondence = std::vector<std::pair<int, int>>;

// Stage 3 for one frame pair: the cliques of the compatibility graph, largest first, each with
// >= min_beads correspondences, no candidate or blob used twice.
std::vector<Correspondence> RigidCorrespondences(const std::vector<TrackCandidate>& ref,
                                                 const std::vector<TrackCandidate>& cur,
                                                 const TrackOptions& o) {
  std::vector<std::pair<int, int>> nodes;
  for (size_t i = 0; i < ref.size(); ++i)
    for (size_t k = 0; k < cur.size(); ++k)
      nodes.emplace_back(static_cast<int>(i), static_cast<int>(k));
  const size_t n = nodes.size();
  CompatibilityGraph g;
  g.adj.assign(n, std::vector<char>(n, 0));
  g.mismatch_mm.assign(n, std::vector<float>(n, 0.0f));
  for (size_t x = 0; x < n; ++x) {
    const auto [i, k] = nodes[x];
    for (size_t y = x + 1; y < n; ++y) {
      const auto [j, l] = nodes[y];
      if (i == j || k == l || ShareBlob(ref[i], ref[j]) || ShareBlob(cur[k], cur[l])) continue;
      const double d0 = Distance(ref[i].point.p_lab, ref[j].point.p_lab);
      const double d1 = Distance(cur[k].point.p_lab, cur[l].point.p_lab);
      if (std::abs(d0 - d1) < o.rigid_tolerance_mm) {
        g.adj[x][y] = g.adj[y][x] = 1;
        g.mismatch_mm[x][y] = g.mismatch_mm[y][x] = static_cast<float>(std::abs(d0 - d1));
      }
    }
  }
  std::vector<char> alive(n, 1);
  std::vector<Correspondence> out;
  for (;;) {
    std::vector<int> P;
    for (size_t x = 0; x < n; ++x) {
      if (!alive[x]) continue;
      bool any = false;
      for (size_t y = 0; y < n && !any; ++y) any = alive[y] && g.adj[x][y];
      if (any) P.push_back(static_cast<int>(x));
    }
    std::vector<int> best;
    double best_mismatch = 0;
    LargestClique(g, {}, P, {}, &best, &best_mismatch);
    if (static_cast<int>(best.size()) < o.min_body_beads) break;
    Correspondence c;
    for (int x : best) c.push_back(nodes[x]);
    std::sort(c.begin(), c.end());
    out.push_back(c);
    for (size_t x = 0; x < n; ++x) {
      for (const auto& [i, k] : c) {
        const auto [j, l] = nodes[x];
        if (j == i || l == k || ShareBlob(ref[i], ref[j]) || ShareBlob(cur[k], cur[l]))
          alive[x] = 0;
      }
    }
  }
  return out;
}

// lab_from_body mapping the reference points onto the current ones (Kabsch, no scale).
Pose6 RigidFit(const std::vector<Eigen::Vector3d>& ref, const std::vector<Eigen::Vector3d>& cur) {
  Eigen::Matrix3Xd A(3, ref.size()), B(3, cur.size());
  for (size_t i = 0; i < ref.size(); ++i) A.col(i) = ref[i], B.col(i) = cur[i];
  const Eigen::Matrix4d T = Eigen::umeyama(A, B, false);
  return PoseOf(T.topLeftCorner<3, 3>(), T.topRightCorner<3, 1>());
}

std::string FrameLabel(const TrackResult& r, size_t f) {
  return "frame " + std::to_string(r.frames[f].number);
}

}  // namespace

void SplitMergedPairs(const cv::Mat& image, const MarkerBlobOptions& blobs, TrackImage* ti) {
  cv::Mat grey = image;
  if (grey.channels() == 3) cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  grey.convertTo(grey, CV_32F);
  const auto [d_min, d_max] = blobs.DiameterRangePx();
  const double d_nom = 0.5 * (d_min + d_max);
  MarkerBlobDetection& det = ti->detection;
  std::vector<RejectedBlob> kept;
  for (const RejectedBlob& rb : det.rejected) {
    // A pair of touching blobs is at most about two diameters long (area-equivalent diameter
    // about 1.4 of one); larger merged regions are clusters or anatomy, not fitted.
    if (rb.why != "merged" || rb.diameter_px > 2.0 * d_max) {
      kept.push_back(rb);
      continue;
    }
    bool done = false;  // both pieces of one pair are listed: fit it once
    for (const MarkerBlob& b : det.blobs)
      done |= std::hypot(b.uv_px.x - rb.uv_px.x, b.uv_px.y - rb.uv_px.y) < 0.8 * d_nom;
    if (done) continue;
    std::string why;
    const auto pair =
        FitBlobPair(grey, rb.uv_px, d_nom, blobs.min_contrast, det.correlation_factor, &why);
    if (!pair) {
      RejectedBlob r = rb;
      r.why = "merged (" + why + ")";
      kept.push_back(r);
      continue;
    }
    for (const MarkerBlob& b : pair->blobs) det.blobs.push_back(b);
    ++ti->split_pairs;
  }
  det.rejected = std::move(kept);
}

bool TrackOptions::Check(std::string* error) const {
  if (!CheckRange("marker_diameter_mm", marker_diameter_mm, plausible::kMarkerDiameterMm, error))
    return false;
  if (!(diameter_tolerance > 0 && diameter_tolerance < 1)) {
    *error = "diameter_tolerance: expected 0 .. 1 (a fraction of the diameter)";
    return false;
  }
  if (!CheckRange("epipolar_px", epipolar_px, plausible::kPixelSigmaPx, error)) return false;
  if (!CheckRange("rigid_tolerance_mm", rigid_tolerance_mm, plausible::kToleranceMm, error))
    return false;
  if (min_body_beads < 3) {
    *error = "min_body_beads: expected >= 3 (a rigid pose needs three beads)";
    return false;
  }
  return true;
}

StatusOr<HeldPoint> TriangulateHeld(const std::vector<TrackCamera>& cameras,
                                    const std::vector<TrackObservation>& obs) {
  if (obs.size() < 2) return Status::Error("a bead seen by one camera cannot be triangulated");
  // Least-squares midpoint of the rays.
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const auto& o : obs) {
    Eigen::Vector3d c, d;
    if (!Ray(cameras[o.camera], o.uv_px, &c, &d))
      return Status::Error("a pixel cannot be undistorted");
    const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - d * d.transpose();
    A += P;
    b += P * c;
  }
  HeldPoint out;
  out.p_lab = A.ldlt().solve(b);
  // Gauss-Newton in pixels, weighted by the pixels' covariances.
  Eigen::Matrix3d N;
  for (int it = 0; it < 20; ++it) {
    N.setZero();
    Eigen::Vector3d g = Eigen::Vector3d::Zero();
    for (const auto& o : obs) {
      Eigen::Vector2d uv;
      Eigen::Matrix<double, 2, 3> J;
      if (!Project(cameras[o.camera], out.p_lab, &uv, &J)) {
        return Status::Error("the rays meet behind a source");
      }
      const Eigen::Matrix2d W = o.covariance_px2.inverse();
      const Eigen::Vector2d e = uv - o.uv_px;
      N += J.transpose() * W * J;
      g += J.transpose() * W * e;
    }
    const Eigen::Vector3d step = -N.ldlt().solve(g);
    if (!step.allFinite()) return Status::Error("the rays are parallel");
    out.p_lab += step;
    if (step.norm() < 1e-10) break;
  }
  out.covariance = N.inverse();
  if (!out.covariance.allFinite()) return Status::Error("the rays are parallel");
  return out;
}

std::vector<TrackCandidate> MatchFrame(const std::vector<TrackCamera>& cameras,
                                       const std::vector<const MarkerBlobDetection*>& images,
                                       const TrackOptions& o) {
  auto observation = [&](int cam, int blob) {
    const MarkerBlob& b = images[cam]->blobs[blob];
    TrackObservation t;
    t.camera = cam;
    t.blob = blob;
    t.uv_px = Eigen::Vector2d(b.uv_px.x, b.uv_px.y);
    t.covariance_px2 << b.covariance_px2(0, 0), b.covariance_px2(0, 1), b.covariance_px2(1, 0),
        b.covariance_px2(1, 1);
    return t;
  };
  auto worst_px = [&](const TrackCandidate& c) {
    double worst = 0;
    for (const auto& ob : c.observations) {
      Eigen::Vector2d uv;
      if (!Project(cameras[ob.camera], c.point.p_lab, &uv))
        return std::numeric_limits<double>::infinity();
      worst = std::max(worst, (uv - ob.uv_px).norm());
    }
    return worst;
  };
  // The first two cameras that imaged the frame pair up; the others join by reprojection.
  std::vector<int> cams;
  for (size_t c = 0; c < images.size(); ++c) if (images[c]) cams.push_back(static_cast<int>(c));
  std::vector<TrackCandidate> out;
  if (cams.size() < 2) return out;
  const int ca = cams[0], cb = cams[1];
  for (size_t a = 0; a < images[ca]->blobs.size(); ++a) {
    for (size_t b = 0; b < images[cb]->blobs.size(); ++b) {
      TrackCandidate c;
      c.observations = {observation(ca, static_cast<int>(a)), observation(cb, static_cast<int>(b))};
      auto p = TriangulateHeld(cameras, c.observations);
      if (!p.ok()) continue;
      c.point = *p;
      c.epipolar_px = worst_px(c);
      if (!(c.epipolar_px <= o.epipolar_px)) continue;
      for (size_t k = 2; k < cams.size(); ++k) {
        Eigen::Vector2d uv;
        if (!Project(cameras[cams[k]], c.point.p_lab, &uv)) continue;
        int best = -1;
        double best_d = o.epipolar_px;
        for (size_t j = 0; j < images[cams[k]]->blobs.size(); ++j) {
          const auto& q = images[cams[k]]->blobs[j].uv_px;
          const double d = (Eigen::Vector2d(q.x, q.y) - uv).norm();
          if (d < best_d) best_d = d, best = static_cast<int>(j);
        }
        if (best < 0) continue;
        TrackCandidate more = c;
        more.observations.push_back(observation(cams[k], best));
        auto p3 = TriangulateHeld(cameras, more.observations);
        if (!p3.ok()) continue;
        more.point = *p3;
        more.epipolar_px = worst_px(more);
        if (more.epipolar_px <= o.epipolar_px) c = more;
      }
      out.push_back(c);
    }
  }
  return out;
}

namespace {

// Frame f's beads associated again by prediction: each body's pose (from its current matches)
// maps the reference positions into frame f; every (bead, candidate) pair within the tolerance of
// the prediction is a choice, taken nearest first, each candidate and each blob once. A bead
// whose clique took a near-duplicate candidate (two beads overlapping in one image) gets its own
// back; the pose is refitted and the association repeated.
void Reassociate(const TrackOptions& o, size_t f, TrackResult* r) {
  const auto& ref = r->candidates[0];
  const auto& cur = r->candidates[f];
  for (int pass = 0; pass < 2; ++pass) {
    struct Choice { double d; int bead, cand; };
    std::vector<Choice> choices;
    for (TrackBody& body : r->bodies) {
      if (!body.found[f]) continue;
      std::vector<Eigen::Vector3d> p0, p1;
      for (int bi : body.beads) {
        if (r->beads[bi].candidate[f] < 0) continue;
        p0.push_back(ref[r->beads[bi].candidate[0]].point.p_lab);
        p1.push_back(cur[r->beads[bi].candidate[f]].point.p_lab);
      }
      if (static_cast<int>(p0.size()) >= o.min_body_beads) body.lab_from_body[f] = RigidFit(p0, p1);
      const Eigen::Matrix3d R = RotationOf(body.lab_from_body[f].data());
      for (int bi : body.beads) {
        const Eigen::Vector3d predicted =
            R * ref[r->beads[bi].candidate[0]].point.p_lab + body.lab_from_body[f].tail<3>();
        for (size_t k = 0; k < cur.size(); ++k) {
          const double d = (cur[k].point.p_lab - predicted).norm();
          if (d < o.rigid_tolerance_mm) choices.push_back({d, bi, static_cast<int>(k)});
        }
      }
    }
    std::sort(
        choices.begin(), choices.end(), [](const Choice& a, const Choice& b) { return a.d < b.d; });
    std::vector<char> bead_done(r->beads.size(), 0);
    std::vector<int> taken;
    for (TrackBead& bead : r->beads) bead.candidate[f] = -1;
    for (const Choice& c : choices) {
      if (bead_done[c.bead]) continue;
      bool clash = false;
      for (int k : taken) clash |= k == c.cand || ShareBlob(cur[k], cur[c.cand]);
      if (clash) continue;
      bead_done[c.bead] = 1;
      taken.push_back(c.cand);
      r->beads[c.bead].candidate[f] = c.cand;
    }
  }
}

}  // namespace

void FindBodies(const TrackOptions& o, TrackResult* r) {
  const auto& ref = r->candidates[0];
  const size_t F = r->frames.size();
  // Per later frame, the body (clique index) of each reference candidate and its match there.
  std::vector<std::vector<int>> clique_of(F, std::vector<int>(ref.size(), -1));
  std::vector<std::vector<int>> match_of(F, std::vector<int>(ref.size(), -1));
  for (size_t f = 1; f < F; ++f) {
    const auto corr = RigidCorrespondences(ref, r->candidates[f], o);
    for (size_t q = 0; q < corr.size(); ++q) {
      for (const auto& [i, k] : corr[q]) clique_of[f][i] = static_cast<int>(q), match_of[f][i] = k;
    }
  }
  // Bodies: reference candidates together in one clique in every later frame that has both and
  // apart in none. One frame only: the unambiguous candidates (no blob shared), one body.
  std::vector<std::vector<int>> members;
  if (F == 1) {
    std::vector<int> body;
    for (size_t i = 0; i < ref.size(); ++i) {
      bool shared = false;
      for (size_t j = 0; j < ref.size() && !shared; ++j)
        shared = j != i && ShareBlob(ref[i], ref[j]);
      if (!shared) body.push_back(static_cast<int>(i));
    }
    if (static_cast<int>(body.size()) >= o.min_body_beads) members.push_back(body);
  }
  std::vector<char> assigned(ref.size(), 0);
  for (size_t i = 0; i < ref.size() && F > 1; ++i) {
    bool in_some = false;
    for (size_t f = 1; f < F; ++f) in_some |= clique_of[f][i] >= 0;
    if (!in_some || assigned[i]) continue;
    std::vector<int> body = {static_cast<int>(i)};
    for (size_t j = i + 1; j < ref.size(); ++j) {
      if (assigned[j]) continue;
      bool together = false, apart = false;
      for (size_t f = 1; f < F; ++f) {
        if (clique_of[f][i] < 0 || clique_of[f][j] < 0) continue;
        (clique_of[f][i] == clique_of[f][j] ? together : apart) = true;
      }
      if (together && !apart) body.push_back(static_cast<int>(j));
    }
    if (static_cast<int>(body.size()) < o.min_body_beads) continue;
    for (int j : body) assigned[j] = 1;
    members.push_back(body);
  }
  // Beads and bodies with their initial poses.
  r->beads.clear();
  r->bodies.clear();
  for (size_t b = 0; b < members.size(); ++b) {
    TrackBody body;
    body.id = static_cast<int>(b) + 1;
    body.lab_from_body.assign(F, Pose6::Zero());
    body.covariance.assign(F, Matrix6::Zero());
    body.found.assign(F, 0);
    body.found[0] = 1;
    for (int i : members[b]) {
      TrackBead bead;
      bead.id = static_cast<int>(r->beads.size()) + 1;
      bead.body = static_cast<int>(b);
      bead.candidate.assign(F, -1);
      bead.candidate[0] = i;
      for (size_t f = 1; f < F; ++f) bead.candidate[f] = match_of[f][i];
      body.beads.push_back(static_cast<int>(r->beads.size()));
      r->beads.push_back(bead);
    }
    for (size_t f = 1; f < F; ++f) {
      // The rigid fit of the matched beads; the worst bead further than the tolerance from it is
      // dropped from this frame (a wrong epipolar pairing that happened to fit the distances)
      // and the fit repeated.
      for (;;) {
        std::vector<Eigen::Vector3d> p0, p1;
        std::vector<int> who;
        for (int bi : body.beads) {
          const int k = r->beads[bi].candidate[f];
          if (k < 0) continue;
          p0.push_back(ref[r->beads[bi].candidate[0]].point.p_lab);
          p1.push_back(r->candidates[f][k].point.p_lab);
          who.push_back(bi);
        }
        if (static_cast<int>(p0.size()) < o.min_body_beads) {
          for (int bi : body.beads) r->beads[bi].candidate[f] = -1;
          body.found[f] = 0;
          break;
        }
        body.found[f] = 1;
        body.lab_from_body[f] = RigidFit(p0, p1);
        const Eigen::Matrix3d R = RotationOf(body.lab_from_body[f].data());
        int worst = -1;
        double worst_d = o.rigid_tolerance_mm;
        for (size_t q = 0; q < p0.size(); ++q) {
          const double d = (R * p0[q] + body.lab_from_body[f].tail<3>() - p1[q]).norm();
          if (d > worst_d) worst_d = d, worst = who[q];
        }
        if (worst < 0) break;
        r->beads[worst].candidate[f] = -1;
      }
    }
    r->bodies.push_back(body);
  }
  for (size_t f = 1; f < F; ++f) {
    Reassociate(o, f, r);
    for (TrackBody& body : r->bodies) {
      int n = 0;
      for (int bi : body.beads) n += r->beads[bi].candidate[f] >= 0;
      if (n < o.min_body_beads) {
        body.found[f] = 0;
        for (int bi : body.beads) r->beads[bi].candidate[f] = -1;
      }
    }
  }
}

void AddSingleCameraBeads(const TrackOptions& o, TrackResult* r) {
  const auto& ref = r->candidates[0];
  for (size_t f = 1; f < r->frames.size(); ++f) {
    // Blobs already taken by a bead in this frame, per camera.
    std::set<std::pair<int, int>> used;
    for (const TrackBead& bead : r->beads) {
      if (bead.candidate[f] < 0) continue;
      for (const TrackObservation& ob : r->candidates[f][bead.candidate[f]].observations)
        used.insert({ob.camera, ob.blob});
    }
    for (const TrackBody& body : r->bodies) {
      if (!body.found[f]) continue;
      const Eigen::Matrix3d R = RotationOf(body.lab_from_body[f].data());
      for (int bi : body.beads) {
        TrackBead& bead = r->beads[bi];
        if (bead.candidate[f] >= 0) continue;
        const Eigen::Vector3d predicted =
            R * ref[bead.candidate[0]].point.p_lab + body.lab_from_body[f].tail<3>();
        // The nearest unused blob to the prediction in each camera; only a bead that exactly one
        // camera sees this way is added (two would have been an epipolar candidate).
        std::vector<TrackObservation> found;
        for (const TrackImage& im : r->images) {
          if (im.frame != static_cast<int>(f)) continue;
          Eigen::Vector2d uv;
          if (!Project(r->cameras[im.camera], predicted, &uv)) continue;
          int best = -1;
          double best_d = o.epipolar_px;
          for (size_t j = 0; j < im.detection.blobs.size(); ++j) {
            if (used.count({im.camera, static_cast<int>(j)})) continue;
            const cv::Point2d& q = im.detection.blobs[j].uv_px;
            const double d = std::hypot(q.x - uv[0], q.y - uv[1]);
            if (d < best_d) best_d = d, best = static_cast<int>(j);
          }
          if (best < 0) continue;
          const MarkerBlob& b = im.detection.blobs[best];
          TrackObservation t;
          t.camera = im.camera;
          t.blob = best;
          t.uv_px = Eigen::Vector2d(b.uv_px.x, b.uv_px.y);
          t.covariance_px2 << b.covariance_px2(0, 0), b.covariance_px2(0, 1),
              b.covariance_px2(1, 0), b.covariance_px2(1, 1);
          found.push_back(t);
        }
        if (found.size() != 1) continue;
        TrackCandidate c;
        c.observations = found;
        c.point.p_lab = predicted;
        used.insert({found[0].camera, found[0].blob});
        bead.candidate[f] = static_cast<int>(r->candidates[f].size());
        r->candidates[f].push_back(c);
      }
    }
  }
}

Status SolveTrack(double marker_diameter_mm, TrackResult* r) {
  ba::BaProblem problem;
  problem.name = "track";
  problem.marker_radius_mm = marker_diameter_mm / 2;
  for (const TrackCamera& c : r->cameras) {
    ba::IntrinsicsGroup g;
    g.name = c.name;
    g.width = c.width;
    g.height = c.height;
    g.initial = c.intrinsics;
    g.free.fill(false);
    if (!c.covariance_indices.empty()) {
      g.has_prior = true;
      g.prior.mean = c.intrinsics;
      g.prior.indices = c.covariance_indices;
      g.prior.covariance = c.covariance;
      for (int i : c.covariance_indices) g.free[i] = true;
    }
    problem.groups.push_back(g);
  }
  for (const TrackBead& bead : r->beads) {
    ba::BaMarker m;
    m.id = bead.id;
    m.p_ct = r->candidates[0][bead.candidate[0]].point.p_lab;
    problem.markers.push_back(m);
  }
  problem.markers_free = true;
  problem.marker_priors = false;
  std::vector<std::vector<int>> rig_of(r->frames.size(), std::vector<int>(r->bodies.size(), -1));
  for (size_t f = 0; f < r->frames.size(); ++f) {
    for (size_t b = 0; b < r->bodies.size(); ++b) {
      const TrackBody& body = r->bodies[b];
      if (!body.found[f]) continue;
      ba::BaRig rig;
      rig.id = FrameLabel(*r, f) + " body " + std::to_string(body.id);
      rig.initial = body.lab_from_body[f];
      rig.constant = f == 0;
      const int rig_index = static_cast<int>(problem.rigs.size());
      problem.rigs.push_back(rig);
      rig_of[f][b] = rig_index;
      for (size_t c = 0; c < r->cameras.size(); ++c) {
        ba::BaView v;
        v.id = FrameLabel(*r, f) + " " + r->cameras[c].name + " body " + std::to_string(body.id);
        v.kind = ba::ViewKind::kObject;
        v.group = static_cast<int>(c);
        v.rig = rig_index;
        v.cam_from_rig = r->cameras[c].cam_from_lab;
        for (int bi : body.beads) {
          const int k = r->beads[bi].candidate[f];
          if (k < 0) continue;
          for (const auto& ob : r->candidates[f][k].observations) {
            if (ob.camera != static_cast<int>(c)) continue;
            v.point_ids.push_back(r->beads[bi].id);
            v.uv_px.push_back(ob.uv_px);
            v.obs_covariance_px2.push_back(ob.covariance_px2);
          }
        }
        if (!v.point_ids.empty()) problem.views.push_back(v);
      }
    }
  }
  ba::BaOptions options;
  options.covariance_scale = ba::CovarianceScale::kPerGroup;
  auto solved = ba::SolveBundleAdjustment(problem, options);
  if (!solved.ok())
    return Status::Error("the bundle adjustment over the frames: " + solved.status().message());
  const ba::BaResult& res = *solved;
  const ba::StateLayout& L = *res.layout;
  r->ba_chi2 = res.chi2;
  r->ba_dof = res.dof;
  r->ba_sigma0 = res.sigma0;
  r->checks.rms_px = res.rms_object_px;
  r->checks.pixel_sigma_scale =
      res.group_sigma_scale[static_cast<int>(ba::NoiseGroup::kDetectedBlobs)];
  for (const std::string& w : ba::SolveWarnings(res))
    r->warnings.push_back("bundle adjustment: " + w);
  const size_t F = r->frames.size(), B = r->beads.size();
  r->bead_in_body.assign(B, Eigen::Vector3d::Zero());
  r->bead_covariance.assign(B, Eigen::Matrix3d::Zero());
  r->bead_lab.assign(F, std::vector<Eigen::Vector3d>(B, Eigen::Vector3d::Constant(std::nan(""))));
  r->bead_lab_covariance.assign(F, std::vector<Eigen::Matrix3d>(B, Eigen::Matrix3d::Zero()));
  r->bead_rms_px.assign(F, std::vector<double>(B, 0));
  r->bead_num_views.assign(F, std::vector<int>(B, 0));
  for (size_t bi = 0; bi < B; ++bi) {
    r->bead_in_body[bi] = res.MarkerPosition(static_cast<int>(bi));
    r->bead_covariance[bi] = res.MarkerCovariance(static_cast<int>(bi));
  }
  for (size_t f = 0; f < F; ++f) {
    for (size_t b = 0; b < r->bodies.size(); ++b) {
      TrackBody& body = r->bodies[b];
      if (rig_of[f][b] < 0) continue;
      const int rb = L.rig_block(rig_of[f][b]);
      body.lab_from_body[f] = Eigen::Map<const Pose6>(res.block(rb));
      body.covariance[f] = res.Covariance({rb});
      const Eigen::Matrix3d R = RotationOf(body.lab_from_body[f].data());
      for (int bi : body.beads) {
        const int k = r->beads[bi].candidate[f];
        if (k < 0) continue;
        const int mb = L.marker_block(bi);
        // x = R(r) p + t: Jacobian over [r, t, p].
        Eigen::Vector3d Rp;
        Eigen::Matrix<double, 3, 3, Eigen::RowMajor> J_r;
        RotatePointWithJac(
            body.lab_from_body[f].data(), r->bead_in_body[bi].data(), Rp.data(), J_r.data());
        Eigen::Matrix<double, 3, 9> J;
        J << J_r, Eigen::Matrix3d::Identity(), R;
        r->bead_lab[f][bi] = Rp + body.lab_from_body[f].tail<3>();
        r->bead_lab_covariance[f][bi] = J * res.Covariance({rb, mb}) * J.transpose();
        double sq = 0;
        const auto& obs = r->candidates[f][k].observations;
        for (const auto& ob : obs) {
          Eigen::Vector2d uv;
          Project(r->cameras[ob.camera], r->bead_lab[f][bi], &uv);
          sq += (uv - ob.uv_px).squaredNorm();
        }
        r->bead_rms_px[f][bi] = std::sqrt(sq / (2.0 * obs.size()));
        r->bead_num_views[f][bi] = static_cast<int>(obs.size());
      }
    }
  }
  return Status::Ok();
}
namespace {

// The expected largest spread (max - min over the frames) over `distances` when each is its
// mean plus N(0, sigma_f) noise in each frame it was measured in: seeded Monte Carlo.
double PredictedMaxSpread(const std::vector<BodyDistance>& distances) {
  constexpr int kSpreadDraws = 2000;
  Rng rng(20261203);
  std::normal_distribution<double> normal(0, 1);
  double sum = 0;
  for (int k = 0; k < kSpreadDraws; ++k) {
    double largest = 0;
    for (const BodyDistance& d : distances) {
      double lo = 1e300, hi = -1e300;
      for (double s : d.sigma_mm) {
        if (!std::isfinite(s)) continue;
        const double x = s * normal(rng);
        lo = std::min(lo, x);
        hi = std::max(hi, x);
      }
      if (hi > lo) largest = std::max(largest, hi - lo);
    }
    sum += largest;
  }
  return sum / kSpreadDraws;
}

}  // namespace


void CheckTrack(TrackResult* r) {
  const size_t F = r->frames.size();
  r->distances.clear();
  TrackChecks& c = r->checks;
  c.min_beads_per_frame = std::numeric_limits<int>::max();
  for (size_t f = 0; f < F; ++f) {
    int n = 0;
    for (size_t bi = 0; bi < r->beads.size(); ++bi) n += r->bead_num_views[f][bi] >= 2;
    c.min_beads_per_frame = std::min(c.min_beads_per_frame, n);
  }
  if (F == 0) c.min_beads_per_frame = 0;
  double sum_sq = 0;
  int num_sq = 0;
  c.distance_chi2 = 0;
  c.distance_dof = 0;
  for (const TrackBody& body : r->bodies) {
    for (size_t x = 0; x < body.beads.size(); ++x) {
      for (size_t y = x + 1; y < body.beads.size(); ++y) {
        const TrackBead& a = r->beads[body.beads[x]];
        const TrackBead& b = r->beads[body.beads[y]];
        BodyDistance d;
        d.body = body.id;
        d.bead_a = a.id;
        d.bead_b = b.id;
        d.distance_mm.assign(F, std::nan(""));
        d.sigma_mm.assign(F, std::nan(""));
        double wsum = 0, wd = 0, lo = 1e300, hi = -1e300;
        for (size_t f = 0; f < F; ++f) {
          if (a.candidate[f] < 0 || b.candidate[f] < 0) continue;
          // A bead seen by one camera has no triangulation of its own in this frame.
          if (r->candidates[f][a.candidate[f]].observations.size() < 2 ||
              r->candidates[f][b.candidate[f]].observations.size() < 2) {
            continue;
          }
          const HeldPoint& pa = r->candidates[f][a.candidate[f]].point;
          const HeldPoint& pb = r->candidates[f][b.candidate[f]].point;
          const Eigen::Vector3d u = (pa.p_lab - pb.p_lab).normalized();
          d.distance_mm[f] = (pa.p_lab - pb.p_lab).norm();
          d.sigma_mm[f] =
              c.pixel_sigma_scale * std::sqrt(u.dot((pa.covariance + pb.covariance) * u));
          wsum += 1.0 / (d.sigma_mm[f] * d.sigma_mm[f]);
          wd += d.distance_mm[f] / (d.sigma_mm[f] * d.sigma_mm[f]);
          lo = std::min(lo, d.distance_mm[f]);
          hi = std::max(hi, d.distance_mm[f]);
        }
        if (wsum == 0) continue;
        const double mean = wd / wsum;
        int n = 0;
        for (size_t f = 0; f < F; ++f) {
          if (!std::isfinite(d.distance_mm[f])) continue;
          ++n;
          c.distance_chi2 += std::pow((d.distance_mm[f] - mean) / d.sigma_mm[f], 2);
          for (size_t g = f + 1; g < F; ++g) {
            if (!std::isfinite(d.distance_mm[g])) continue;
            const double s = std::hypot(d.sigma_mm[f], d.sigma_mm[g]);
            d.max_change_sigmas =
                std::max(d.max_change_sigmas, std::abs(d.distance_mm[f] - d.distance_mm[g]) / s);
          }
        }
        if (n < 2) continue;
        for (size_t f = 0; f < F; ++f) {
          if (std::isfinite(d.distance_mm[f]))
            sum_sq += std::pow(d.distance_mm[f] - mean, 2), ++num_sq;
        }
        c.distance_dof += n - 1;
        d.spread_mm = hi - lo;
        c.max_spread_mm = std::max(c.max_spread_mm, d.spread_mm);
        c.max_change_sigmas = std::max(c.max_change_sigmas, d.max_change_sigmas);
        c.max_change_sigmas_stated =
            std::max(c.max_change_sigmas_stated, d.max_change_sigmas * c.pixel_sigma_scale);
        r->distances.push_back(d);
      }
    }
  }
  c.rms_spread_mm = num_sq > 0 ? std::sqrt(sum_sq / num_sq) : 0;
  c.predicted_max_spread_mm = PredictedMaxSpread(r->distances);
  c.distance_chi2_p = c.distance_dof > 0 ? ChiSquareUpperTail(c.distance_chi2, c.distance_dof) : 1;
}

StatusOr<TrackResult> Track(const std::vector<TrackCamera>& cameras,
                            const std::vector<TrackFrame>& frames,
                            const TrackOptions& options) {
  std::string error;
  if (!options.Check(&error)) return Status::Error(error);
  if (cameras.size() < 2) return Status::Error("tracking needs at least two cameras");
  TrackResult r;
  r.cameras = cameras;
  r.frames = frames;
  // 1. Beads in each image.
  auto t0 = Clock::now();
  const Eigen::Vector3d centre = CommonFieldCentre(cameras);
  for (size_t f = 0; f < frames.size(); ++f) {
    for (size_t c = 0; c < cameras.size(); ++c) {
      const std::string& path = frames[f].image_per_camera[c];
      if (path.empty()) continue;
      const cv::Mat image = ImRead(path, cv::IMREAD_UNCHANGED);
      if (image.empty()) return Status::Error(path + ": cannot be read as an image");
      if (image.cols != cameras[c].width || image.rows != cameras[c].height) {
        return Status::Error(path + ": " + std::to_string(image.cols) + " x " +
                             std::to_string(image.rows) + " px, but camera " + cameras[c].name +
                             " is calibrated for " + std::to_string(cameras[c].width) + " x " +
                             std::to_string(cameras[c].height));
      }
      MarkerBlobOptions blobs = options.blobs;
      blobs.diameter_mm = options.marker_diameter_mm;
      blobs.px_per_mm = cameras[c].intrinsics[kFx] / (centre - cameras[c].CentreInLab()).norm();
      blobs.diameter_tolerance = options.diameter_tolerance;
      TrackImage ti;
      ti.frame = static_cast<int>(f);
      ti.camera = static_cast<int>(c);
      ti.path = path;
      ti.detection = DetectMarkerBlobs(image, blobs);
      if (!ti.detection.ok) {
        r.warnings.push_back(path + ": no beads: " + ti.detection.reason);
      } else {
        SplitMergedPairs(image, blobs, &ti);
      }
      r.images.push_back(std::move(ti));
    }
  }
  r.time_detect_s = Seconds(t0);
  auto tracked = TrackDetections(cameras, frames, std::move(r.images), options);
  if (!tracked.ok()) return tracked.status();
  tracked->time_detect_s = r.time_detect_s;
  tracked->warnings.insert(tracked->warnings.begin(), r.warnings.begin(), r.warnings.end());
  return tracked;
}

StatusOr<TrackResult> TrackDetections(const std::vector<TrackCamera>& cameras,
                                      const std::vector<TrackFrame>& frames,
                                      std::vector<TrackImage> images,
                                      const TrackOptions& options) {
  std::string error;
  if (!options.Check(&error)) return Status::Error(error);
  if (cameras.size() < 2) return Status::Error("tracking needs at least two cameras");
  if (frames.empty()) return Status::Error("no frames");
  TrackResult r;
  r.cameras = cameras;
  r.frames = frames;
  r.images = std::move(images);
  // 2. Candidates per frame.
  auto t0 = Clock::now();
  r.candidates.resize(frames.size());
  for (size_t f = 0; f < frames.size(); ++f) {
    std::vector<const MarkerBlobDetection*> per_camera(cameras.size(), nullptr);
    for (const TrackImage& im : r.images) {
      if (im.frame == static_cast<int>(f) && im.detection.ok) per_camera[im.camera] = &im.detection;
    }
    r.candidates[f] = MatchFrame(cameras, per_camera, options);
  }
  // 3. Identity and bodies.
  FindBodies(options, &r);
  AddSingleCameraBeads(options, &r);
  r.time_match_s = Seconds(t0);
  if (r.bodies.empty()) {
    return Status::Error(
        "no rigid body of >= " + std::to_string(options.min_body_beads) +
        " beads found in every frame (" + std::to_string(r.candidates[0].size()) +
        " bead candidates in the first frame; check --marker-diameter-mm and the cameras)");
  }
  for (size_t f = 0; f < frames.size(); ++f) {
    for (const TrackBody& b : r.bodies) {
      if (!b.found[f]) {
        r.warnings.push_back(FrameLabel(r, f) + ": body " + std::to_string(b.id) +
                             " not identified (fewer than " +
                             std::to_string(options.min_body_beads) + " of its beads matched)");
      }
    }
    std::set<int> used;
    for (const TrackBead& bead : r.beads)
      if (bead.candidate[f] >= 0) used.insert(bead.candidate[f]);
    std::set<std::pair<int, int>> used_blobs;
    for (int k : used)
      for (const auto& ob : r.candidates[f][k].observations)
        used_blobs.insert({ob.camera, ob.blob});
    int unassigned = 0;
    for (size_t k = 0; k < r.candidates[f].size(); ++k) {
      bool shares = false;
      for (const auto& ob : r.candidates[f][k].observations)
        shares |= used_blobs.count({ob.camera, ob.blob}) > 0;
      unassigned += !used.count(static_cast<int>(k)) && !shares;
    }
    if (unassigned > 0) {
      r.warnings.push_back(
          FrameLabel(r, f) + ": " + std::to_string(unassigned) +
          " bead candidate(s) matched across the cameras but in no rigid body (no id)");
    }
  }
  // 4. One bundle adjustment.
  t0 = Clock::now();
  if (Status s = SolveTrack(options.marker_diameter_mm, &r); !s.ok()) return s;
  r.time_ba_s = Seconds(t0);
  // 5. Checks.
  CheckTrack(&r);
  return r;
}

}  // namespace carmba
