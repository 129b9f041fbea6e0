// Calibration from the simulator's IMAGES against the known truth, per shipped scene: render,
// detect, calibrate (free OPENCV5, the pixel sigma estimated from the residuals, as a user runs
// it); the estimated projection must be within 3 sigma of the true projection over a grid of
// pixels covering the field of view, the image centre and the corners, and the residual RMS must
// be what the detection error (against the truth) predicts.
//
// Two definitions of "the projection" and its sigma:
//  - asserted: the same camera-frame ray through the estimated and the true intrinsics, sigma from
//    the intrinsics' covariance marginal over the plate poses (dominated by the principal point,
//    ~1-3 px). Calibrated on ideal observations (second test: never over 3 sigma in 100 seeds).
//  - printed: mrcal's (a point fixed in the frame averaged over the plate poses, compared through
//    the TRUE poses; sigma 0.001-0.01 px). On ideal observations its worst grid point exceeds 3
//    sigma in 7-8 of 100 seeds (largest 3.6-3.9: a maximum over 162 correlated comparisons). From
//    the images: thesis 2.3 sigma, pincushion 3.0 sigma - at this precision the detector's
//    ~0.004 px systematic error is no longer negligible.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>

#include "calib/calibrate.h"
#include "calib/projection_uncertainty.h"
#include "synthetic/synthetic_views.h"
#include "camera/camera_model.h"
#include "detect/grid_detector.h"
#include "scene_test_util.h"

