// Relative pose, triangulation and leave-one-marker-out TRE on the engine (src/ba/
// relative_pose.h, triangulation.h, tre.h), checked against seeded Monte Carlo re-solves of the
// synthetic joint problem (10 plate views, 7 object views of the thesis's 9-marker object, all
// noise sources on: plate and object pixels, CT, an intrinsics prior):
//   * the relative pose's Jacobian against central differences; its 6x6 covariance by NEES;
//   * a triangulated tip's 3x3 covariance by NEES, with the calibration's share non-zero;
//   * the leave-one-out TRE: mean squared error / predicted in [0.8, 1.25];
//   * Fitzpatrick's formula on a hand-worked layout; bad input to the triangulation.
// NEES acceptance [0.8, 1.25] is the issue's. With T trials a mean NEES / dim of dimension d has a
// relative standard error of about sqrt(2 / (d T)) (correlated trials make it larger): 200 trials
// of a 6-dim NEES give ~4 %, so the band is > 5 standard errors wide.
#include "analysis/triangulation.h"

#include <gtest/gtest.h>

#include <array>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>

#include "analysis/relative_pose.h"
#include "analysis/tre.h"
#include "ba/bundle_adjuster.h"
#include "ba/synthetic_pixels.h"
#include "figures.h"
#include "geometry/rotation.h"
#include "synthetic/synthetic_joint.h"

