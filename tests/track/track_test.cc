// carmba track (track/track.h): the calibration text, frame pairing, and the pipeline after
// detection on synthetic beads seen by the wrist data's two real cameras (two rigid bodies moving
// between three frames, spurious blobs, pixel noise): every bead found with its id in every frame,
// the bodies separated, and the beads' lab positions within their covariances (NEES, seeded
// Monte Carlo). The real wrist radiographs end to end are in tests/cli/track_cli_test.cc.
#include "track/track.h"

#include <ceres/rotation.h>
#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <random>

#include "camera/camera.h"
#include "figures.h"
#include "geometry/random_vector.h"
#include "scratch.h"

namespace carmba {
namespace {

std::string Calib(int cam) {
  return std::string(CARMBA_SOURCE_DIR) +
         "/data/real/autoscoper-wrist/calibration/xr_calib_wrist_cam0" + std::to_string(cam) +
         ".txt";
}

std::vector<TrackCamera> WristCameras() {
  std::vector<TrackCamera> cams;
  for (int c : {1, 2}) {
    auto cam = ReadXmaCalibration(Calib(c), "cam0" + std::to_string(c));
    EXPECT_TRUE(cam.ok()) << cam.status().message();
    cams.push_back(*cam);
  }
  return cams;
}

TEST(TrackInputs, ReadsTheXmaCalibrationOfTheWristData) {
  const auto cams = WristCameras();
  EXPECT_EQ(cams[0].width, 1760);
  EXPECT_DOUBLE_EQ(cams[0].intrinsics[kFx], 6167.35342293);
  EXPECT_DOUBLE_EQ(cams[1].intrinsics[kCy], 894.238444813);
  // x_cam = R x_lab + t: the source is at -R^T t, about 0.9 and 1.15 m from the lab origin.
  EXPECT_NEAR(cams[0].CentreInLab().norm(), 905.7, 1.0);
  EXPECT_NEAR(cams[1].CentreInLab().norm(), 1163.0, 3.0);
}

TEST(TrackInputs, BadCalibrationTextNamesTheLine) {
  test::ScratchDir dir("track_inputs");
  const std::string good =
      "image size\n1760,1760\n\ncamera matrix\n6000,0,800\n0,6000,900\n0,0,1\n\n"
      "rotation\n1,0,0\n0,1,0\n0,0,1\n\ntranslation\n0\n0\n900\n";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"image size\n1760\n", ":2: expected 2 number(s) in section 'image size'"},
      {"camera matrix\n6000,0,800\n0,6000,nan\n0,0,1\n", ":3: expected 3 number(s)"},
      {"focal\n1\n", ":1: unknown section 'focal'"},
      {"image size\n1760,1760\n", "section 'camera matrix' is missing"},
      {"image size\n1760,1760\ncamera matrix\n6000,0,800\n0,6000,900\n0,0,1\n"
       "rotation\n1,0,0\n0,1,0\n0,0,2\n"
       "translation\n0\n0\n900\n",
       "rotation is not a rotation matrix"},
      {"image size\n1760,1760\ncamera matrix\n6000,0,800\n0,6000,900\n0,0,1\n"
       "rotation\n1,0,0\n0,1,0\n0,0,1\n"
       "translation\n0\n0\n0.9\n",
       "translation in metres?"},
  };
  {
    std::ofstream(dir.File("good.txt")) << good;
    EXPECT_TRUE(ReadXmaCalibration(dir.File("good.txt"), "c").ok());
  }
  for (const auto& [text, expected] : cases) {
    std::ofstream(dir.File("bad.txt")) << text;
    auto cam = ReadXmaCalibration(dir.File("bad.txt"), "c");
    ASSERT_FALSE(cam.ok()) << text;
    EXPECT_NE(cam.status().message().find(expected), std::string::npos) << cam.status().message();
  }
  EXPECT_FALSE(ReadXmaCalibration(dir.File("missing.txt"), "c").ok());
}