namespace carmba {
namespace {

constexpr double kNumSigmas = 3.0;  // the bound, per coordinate
// Residual RMS vs the detection error: 1000-2000 residuals give the RMS to ~2-3 %; the detection
// error's small systematic part (~0.004 px RMS, partly absorbed by the model) adds a little.
constexpr double kRmsRelTol = 0.15;

struct Detected {
  ObservationSet obs;
  double error_rms_px = 0;  // per coordinate, detections vs the true projected centres
};

Detected RenderAndDetect(const sim::XrayScene& scene) {
  Detected d;
  d.obs.grid = SceneGrid(scene);
  d.obs.width = scene.camera.width;
  d.obs.height = scene.camera.height;
  auto grid = sim::RayGrid::Build(scene.camera, scene.render);
  EXPECT_TRUE(grid.ok());
  double sum2 = 0;
  int n = 0;
  for (int i = 0; i < static_cast<int>(scene.views.size()); ++i) {
    auto v = sim::RenderXrayView(scene, i, grid->get());
    EXPECT_TRUE(v.ok());
    GridDetection det = DetectGrid(v->image, d.obs.grid, DetectionOptions());
    EXPECT_TRUE(det.found) << scene.views[i].name << ": " << det.reason;
    if (!det.found) continue;
    det.view.image = scene.views[i].name;
    // Ids of the physical spheres (the nearest true centre), so that the estimated plate frame is
    // the simulator's (the detector's ordering may be a symmetry of the grid).
    for (size_t j = 0; j < det.view.uv_px.size(); ++j) {
      double best = 1e300;
      for (size_t k = 0; k < v->centers_px.size(); ++k) {
        const double d2 = (det.view.uv_px[j] - v->centers_px[k]).squaredNorm();
        if (d2 < best) best = d2, det.view.point_ids[j] = static_cast<int>(k);
      }
      sum2 += best;
      ++n;
    }
    d.obs.views.push_back(det.view);
  }
  d.error_rms_px = std::sqrt(sum2 / (2.0 * n));
  return d;
}

// Largest |estimate - truth| / sigma (per coordinate) of the projection of the true ray of each
// pixel in `pixels`; sigma from the intrinsics' covariance (marginal over the plate poses).
double WorstSigmas(const CalibrationResult& r, const Camera& truth,
                   const std::vector<Eigen::Vector2d>& pixels, std::string* where) {
  double worst = 0;
  for (const auto& q : pixels) {
    double xy[2];
    EXPECT_TRUE(UnprojectToNormalized(truth.params.data(), q.data(), xy));
    const double p[3] = {xy[0], xy[1], 1.0};
    double uv[2], J[2 * kNumIntrinsics];
    EXPECT_TRUE(ProjectCamPointWithJac(r.camera.params.data(), p, uv, J, nullptr));
    const Eigen::Map<const Eigen::Matrix<double, 2, kNumIntrinsics, Eigen::RowMajor>> Jm(J);
    const Eigen::Matrix2d C = Jm * r.covariance * Jm.transpose();
    for (int c = 0; c < 2; ++c) {
      const double n_sigma = std::abs(uv[c] - q[c]) / std::sqrt(C(c, c));
      if (n_sigma > worst) {
        worst = n_sigma;
        *where = "pixel (" + std::to_string(q.x()) + ", " + std::to_string(q.y()) + ") " +
                 (c ? "v" : "u") + ": error " + std::to_string(uv[c] - q[c]) + " px, sigma " +
                 std::to_string(std::sqrt(C(c, c))) + " px";
      }
    }
  }
  return worst;
}

// mrcal's definition of the projection and its uncertainty (calib/calibrate.h): the point at
// `distance_mm` along pixel q's ray, fixed in the frame averaged over the plate poses. Its true
// projection: map it into every plate frame with the estimated poses, back into the camera with
// the TRUE poses, average, project with the true intrinsics. Largest |q - q_true| / sigma per
// coordinate, sigma from ProjectionUncertainty. Needs the observations' ids to be the simulator's
// sphere order and view i = scene view i.
double WorstSigmasMrcalDefinition(const ObservationSet& obs, const CalibrationResult& r,
                                  const sim::XrayScene& scene,
                                  const std::vector<Eigen::Vector2d>& pixels, std::string* where) {
  double worst = 0;
  const double distance = r.uncertainty_distance_mm;
  for (const auto& q : pixels) {
    double xy[2];
    EXPECT_TRUE(UnprojectToNormalized(r.camera.params.data(), q.data(), xy));
    const Eigen::Vector3d p_cam = distance * Eigen::Vector3d(xy[0], xy[1], 1.0).normalized();
    Eigen::Vector3d p_true = Eigen::Vector3d::Zero();
    for (size_t i = 0; i < obs.views.size(); ++i) {
      const auto& pose = r.cam_from_plate[i];
      const Rigid3 cam_from_plate_est =
          Rigid3::FromRvec({pose[0], pose[1], pose[2]}, {pose[3], pose[4], pose[5]});
      p_true += scene.CamFromObject(static_cast<int>(i)) * (cam_from_plate_est.Inverse() * p_cam);
    }
    p_true /= static_cast<double>(obs.views.size());
    double q_true[2];
    EXPECT_TRUE(ProjectCamPoint(scene.camera.params.data(), p_true.data(), q_true));
    auto s = ProjectionUncertainty(obs, r, q.x(), q.y(), distance);
    EXPECT_TRUE(s.ok());
    const double sig[2] = {s->sigma_u_px, s->sigma_v_px};
    for (int c = 0; c < 2; ++c) {
      const double n_sigma = std::abs(q[c] - q_true[c]) / sig[c];
      if (n_sigma > worst) {
        worst = n_sigma;
        *where = "pixel (" + std::to_string(q.x()) + ", " + std::to_string(q.y()) + ") " +
                 (c ? "v" : "u") + ": error " + std::to_string(q[c] - q_true[c]) + " px, sigma " +
                 std::to_string(sig[c]) + " px";
      }
    }
  }
  return worst;
}

TEST(SceneAccuracy, ProjectionWithinThreeSigmaOfTheTruthFromImages) {
  for (const std::string name : {"thesis_calibration", "calib_7x6_pincushion"}) {
    const sim::XrayScene scene = LoadShippedScene(name);
    const Detected d = RenderAndDetect(scene);
    ASSERT_EQ(d.obs.views.size(), scene.views.size()) << name;
    auto r = Calibrate(d.obs, CalibrationOptions());
    ASSERT_TRUE(r.ok()) << r.status().message();
    const int w = scene.camera.width, h = scene.camera.height;
    // A 9 x 9 grid over the fully exposed field of view, plus its centre and the image corners
    // (outside the circular field: extrapolated, with correspondingly large sigmas).
    const double fu =
        scene.render.fov_center_u_px >= 0 ? scene.render.fov_center_u_px : 0.5 * (w - 1);
    const double fv =
        scene.render.fov_center_v_px >= 0 ? scene.render.fov_center_v_px : 0.5 * (h - 1);
    const double fr =
        (scene.render.fov_radius_px > 0 ? scene.render.fov_radius_px : 0.5 * std::min(w, h)) -
        scene.render.fov_edge_px;
    std::vector<Eigen::Vector2d> field,
        corners = {{0, 0}, {w - 1.0, 0}, {0, h - 1.0}, {w - 1.0, h - 1.0}};
    for (int i = 0; i < 9; ++i) {
      for (int j = 0; j < 9; ++j) {
        const Eigen::Vector2d q(fu + fr * (i - 4) / 4.0, fv + fr * (j - 4) / 4.0);
        if (std::hypot(q.x() - fu, q.y() - fv) <= fr) field.push_back(q);
      }
    }
    std::string where_field, where_corner;
    const double worst_field = WorstSigmas(*r, scene.camera, field, &where_field);
    const double worst_corner = WorstSigmas(*r, scene.camera, corners, &where_corner);
    std::string where_mrcal;
    const double worst_mrcal = WorstSigmasMrcalDefinition(d.obs, *r, scene, field, &where_mrcal);
    std::cout << name << " mrcal definition: worst over the field " << worst_mrcal << " sigma ("
              << where_mrcal << ")\n";
    const double expected_rms = d.error_rms_px * std::sqrt(double(r->dof) / (2.0 * r->num_points));
    std::cout << name << ": detection error " << d.error_rms_px << " px RMS; calibration RMS "
              << r->rms_px << " px (expected " << expected_rms << ")\n  worst over the field "
              << worst_field << " sigma (" << where_field << ")\n  worst at the corners "
              << worst_corner << " sigma (" << where_corner << ")\n";
    for (int i = 0; i < 4; ++i) {
      std::cout << "  " << kIntrinsicNames[i] << " - truth = "
                << r->camera.params[i] - scene.camera.params[i] << " px = "
                << (r->camera.params[i] - scene.camera.params[i]) / r->sigma[i] << " sigma\n";
    }
    EXPECT_LT(worst_field, kNumSigmas) << name << ": " << where_field;
    EXPECT_LT(worst_corner, kNumSigmas) << name << ": " << where_corner;
    EXPECT_NEAR(r->rms_px / expected_rms, 1.0, kRmsRelTol) << name;
  }
}

TEST(SceneAccuracy, TheThreeSigmaCheckIsCalibratedOnIdealObservations) {
  // The check above, on the true projected centres plus white Gaussian noise (what a perfect
  // detector would give), over 100 seeds: the worst |error| / sigma over the field's 9 x 9 grid
  // (strongly correlated points, mostly one principal-point offset) must exceed 3 rarely. This
  // shows the check's sigma is neither too small (it would fail often here) nor so large that
  // the image test above is vacuous (that test fails with the previous detector: 5.9 sigma).
  constexpr int kSeeds = 100;
  constexpr double kNoisePx = 0.03;
  constexpr double kMaxFractionOver3 = 0.10;  // a 2-D 3-sigma check over a grid: a few % expected
  for (const std::string name : {"thesis_calibration", "calib_7x6_pincushion"}) {
    const sim::XrayScene scene = LoadShippedScene(name);
    const ObservationSet clean = SceneTruthObservations(scene);
    const int w = scene.camera.width, h = scene.camera.height;
    std::vector<Eigen::Vector2d> field;
    for (int i = 0; i < 9; ++i) {
      for (int j = 0; j < 9; ++j) {
        const Eigen::Vector2d q(0.5 * (w - 1) + 0.4 * w * (i - 4) / 4.0,
                                0.5 * (h - 1) + 0.4 * h * (j - 4) / 4.0);
        if ((q - Eigen::Vector2d(0.5 * (w - 1), 0.5 * (h - 1))).norm() <= 0.4 * w)
          field.push_back(q);
      }
    }
    int over = 0, over_m = 0;
    double worst_all = 0, worst_m_all = 0;
    for (int seed = 0; seed < kSeeds; ++seed) {
      auto r = Calibrate(AddNoise(clean, kNoisePx, 9000 + seed), CalibrationOptions());
      ASSERT_TRUE(r.ok()) << r.status().message();
      std::string where;
      const double worst = WorstSigmas(*r, scene.camera, field, &where);
      const double worst_m = WorstSigmasMrcalDefinition(clean, *r, scene, field, &where);
      over_m += worst_m > kNumSigmas;
      worst_m_all = std::max(worst_m_all, worst_m);
      over += worst > kNumSigmas;
      worst_all = std::max(worst_all, worst);
    }
    std::cout << name << ": ideal observations, worst over the field > 3 sigma in " << over
              << " of " << kSeeds << " seeds (largest " << worst_all << "); mrcal definition: "
              << over_m << " (largest " << worst_m_all << ")\n";
    EXPECT_LE(over, kMaxFractionOver3 * kSeeds) << name;
  }
}

}  // namespace
}  // namespace carmba