namespace carmba {
namespace analysis {
namespace {

constexpr double kTriNeesLow = 0.8, kTriNeesHigh = 1.25;  // the band

ba::SyntheticJointSpec TriangulationSpec() {
  ba::SyntheticJointSpec s;
  s.num_plate_views = 10;
  s.intrinsics_prior = true;
  return s;
}


TEST(RelativePose, JacobianMatchesCentralDifferences) {
  // Central differences have a truncation error ~h^2 |f'''| and a rounding error ~eps |f| / h:
  // with h = 1e-6 both are below 1e-7 for rotation vectors of order 1 and translations of 1e3 mm.
  constexpr double kH = 1e-6, kTol = 1e-6;
  Pose6 a, b;
  a << 0.3, -0.4, 0.2, 10, -20, 700;
  b << -0.5, 1.1, 0.3, -40, 5, 720;
  Eigen::Matrix<double, 6, 12> J;
  RelativePoseWithJacobian(a, b, &J);
  for (int k = 0; k < 12; ++k) {
    Pose6 ap = a, am = a, bp = b, bm = b;
    if (k < 6) {
      ap[k] += kH, am[k] -= kH;
    } else {
      bp[k - 6] += kH, bm[k - 6] -= kH;
    }
    Pose6 rp, rm;
    RelativePose(ap.data(), bp.data(), rp.data());
    RelativePose(am.data(), bm.data(), rm.data());
    const Pose6 num = (rp - rm) / (2 * kH);
    for (int i = 0; i < 6; ++i) {
      EXPECT_NEAR(J(i, k), num[i], kTol * (1 + std::abs(num[i]))) << "row " << i << " column " << k;
    }
  }
  // Composition: the relative pose maps view a's camera points to view b's.
  const Eigen::Vector3d p(3, -7, 11);
  Pose6 rel;
  RelativePose(a.data(), b.data(), rel.data());
  const Eigen::Vector3d in_a = RotationOf(a.head<3>()) * p + a.tail<3>();
  const Eigen::Vector3d in_b = RotationOf(b.head<3>()) * p + b.tail<3>();
  EXPECT_LT((RotationOf(rel.head<3>()) * in_a + rel.tail<3>() - in_b).norm(), 1e-9);
}

TEST(RelativePose, MonteCarloNeesAndThreeSigma) {
  constexpr int kTrials = 200;
  const ba::SyntheticJoint ref =
      ba::MakeSyntheticJoint(TriangulationSpec(), ba::NoiseSwitches(), 0);
  const auto pairs = RelativePosePairs(ref.problem, ref.pairs);
  ASSERT_EQ(pairs.size(), 21u);  // 7 object views: all pairs
  std::vector<double> nees(pairs.size(), 0.0);
  int within3 = 0, total = 0;
  double worst_sigma = 0, us = 0, us_batch = 0;
  for (int t = 0; t < kTrials; ++t) {
    const ba::SyntheticJoint sj =
        ba::MakeSyntheticJoint(TriangulationSpec(), ba::NoiseSwitches(), 7000 + t);
    auto r = ba::SolveBundleAdjustment(sj.problem, ba::BaOptions());
    ASSERT_TRUE(r.ok()) << r.status().message();
    const auto tb = std::chrono::steady_clock::now();
    const auto batch = EstimateRelativePoses(*r, pairs);
    us_batch +=
        std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - tb).count();
    if (t == 0) {
      // The batch (one covariance of all views) equals pair by pair.
      ASSERT_EQ(batch.size(), pairs.size());
      for (size_t k = 0; k < pairs.size(); ++k) {
        const auto one = EstimateRelativePose(*r, pairs[k].first, pairs[k].second);
        EXPECT_LT((batch[k].covariance - one.covariance).norm(), 1e-12 * one.covariance.norm());
        EXPECT_EQ(batch[k].view_a, pairs[k].first);
      }
    }
    for (size_t k = 0; k < pairs.size(); ++k) {
      const auto [a, b] = pairs[k];
      const auto t0 = std::chrono::steady_clock::now();
      const RelativePoseEstimate est = EstimateRelativePose(*r, a, b);
      us +=
          std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count();
      const RelativePoseError err = CompareRelativePose(est, sj.true_poses[a], sj.true_poses[b]);
      nees[k] += err.nees / 6.0;
      within3 += err.rotation_mahalanobis < 3.0;
      ++total;
      worst_sigma = std::max(worst_sigma, std::abs(err.angle_error_sigma));
    }
  }
  double lo = 1e9, hi = 0, mean = 0;
  for (double& x : nees) {
    x /= kTrials;
    lo = std::min(lo, x), hi = std::max(hi, x), mean += x / nees.size();
    EXPECT_GE(x, kTriNeesLow);
    EXPECT_LE(x, kTriNeesHigh);
  }
  // The rotation part's Mahalanobis distance (3 dof) is below 3 with probability 0.971.
  const double frac = static_cast<double>(within3) / total;
  std::printf("relative pose, %d trials x %zu pairs: mean NEES / 6 = %.3f (pairs %.3f .. %.3f); "
              "rotation within 3 sigma (3-dof Mahalanobis) %.3f (0.971 expected); worst angle "
              "error %.2f sigma; %.1f us per pair alone, %.0f us for the %zu pairs together\n",
              kTrials, pairs.size(), mean, lo, hi, frac, worst_sigma, us / total,
              us_batch / kTrials, pairs.size());
  testing::RecordFigure("mc.relative_pose_trials", "%d trials x %zu pairs", kTrials, pairs.size());
  testing::RecordFigure("mc.relative_pose_nees", "%.3f (pairs %.3f .. %.3f)", mean, lo, hi);
  testing::RecordFigure("mc.relative_pose_within3", "%.1f %%", 100 * frac);
  EXPECT_NEAR(frac, 0.971, 0.02);
}

// A point away from the markers (an instrument tip), projected through the TRUE camera.
const Eigen::Vector3d kTip(-30.0, 10.0, 80.0);

std::vector<PixelObservation> TipPixels(const ba::SyntheticJoint& sj,
                                        const std::vector<int>& views,
                                        double sigma_px,
                                        std::mt19937_64* rng) {
  return TruePointPixels(sj, kTip, views, sigma_px, rng);
}

TEST(Triangulation, MonteCarloNees) {
  constexpr int kTrials = 300;
  constexpr double kTipSigmaPx = 0.3;
  for (const bool two_views : {true, false}) {
    double nees = 0;
    std::array<double, ba::kNumSources> share{};
    double share_pixels = 0;
    std::mt19937_64 rng(42);
    double us = 0;
    int flagged = 0;
    double chi2_per_dof = 0;
    for (int t = 0; t < kTrials; ++t) {
      const ba::SyntheticJoint sj =
          ba::MakeSyntheticJoint(TriangulationSpec(), ba::NoiseSwitches(), 9000 + t);
      auto r = ba::SolveBundleAdjustment(sj.problem, ba::BaOptions());
      ASSERT_TRUE(r.ok()) << r.status().message();
      std::vector<int> views = ObjectViews(sj.problem);
      if (two_views) views = {views[0], views[4]};  // 0 and 90 degrees
      const auto obs = TipPixels(sj, views, kTipSigmaPx, &rng);
      const auto t0 = std::chrono::steady_clock::now();
      auto tp = TriangulatePoint(sj.problem, *r, obs);
      us +=
          std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count();
      ASSERT_TRUE(tp.ok()) << tp.status().message();
      // The self-check flags (and with 3+ rays rejects) at its 0.5 % tail; its mean chi2 / dof
      // near 1 says its residual covariance is right (both in src/docs/results.md).
      flagged += !tp->warnings.empty();
      chi2_per_dof += tp->chi2 / tp->dof / kTrials;
      const Eigen::Vector3d e = tp->p_in_object - kTip;
      nees += e.dot(tp->covariance.ldlt().solve(e)) / 3.0;
      const double tr = tp->covariance.trace();
      for (int s = 0; s < ba::kNumSources; ++s)
        share[s] += tp->solve_trace_by_source[s] / tr / kTrials;
      share_pixels += tp->covariance_pixels.trace() / tr / kTrials;
    }
    nees /= kTrials;
    std::printf("triangulated tip (%s, %d trials): self-check mean chi2 / dof %.3f, %d flagged\n",
                two_views ? "views +000 and +090" : "all 7 views", kTrials, chi2_per_dof, flagged);
    EXPECT_LE(flagged, kTrials * 3 / 100);
    std::printf("triangulated tip (%s, %d trials): mean NEES / 3 = %.3f; variance shares: tip "
                "pixels %.1f %%, object pixels %.1f %%, CT %.1f %%, plate pixels %.2f %%, "
                "intrinsics prior %.2f %%; %.0f us per point\n",
                two_views ? "views +000 and +090" : "all 7 views", kTrials, nees,
                100 * share_pixels, 100 * share[1], 100 * share[2], 100 * share[0], 100 * share[4],
                us / kTrials);
    testing::RecordFigure(
        two_views ? "mc.tip_nees_two_views" : "mc.tip_nees_all_views", "%.3f", nees);
    testing::RecordFigure(two_views ? "mc.tip_chi2_two_views" : "mc.tip_chi2_all_views",
                          "%.2f (%d of %d flagged)",
                          chi2_per_dof,
                          flagged,
                          kTrials);
    testing::RecordFigure("mc.tip_trials", "%d", kTrials);
    EXPECT_GE(nees, kTriNeesLow);
    EXPECT_LE(nees, kTriNeesHigh);
  }
}

// A mis-clicked pixel (94.5 px off): with seven rays it is rejected and the point stays within
// its covariance of the truth; with two rays it cannot be told which is wrong, and the point is
// flagged instead of reported silently.
TEST(Triangulation, AMisclickedRayIsRejectedOrFlagged) {
  const ba::SyntheticJoint sj =
      ba::MakeSyntheticJoint(TriangulationSpec(), ba::NoiseSwitches(), 31337);
  auto r = ba::SolveBundleAdjustment(sj.problem, ba::BaOptions());
  ASSERT_TRUE(r.ok()) << r.status().message();
  std::mt19937_64 rng(5);
  const std::vector<int> views = ObjectViews(sj.problem);
  auto obs = TipPixels(sj, views, 0.3, &rng);
  obs[2].uv_px += Eigen::Vector2d(80.0, -50.0);  // 94.5 px
  auto t = TriangulatePoint(sj.problem, *r, obs);
  ASSERT_TRUE(t.ok()) << t.status().message();
  for (size_t i = 0; i < obs.size(); ++i) EXPECT_EQ(t->rejected[i], i == 2 ? 1 : 0) << i;
  const Eigen::Vector3d e = t->p_in_object - kTip;
  EXPECT_LT(e.dot(t->covariance.ldlt().solve(e)), 16.3);  // chi-square(3) 99.9 %
  EXPECT_GT(t->chi2_p_value, 0.005);
  EXPECT_EQ(t->dof, 2 * 6 - 3);
  ASSERT_FALSE(t->warnings.empty());
  EXPECT_NE(t->warnings[0].find("the ray of view '" + sj.problem.views[obs[2].view].id +
                                "' was rejected as an outlier"),
            std::string::npos)
      << t->warnings[0];
  EXPECT_NEAR(t->residual_px[2].norm(), 94.5, 2.0);

  auto two = TipPixels(sj, {views[0], views[4]}, 0.3, &rng);
  two[1].uv_px += Eigen::Vector2d(80.0, -50.0);
  auto t2 = TriangulatePoint(sj.problem, *r, two);
  ASSERT_TRUE(t2.ok()) << t2.status().message();
  EXPECT_EQ(t2->rejected[0] + t2->rejected[1], 0);
  ASSERT_EQ(t2->warnings.size(), 1u);
  EXPECT_NE(t2->warnings[0].find("the rays do not meet within their pixel covariances"),
            std::string::npos)
      << t2->warnings[0];
  EXPECT_NE(t2->warnings[0].find("with two rays the wrong one cannot be told"), std::string::npos);
}

TEST(Triangulation, EachSourceAloneMatchesItsShare) {
  // Each noise source of the solve switched on alone (the tip's own pixels noise-free): the
  // tip's mean squared error against the covariance's share of that source. The calibration's
  // share (plate pixels, intrinsics prior) is small here -- the per-view poses absorb most of an
  // intrinsics error (shared/notes/joint-ba.md) -- and is checked like the others.
  constexpr int kTrials = 150;
  const ba::Source sources[] = {ba::Source::kPlatePixels,
                                ba::Source::kObjectPixels,
                                ba::Source::kCt,
                                ba::Source::kIntrinsicsPrior};
  for (ba::Source src : sources) {
    double e2 = 0, predicted = 0;
    std::mt19937_64 rng(7);
    for (int t = 0; t < kTrials; ++t) {
      const ba::SyntheticJoint sj =
          ba::MakeSyntheticJoint(TriangulationSpec(), ba::NoiseSwitches::Only(src), 20000 + t);
      auto r = ba::SolveBundleAdjustment(sj.problem, ba::BaOptions());
      ASSERT_TRUE(r.ok()) << r.status().message();
      const std::vector<int> views = ObjectViews(sj.problem);
      auto tp = TriangulatePoint(sj.problem, *r, TipPixels(sj, {views[0], views[4]}, 0.0, &rng));
      ASSERT_TRUE(tp.ok()) << tp.status().message();
      e2 += (tp->p_in_object - kTip).squaredNorm();
      predicted += tp->solve_trace_by_source[static_cast<int>(src)];
    }
    const double ratio = e2 / predicted;
    std::printf(
        "tip error from %s alone: mean squared error / predicted share = %.3f (RMS %.4f mm)\n",
        ba::SourceName(src),
        ratio,
        std::sqrt(e2 / kTrials));
    std::string key = std::string("mc.tip_source_") + ba::SourceName(src);
    for (char& c : key) c = c == ' ' ? '_' : static_cast<char>(std::tolower(c));
    testing::RecordFigure(key, "%.2f", ratio);
    testing::RecordFigure("mc.tip_source_trials", "%d", kTrials);
    EXPECT_GE(ratio, kTriNeesLow) << ba::SourceName(src);
    EXPECT_LE(ratio, kTriNeesHigh) << ba::SourceName(src);
  }
}

TEST(Triangulation, CovarianceIgnoringTheSolveIsTooSmall) {
  // The same Monte Carlo with only the tip's pixel covariance N^-1: overconfident, which is why
  // the solve's share is propagated (a test that the propagation matters, not a tuning).
  constexpr int kTrials = 150;
  double nees_pixels = 0;
  std::mt19937_64 rng(43);
  for (int t = 0; t < kTrials; ++t) {
    const ba::SyntheticJoint sj =
        ba::MakeSyntheticJoint(TriangulationSpec(), ba::NoiseSwitches(), 11000 + t);
    auto r = ba::SolveBundleAdjustment(sj.problem, ba::BaOptions());
    ASSERT_TRUE(r.ok());
    const std::vector<int> views = ObjectViews(sj.problem);
    auto tp = TriangulatePoint(sj.problem, *r, TipPixels(sj, {views[0], views[4]}, 0.05, &rng));
    ASSERT_TRUE(tp.ok());
    const Eigen::Vector3d e = tp->p_in_object - kTip;
    nees_pixels += e.dot(tp->covariance_pixels.ldlt().solve(e)) / 3.0 / kTrials;
  }
  std::printf("tip with 0.05 px picks, pixel-only covariance: mean NEES / 3 = %.2f\n", nees_pixels);
  testing::RecordFigure("mc.tip_pixel_only_nees", "%.0f", nees_pixels);
  EXPECT_GT(nees_pixels, 2.0);
}

TEST(Triangulation, BadInput) {
  const ba::SyntheticJoint sj = ba::MakeSyntheticJoint(TriangulationSpec(), ba::NoiseSwitches(), 1);
  auto r = ba::SolveBundleAdjustment(sj.problem, ba::BaOptions());
  ASSERT_TRUE(r.ok());
  const std::vector<int> views = ObjectViews(sj.problem);
  std::mt19937_64 rng(1);
  auto obs = TipPixels(sj, {views[0], views[4]}, 0.3, &rng);
  {
    auto one = obs;
    one.resize(1);
    auto t = TriangulatePoint(sj.problem, *r, one);
    ASSERT_FALSE(t.ok());
    EXPECT_NE(t.status().message().find("seen in one view only ('+000')"), std::string::npos)
        << t.status().message();
  }
  {
    auto nan = obs;
    nan[1].uv_px[0] = std::nan("");
    auto t = TriangulatePoint(sj.problem, *r, nan);
    ASSERT_FALSE(t.ok());
    EXPECT_EQ(t.status().message(), "view '+090': non-finite pixel or pixel covariance");
  }
  {
    auto twice = obs;
    twice[1].view = twice[0].view;
    auto t = TriangulatePoint(sj.problem, *r, twice);
    ASSERT_FALSE(t.ok());
    EXPECT_EQ(t.status().message(), "view '+000' is given twice");
  }
  {
    auto plate = obs;
    plate[1].view = 0;
    auto t = TriangulatePoint(sj.problem, *r, plate);
    ASSERT_FALSE(t.ok());
    EXPECT_NE(t.status().message().find("is a plate view"), std::string::npos);
  }
  {
    // Views +000 and +010 are 10 deg apart: a warning only with a threshold above that.
    auto near = TipPixels(sj, {views[0], views[1]}, 0.3, &rng);
    TriangulationOptions o;
    o.min_ray_angle_deg = 15;
    auto t = TriangulatePoint(sj.problem, *r, near, o);
    ASSERT_TRUE(t.ok()) << t.status().message();
    ASSERT_EQ(t->warnings.size(), 1u);
    EXPECT_NE(t->warnings[0].find("nearly parallel"), std::string::npos);
    // The rays of the tip are 9.3 deg apart (the C-arm's 10 deg about an axis not through the tip).
    EXPECT_NE(t->warnings[0].find("'+000' and '+010') is 9.28 deg apart (below 15)"),
              std::string::npos)
        << t->warnings[0];
    auto t2 = TriangulatePoint(sj.problem, *r, near);  // default 5 deg
    ASSERT_TRUE(t2.ok());
    EXPECT_TRUE(t2->warnings.empty()) << t2->warnings[0];
  }
  {
    // Two views with the same pose: parallel rays, an error.
    ba::BaProblem p = sj.problem;
    ba::BaResult same = *r;
    const int b0 = same.layout->view_block(views[0]), b1 = same.layout->view_block(views[1]);
    std::copy(
        same.block(b0), same.block(b0) + 6, same.state.data() + same.layout->block(b1).offset);
    auto par = obs;
    par[1].view = views[1];
    par[1].uv_px = par[0].uv_px;
    auto t = TriangulatePoint(p, same, par);
    ASSERT_FALSE(t.ok());
    EXPECT_NE(t.status().message().find("parallel"), std::string::npos) << t.status().message();
  }
}

TEST(Fitzpatrick, HandWorkedLayout) {
  // Four fiducials at (+-a, 0, 0), (0, +-b, 0): principal axes x, y, z. RMS distances from the
  // axes: f_x^2 = b^2 / 2, f_y^2 = a^2 / 2, f_z^2 = (a^2 + b^2) / 2. Target (0, 0, c): d_x^2 =
  // d_y^2 = c^2, d_z^2 = 0. TRE^2 = FLE^2 / 4 (1 + (2 c^2 / b^2 + 2 c^2 / a^2) / 3).
  const double a = 40, b = 20, c = 30, fle2 = 0.25;
  const std::vector<Eigen::Vector3d> f = {{a, 0, 0}, {-a, 0, 0}, {0, b, 0}, {0, -b, 0}};
  const double expected = fle2 / 4 * (1 + (2 * c * c / (b * b) + 2 * c * c / (a * a)) / 3);
  EXPECT_NEAR(FitzpatrickTre2(f, Eigen::Vector3d(0, 0, c), fle2), expected, 1e-12);
  // At the centroid: FLE^2 / N.
  EXPECT_NEAR(FitzpatrickTre2(f, Eigen::Vector3d::Zero(), fle2), fle2 / 4, 1e-12);
  // Collinear fiducials: undefined.
  EXPECT_TRUE(
      std::isnan(FitzpatrickTre2({{0, 0, 0}, {1, 0, 0}, {2, 0, 0}}, Eigen::Vector3d::Zero(), 1)));
}

TEST(LeaveOneMarkerOut, MonteCarloMeanSquaredErrorOverPredicted) {
  constexpr int kTrials = 60;
  double sum_e2 = 0, sum_pred2 = 0, sum_true2 = 0, sum_tre2 = 0, sum_fitz2 = 0, sum_m = 0;
  int n = 0;
  double time_s = 0;
  for (int t = 0; t < kTrials; ++t) {
    const ba::SyntheticJoint sj =
        ba::MakeSyntheticJoint(TriangulationSpec(), ba::NoiseSwitches(), 13000 + t);
    auto r = ba::SolveBundleAdjustment(sj.problem, ba::BaOptions());
    ASSERT_TRUE(r.ok());
    auto tre = LeaveOneMarkerOut(sj.problem, *r, ba::BaOptions());
    ASSERT_TRUE(tre.ok()) << tre.status().message();
    ASSERT_EQ(tre->num_evaluated, 9);
    time_s += tre->time_s;
    for (size_t m = 0; m < tre->markers.size(); ++m) {
      const MarkerTre& k = tre->markers[m];
      ASSERT_TRUE(k.skipped.empty()) << k.skipped;
      sum_e2 += k.error_mm * k.error_mm;
      sum_pred2 += k.predicted_rms_mm * k.predicted_rms_mm;
      sum_true2 += (k.p_triangulated - sj.true_markers[m]).squaredNorm();
      sum_tre2 += k.predicted_tre_mm * k.predicted_tre_mm;
      sum_fitz2 += k.fitzpatrick_rms_mm * k.fitzpatrick_rms_mm;
      sum_m += k.mahalanobis2 / 3;
      ++n;
    }
  }
  const double ratio = sum_e2 / sum_pred2, ratio_true = sum_true2 / sum_tre2;
  std::printf("leave-one-marker-out, %d trials x %d markers: mean |p_tri - p_ct|^2 / predicted = "
              "%.3f; against the true positions %.3f; mean Mahalanobis^2 / 3 = %.3f; RMS error "
              "%.3f mm, predicted %.3f mm, Fitzpatrick %.3f mm; %.1f ms per leave-one-out run\n",
              kTrials, n / kTrials, ratio, ratio_true, sum_m / n, std::sqrt(sum_e2 / n),
              std::sqrt(sum_pred2 / n), std::sqrt(sum_fitz2 / n), 1e3 * time_s / kTrials);
  testing::RecordFigure("mc.tre_trials", "%d trials x %d markers", kTrials, n / kTrials);
  testing::RecordFigure("mc.tre_ratio",
                        "%.3f against the CT positions, %.3f against the true ones",
                        ratio,
                        ratio_true);
  testing::RecordFigure("mc.tre_rms",
                        "RMS %.3f mm measured, %.3f predicted, %.3f Fitzpatrick",
                        std::sqrt(sum_e2 / n),
                        std::sqrt(sum_pred2 / n),
                        std::sqrt(sum_fitz2 / n));
  EXPECT_GE(ratio, kTriNeesLow);
  EXPECT_LE(ratio, kTriNeesHigh);
  EXPECT_GE(ratio_true, kTriNeesLow);
  EXPECT_LE(ratio_true, kTriNeesHigh);
}

TEST(LeaveOneMarkerOut, FourMarkersPerViewAreSkippedWithTheReason) {
  // Views with four markers: leaving one out leaves three, so every view drops out of the solve.
  ba::SyntheticJoint sj = ba::MakeSyntheticJoint(TriangulationSpec(), ba::NoiseSwitches(), 3);
  for (auto& v : sj.problem.views) {
    if (v.kind != ba::ViewKind::kObject) continue;
    v.point_ids.resize(4);
    v.uv_px.resize(4);
  }
  auto r = ba::SolveBundleAdjustment(sj.problem, ba::BaOptions());
  ASSERT_TRUE(r.ok()) << r.status().message();
  auto tre = LeaveOneMarkerOut(sj.problem, *r, ba::BaOptions());
  ASSERT_TRUE(tre.ok());
  EXPECT_EQ(tre->num_evaluated, 0);
  EXPECT_EQ(tre->markers[0].skipped,
            "seen in 0 view(s) of the solve without it (7 view(s) left out: fewer than 4 other "
            "markers): at least two are needed");
  EXPECT_EQ(tre->markers[8].skipped.substr(0, 9), "seen in 0");
}

}  // namespace
}  // namespace analysis
}  // namespace carmba