TEST(TrackInputs, CameraJsonAndPoseGiveTheSameCamera) {
  test::ScratchDir dir("track_camera_json");
  const TrackCamera xma = WristCameras()[0];
  Camera cam;
  cam.width = xma.width;
  cam.height = xma.height;
  cam.params = xma.intrinsics;
  dir.Write("camera.json", CameraToJson(cam).dump(2));
  dir.Write("pose.json",
            "{\"cam_from_lab\": {\"rvec\": [" + std::to_string(xma.cam_from_lab[0]) + ", " +
                std::to_string(xma.cam_from_lab[1]) + ", " + std::to_string(xma.cam_from_lab[2]) +
                "], \"t_mm\": [" + std::to_string(xma.cam_from_lab[3]) + ", " +
                std::to_string(xma.cam_from_lab[4]) + ", " + std::to_string(xma.cam_from_lab[5]) +
                "]}}");
  auto c = ReadTrackCamera("cam01", dir.File("camera.json") + "+" + dir.File("pose.json"));
  ASSERT_TRUE(c.ok()) << c.status().message();
  EXPECT_EQ(c->width, 1760);
  EXPECT_NEAR((c->CentreInLab() - xma.CentreInLab()).norm(), 0, 1e-3);
  EXPECT_DOUBLE_EQ(c->intrinsics[kFx], xma.intrinsics[kFx]);
  // Bad pose files name the key.
  dir.Write("bad.json", "{\"cam_from_lab\": {\"rvec\": [1, 2], \"t_mm\": [0, 0, 900]}}");
  auto bad = ReadTrackCamera("cam01", dir.File("camera.json") + "+" + dir.File("bad.json"));
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("key 'cam_from_lab'"), std::string::npos)
      << bad.status().message();
  dir.Write("deg.json", "{\"cam_from_lab\": {\"rvec\": [0, 90, 0], \"t_mm\": [0, 0, 900]}}");
  bad = ReadTrackCamera("cam01", dir.File("camera.json") + "+" + dir.File("deg.json"));
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("degrees given?"), std::string::npos)
      << bad.status().message();
}

TEST(TrackInputs, FramesPairByTheNumberInTheFileName) {
  EXPECT_EQ(*FrameNumberOfFile("/a/xr_rad_uln_cam01_UND.0099.tif"), 99);
  EXPECT_EQ(*FrameNumberOfFile("cam2_frame_12.png"), 12);
  EXPECT_FALSE(FrameNumberOfFile("/a/b/image.png").ok());
  std::vector<std::string> unpaired;
  auto frames = PairFrames(
      {{"a.0002.tif", "a.0099.tif", "a.0007.tif"}, {"b.0099.tif", "b.0002.tif"}}, &unpaired);
  ASSERT_TRUE(frames.ok());
  ASSERT_EQ(frames->size(), 2u);
  EXPECT_EQ((*frames)[0].number, 2);
  EXPECT_EQ((*frames)[1].image_per_camera[1], "b.0099.tif");
  EXPECT_EQ(unpaired, std::vector<std::string>{"a.0007.tif"});
  EXPECT_FALSE(PairFrames({{"a.1.tif", "x.001.tif"}, {"b.1.tif"}}, nullptr).ok());  // frame 1 twice
  EXPECT_FALSE(PairFrames({{"a.1.tif"}, {"b.2.tif"}}, nullptr).ok());
}

struct Scene {
  std::vector<TrackFrame> frames;
  std::vector<TrackImage> images;
  std::vector<std::vector<Eigen::Vector3d>> truth;  // per frame, per bead (lab)
  std::vector<int> body_of;                          // per bead
};

Eigen::Matrix3d Rot(const Pose6& p) {
  Eigen::Matrix3d R;
  ceres::AngleAxisToRotationMatrix(p.data(), ceres::ColumnMajorAdapter3x3(R.data()));
  return R;
}

