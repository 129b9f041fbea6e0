// Rigs in the engine (ba/problem.h): views whose pose is a held cam_from_rig times a shared
// rig_from_object block. The analytic residual against its autodiff twin and finite differences,
// and a rig problem (two held cameras, three frames, the first held) that recovers the truth.
#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

#include <memory>
#include <random>

#include "ba/bundle_adjuster.h"
#include "ba/reprojection_error.h"
#include "geometry/random_vector.h"

namespace carmba {
namespace ba {
namespace {

TEST(RigReprojectionError, AnalyticEqualsJetsAndFiniteDifferences) {
  const double rig[6] = {0.1, -0.2, 0.05, 3, -4, 20};
  const double point[3] = {12, -30, 25};
  const double intr[9] = {2000, 2010, 205, 200, 0.08, -0.2, 1e-4, -2e-4, 0.1};
  const double cam_from_rig[6] = {0.3, 0.6, -0.1, -10, 5, 700};
  const double* params[3] = {rig, point, intr};
  PixelWhitening w;
  ASSERT_TRUE(
      PixelWhitening::FromCovariance((Eigen::Matrix2d() << 0.09, 0.03, 0.03, 0.04).finished(), &w));
  RigReprojectionError analytic(200, 190, w, cam_from_rig);
  std::unique_ptr<ceres::CostFunction> twin(
      RigReprojectionErrorAutoDiff::Create(200, 190, w, cam_from_rig));
  double r1[2], r2[2], a[3][18], b[3][18];
  double* ja[3] = {a[0], a[1], a[2]};
  double* jb[3] = {b[0], b[1], b[2]};
  ASSERT_TRUE(analytic.Evaluate(params, r1, ja));
  ASSERT_TRUE(twin->Evaluate(params, r2, jb));
  const int sizes[3] = {6, 3, 9};
  for (int k = 0; k < 2; ++k) EXPECT_NEAR(r1[k], r2[k], 1e-9 * std::max(1.0, std::abs(r2[k])));
  for (int blk = 0; blk < 3; ++blk) {
    for (int i = 0; i < 2 * sizes[blk]; ++i) {
      EXPECT_NEAR(a[blk][i], b[blk][i], 1e-9 * std::max(1.0, std::abs(b[blk][i])))
          << blk << " " << i;
    }
  }
  ceres::NumericDiffOptions nd;
  const std::vector<const ceres::Manifold*>* no_manifolds = nullptr;
  ceres::GradientChecker checker(&analytic, no_manifolds, nd);
  ceres::GradientChecker::ProbeResults res;
  EXPECT_TRUE(checker.Probe(params, 1e-6, &res)) << res.error_log;
  // The same as an ordinary ReprojectionError through the composed pose.
  Eigen::Matrix3d Rc, Rr;
  ceres::AngleAxisToRotationMatrix(cam_from_rig, ceres::ColumnMajorAdapter3x3(Rc.data()));
  ceres::AngleAxisToRotationMatrix(rig, ceres::ColumnMajorAdapter3x3(Rr.data()));
  const Eigen::Matrix3d R = Rc * Rr;
  const Eigen::Vector3d t =
      Rc * Eigen::Vector3d(rig[3], rig[4], rig[5]) + Eigen::Vector3d(cam_from_rig + 3);
  double composed[6];
  ceres::RotationMatrixToAngleAxis(ceres::ColumnMajorAdapter3x3(R.data()), composed);
  for (int i = 0; i < 3; ++i) composed[3 + i] = t[i];
  ReprojectionError plain(200, 190, w);
  const double* p2[3] = {composed, point, intr};
  double r3[2];
  ASSERT_TRUE(plain.Evaluate(p2, r3, nullptr));
  EXPECT_NEAR(r1[0], r3[0], 1e-8);
  EXPECT_NEAR(r1[1], r3[1], 1e-8);
}

TEST(Rigs, TwoHeldCamerasThreeFramesRecoverTheMotionAndTheBeads) {
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0, 0.1);
  BaProblem p;
  for (const char* name : {"a", "b"}) {
    IntrinsicsGroup g;
    g.name = name;
    g.initial = {5000, 5000, 800, 800, 0, 0, 0, 0, 0};
    g.free.fill(false);
    p.groups.push_back(g);
  }
  const Pose6 cam_a = (Pose6() << 0, -0.5, 0, 0, 0, 900).finished();
  const Pose6 cam_b = (Pose6() << 0, 0.6, 0, 0, 0, 1000).finished();
  std::vector<Eigen::Vector3d> beads = {
      {0, 0, 0}, {8, 1, -2}, {-3, 7, 4}, {5, -6, 3}, {-6, -2, -5}};
  for (size_t i = 0; i < beads.size(); ++i) {
    BaMarker m;
    m.id = static_cast<int>(i) + 1;
    m.p_ct = beads[i] + Eigen::Vector3d(0.3, -0.2, 0.1);  // a start off the truth
    p.markers.push_back(m);
  }
  p.marker_priors = false;
  const std::vector<Pose6> truth = {Pose6::Zero(),
                                    (Pose6() << 0.1, -0.05, 0.2, 3, -2, 5).finished(),
                                    (Pose6() << -0.15, 0.1, 0.05, -4, 6, 2).finished()};
  for (size_t f = 0; f < truth.size(); ++f) {
    BaRig rig;
    rig.id = "frame " + std::to_string(f);
    rig.initial = f == 0 ? truth[f] : Pose6(truth[f] + Pose6::Constant(0.01));
    rig.constant = f == 0;
    p.rigs.push_back(rig);
    for (int c = 0; c < 2; ++c) {
      BaView v;
      v.id = rig.id + (c ? " b" : " a");
      v.group = c;
      v.rig = static_cast<int>(f);
      v.cam_from_rig = c ? cam_b : cam_a;
      v.sigma_px = 0.1;
      for (size_t i = 0; i < beads.size(); ++i) {
        Eigen::Matrix3d Rr, Rc;
        ceres::AngleAxisToRotationMatrix(truth[f].data(), ceres::ColumnMajorAdapter3x3(Rr.data()));
        ceres::AngleAxisToRotationMatrix(v.cam_from_rig.data(),
                                         ceres::ColumnMajorAdapter3x3(Rc.data()));
        const Eigen::Vector3d pc =
            Rc * (Rr * beads[i] + truth[f].tail<3>()) + v.cam_from_rig.tail<3>();
        double uv[2];
        ASSERT_TRUE(ProjectCamPoint(p.groups[c].initial.data(), pc.data(), uv));
        v.point_ids.push_back(static_cast<int>(i) + 1);
        v.uv_px.push_back(Eigen::Vector2d(uv[0], uv[1]) + RandomVector<2>(noise, rng));
      }
      p.views.push_back(v);
    }
  }
  ASSERT_TRUE(p.Check().ok()) << p.Check().message();
  auto r = SolveBundleAdjustment(p, BaOptions());
  ASSERT_TRUE(r.ok()) << r.status().message();
  const StateLayout& L = *r->layout;
  for (size_t f = 1; f < truth.size(); ++f) {
    const int b = L.rig_block(static_cast<int>(f));
    const Eigen::Map<const Pose6> est(r->block(b));
    const Eigen::MatrixXd C = r->Covariance({b});
    for (int i = 0; i < 6; ++i) {
      EXPECT_LT(std::abs(est[i] - truth[f][i]), 5 * std::sqrt(C(i, i)))
          << "frame " << f << " param " << i;
    }
  }
  // The first frame's rig is held: a zero covariance.
  EXPECT_EQ(r->Covariance({L.rig_block(0)}).norm(), 0.0);
  EXPECT_LT(r->rms_object_px, 0.2);
  // A rig with fewer than 4 observations over its views is refused, naming it.
  BaProblem bad = p;
  for (BaView& v : bad.views) {
    if (v.rig == 2) v = KeepObservations(v, {1, 0, 0, 0, 0});
  }
  const Status s = bad.Check();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("rig 'frame 2': 2 observation(s)"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace ba
}  // namespace carmba