// Two bodies of 5 and 6 beads near the cameras' common field, moved between three frames; each
// image gets the beads' projections with noise `sigma_px` (stated exactly) and 3 spurious blobs.
Scene MakeScene(const std::vector<TrackCamera>& cams, std::mt19937* rng, double sigma_px) {
  std::normal_distribution<double> n01(0, 1);
  std::uniform_real_distribution<double> u(-1, 1);
  Scene s;
  // The lab point both cameras look at (near the origin for the wrist cameras).
  const Eigen::Vector3d centre(0, 0, 0);
  std::vector<Eigen::Vector3d> beads;
  for (int b = 0; b < 2; ++b) {
    const Eigen::Vector2d yz = 5 * RandomVector<2>(u, *rng);
    const Eigen::Vector3d body_centre = centre + Eigen::Vector3d(b ? 15 : -15, yz[0], yz[1]);
    for (int i = 0; i < 5 + b; ++i) {
      beads.push_back(body_centre + 8 * RandomVector<3>(u, *rng));
      s.body_of.push_back(b);
    }
  }
  for (int f = 0; f < 3; ++f) {
    TrackFrame frame;
    frame.number = 10 * f + 1;
    frame.image_per_camera = {"c1", "c2"};
    s.frames.push_back(frame);
    std::vector<Pose6> motion(2, Pose6::Zero());
    if (f > 0) {
      for (auto& m : motion)
        m << 0.15 * u(*rng), 0.15 * u(*rng), 0.15 * u(*rng), 6 * u(*rng), 6 * u(*rng), 6 * u(*rng);
    }
    std::vector<Eigen::Vector3d> lab;
    for (size_t i = 0; i < beads.size(); ++i) {
      const Pose6& m = motion[s.body_of[i]];
      lab.push_back(Rot(m) * (beads[i] - centre) + centre + m.tail<3>());
    }
    s.truth.push_back(lab);
    for (size_t c = 0; c < cams.size(); ++c) {
      TrackImage im;
      im.frame = f;
      im.camera = static_cast<int>(c);
      im.detection.ok = true;
      for (const Eigen::Vector3d& p : lab) {
        const Eigen::Vector3d pc = Rot(cams[c].cam_from_lab) * p + cams[c].cam_from_lab.tail<3>();
        double uv[2] = {0, 0};
        EXPECT_TRUE(ProjectCamPoint(cams[c].intrinsics.data(), pc.data(), uv));
        MarkerBlob b;
        const Eigen::Vector2d noise = sigma_px * RandomVector<2>(n01, *rng);
        b.uv_px = cv::Point2d(uv[0] + noise[0], uv[1] + noise[1]);
        b.covariance_px2 = cv::Matx22d(sigma_px * sigma_px, 0, 0, sigma_px * sigma_px);
        b.diameter_px = 6;
        im.detection.blobs.push_back(b);
      }
      for (int k = 0; k < 3; ++k) {
        MarkerBlob b;
        const Eigen::Vector2d where = RandomVector<2>(u, *rng);
      b.uv_px = cv::Point2d(880 + 300 * where[0], 880 + 300 * where[1]);
        b.covariance_px2 = cv::Matx22d(sigma_px * sigma_px, 0, 0, sigma_px * sigma_px);
        im.detection.blobs.push_back(b);
      }
      s.images.push_back(im);
    }
  }
  return s;
}

// The tracked bead nearest to each true bead in the first frame: -1 if none within 0.5 mm.
std::vector<int> MatchTruth(const TrackResult& r, const Scene& s) {
  std::vector<int> out;
  for (const Eigen::Vector3d& t : s.truth[0]) {
    int best = -1;
    double best_d = 0.5;
    for (size_t b = 0; b < r.beads.size(); ++b) {
      const double d = (r.bead_lab[0][b] - t).norm();
      if (r.bead_num_views[0][b] > 0 && d < best_d) best_d = d, best = static_cast<int>(b);
    }
    out.push_back(best);
  }
  return out;
}

TEST(Track, SyntheticBeadsAreIdentifiedInEveryFrameAndTheirCovariancesHold) {
  const auto cams = WristCameras();
  const unsigned seed = getenv("CARMBA_TRACK_SEED") ? std::atoi(getenv("CARMBA_TRACK_SEED")) : 22;
  const int trials = getenv("CARMBA_TRACK_TRIALS") ? std::atoi(getenv("CARMBA_TRACK_TRIALS")) : 40;
  std::mt19937 rng(seed);
  TrackOptions options;
  double nees_sum = 0;
  int nees_n = 0, found = 0, total = 0, wrong = 0, failed = 0;
  for (int trial = 0; trial < trials; ++trial) {
    const Scene s = MakeScene(cams, &rng, 0.08);
    auto r = TrackDetections(cams, s.frames, s.images, options);
    if (!r.ok()) {
      ++failed;
      total += static_cast<int>(s.truth[0].size() * s.frames.size());
      continue;
    }
    const std::vector<int> id = MatchTruth(*r, s);
    for (size_t i = 0; i < id.size(); ++i) {
      for (size_t f = 0; f < s.frames.size(); ++f) {
        ++total;
        if (id[i] < 0 || r->bead_num_views[f][id[i]] < 2) continue;
        const Eigen::Vector3d e = r->bead_lab[f][id[i]] - s.truth[f][i];
        if (e.norm() > 0.5) {  // the id of another bead, or a ghost
          ++wrong;
          continue;
        }
        ++found;
        nees_sum += e.dot(r->bead_lab_covariance[f][id[i]].ldlt().solve(e));
        nees_n += 3;
      }
    }
  }
  const double nees = nees_sum / std::max(1, nees_n);
  std::printf(
      "track synthetic (seed %u): %d trials (%d failed), %d of %d bead-frames tracked (%.1f %%), "
      "%d wrong, bead NEES per dof %.3f\n",
      seed,
      trials,
      failed,
      found,
      total,
      100.0 * found / total,
      wrong,
      nees);
  testing::RecordFigure("tracksyn.result",
                        "seed %u, %d trials: %.1f %% of bead-frames tracked, %d of %d wrong, bead "
                        "NEES per dof %.3f",
                        seed,
                        trials,
                        100.0 * found / total,
                        wrong,
                        total,
                        nees);
  // The misses and wrong ones are beads whose images overlap within a few px in
  // one camera (ghost pairings; a real detector would merge them): issue 22's "no wrong match"
  // does not hold there.
  EXPECT_LE(wrong, 0.005 * total);
  EXPECT_GE(found, 0.97 * total);
  // The lab positions of one body's beads share its pose: correlated, but each one's NEES is
  // chi-square with 3 dof.
  EXPECT_GT(nees, 0.75);
  EXPECT_LT(nees, 1.3);
}

TEST(Track, ABeadMissedByOneCameraJoinsWithItsSinglePixel) {
  const auto cams = WristCameras();
  std::mt19937 rng(31);
  Scene s = MakeScene(cams, &rng, 0.08);
  // Bead 0 is not detected by the second camera in the last frame (image 2 * 2 + 1).
  s.images[5].detection.blobs.erase(s.images[5].detection.blobs.begin());
  auto r = TrackDetections(cams, s.frames, s.images, TrackOptions());
  ASSERT_TRUE(r.ok()) << r.status().message();
  const std::vector<int> id = MatchTruth(*r, s);
  ASSERT_GE(id[0], 0);
  EXPECT_EQ(r->bead_num_views[2][id[0]], 1);
  // Its position in that frame from the body's pose, within its covariance's reach.
  const Eigen::Vector3d e = r->bead_lab[2][id[0]] - s.truth[2][0];
  EXPECT_LT(e.dot(r->bead_lab_covariance[2][id[0]].ldlt().solve(e)),
            16.3);  // chi-square 3 dof, 0.1 %
  // The distance checks leave it out in that frame.
  for (const BodyDistance& d : r->distances) {
    if (d.bead_a == r->beads[id[0]].id || d.bead_b == r->beads[id[0]].id) {
      EXPECT_FALSE(std::isfinite(d.distance_mm[2]));
    }
  }
}

TEST(Track, CamerasWithACovarianceAreFreeWithinIt) {
  auto cams = WristCameras();
  std::mt19937 rng(41);
  const Scene s = MakeScene(cams, &rng, 0.08);
  auto held = TrackDetections(cams, s.frames, s.images, TrackOptions());
  ASSERT_TRUE(held.ok()) << held.status().message();
  for (TrackCamera& c : cams) {
    c.covariance_indices = {kFx, kFy, kCx, kCy};
    c.covariance = Eigen::Vector4d(400, 400, 100, 100).asDiagonal();  // sigma 20, 20, 10, 10 px
  }
  auto free = TrackDetections(cams, s.frames, s.images, TrackOptions());
  ASSERT_TRUE(free.ok()) << free.status().message();
  ASSERT_EQ(free->beads.size(), held->beads.size());
  // The lab positions carry the calibration's uncertainty (the two sources' depth scale is free
  // within the focal lengths' sigmas): a larger covariance, and the truth within it.
  double trace_held = 0, trace_free = 0;
  const std::vector<int> id = MatchTruth(*held, s);
  for (size_t i = 0; i < id.size(); ++i) {
    ASSERT_GE(id[i], 0);
    trace_held += held->bead_lab_covariance[1][id[i]].trace();
    trace_free += free->bead_lab_covariance[1][id[i]].trace();
    const Eigen::Vector3d e = free->bead_lab[1][id[i]] - s.truth[1][i];
    EXPECT_LT(e.dot(free->bead_lab_covariance[1][id[i]].ldlt().solve(e)),
              16.3);  // chi-square 3 dof, 0.1 %
  }
  EXPECT_GT(trace_free, 1.5 * trace_held);
}

TEST(Track, BadOptionsAndTooFewBeadsAreErrors) {
  const auto cams = WristCameras();
  TrackOptions o;
  o.marker_diameter_mm = 1e-4;
  std::string error;
  EXPECT_FALSE(o.Check(&error));
  EXPECT_NE(error.find("marker_diameter_mm"), std::string::npos);
  std::mt19937 rng(3);
  Scene s = MakeScene(cams, &rng, 0.08);
  for (TrackImage& im : s.images) im.detection.blobs.resize(2);
  auto r = TrackDetections(cams, s.frames, s.images, TrackOptions());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("no rigid body"), std::string::npos) << r.status().message();
}

}  // namespace
}  // namespace carmba
