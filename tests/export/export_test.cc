// Geometry export: projection matrices, geometry.json, RTK's ThreeDCircularGeometry (golden
// vector and round trip), plastimatch's projection-matrix files (round trip and against
// plastimatch's own writer), undistortion.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>

#include "export/plastimatch_geometry.h"
#include "export/rtk_geometry.h"
#include "export/undistort.h"
#include "export/view_geometry.h"
#include "figures.h"
#include "geometry/random_vector.h"
#include "geometry/rotation.h"
#include "scratch.h"
#include "util/file_util.h"

namespace carmba {
namespace {

// Round trips through files written with 17 significant digits: the matrices agree to rounding.
constexpr double kRoundTripTol = 1e-9;

// `name` in this process's scratch directory (removed at exit).
std::string TempPath(const std::string& name) {
  static const test::ScratchDir dir("export");
  return dir.File(name);
}

void WriteText(const std::string& path, const std::string& text) { std::ofstream(path) << text; }

Camera ThesisCamera() {
  Camera c;
  c.width = 408;
  c.height = 408;
  c.params = {2061.389, 2254.646, 203.655, 205.117, -2.5, 0, 0, 0, 0};
  return c;
}


// Random C-arm-like views around an isocentre far from the CT origin.
GeometrySet RandomViews(uint64_t seed, int n, const Camera& cam) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(-1, 1);
  GeometrySet set;
  const Eigen::Vector3d iso(20, -110, -590);  // like the thesis CT's marker positions
  for (int k = 0; k < n; ++k) {
    const Eigen::Vector3d dir = RandomVector<3>(U, rng).normalized();
    const double distance = 600 + 200 * std::abs(U(rng));
    const Eigen::Vector3d src = iso + dir * distance + RandomVector<3>(U, rng) * 30;
    const Eigen::Vector3d target = iso + 20 * RandomVector<3>(U, rng);
    const double roll_deg = 3 * U(rng);
    set.views.push_back(ViewLookingAt("v" + std::to_string(k), cam, src, target, roll_deg));
  }
  set.reference_point_ct_mm = iso;
  return set;
}

// P = K [R | t]  ->  K, R, t (RQ decomposition; K with a positive diagonal).
ViewGeometry DecomposeP(const Matrix34& P, int width, int height) {
  const Eigen::Matrix3d M = P.leftCols<3>();
  Eigen::Matrix3d J = Eigen::Matrix3d::Zero();
  J(0, 2) = J(1, 1) = J(2, 0) = 1;
  Eigen::HouseholderQR<Eigen::Matrix3d> qr((J * M).transpose());
  Eigen::Matrix3d Q = qr.householderQ();
  Eigen::Matrix3d U = qr.matrixQR().triangularView<Eigen::Upper>();
  Eigen::Matrix3d K = J * U.transpose() * J, R = J * Q.transpose();
  const Eigen::Matrix3d S = K.diagonal().cwiseSign().asDiagonal();
  K = K * S;
  R = S * R;
  const double scale = K(2, 2);
  K /= scale;
  ViewGeometry v;
  v.camera.width = width;
  v.camera.height = height;
  v.camera.params = {K(0, 0), K(1, 1), K(0, 2), K(1, 2), 0, 0, 0, 0, 0};
  const Eigen::Vector3d t = K.inverse() * P.col(3) / scale;
  if (R.determinant() < 0) ADD_FAILURE() << "improper rotation";
  const Eigen::AngleAxisd aa(R);
  v.cam_from_ct.head<3>() = aa.angle() * aa.axis();
  v.cam_from_ct.tail<3>() = t;
  return v;
}

// RTK's Geometry.md example (SID 1000, SDD 1536, gantry 271.847274780273, projection offsets
// -117.056503295898, -1.01195001602173), its matrix recomputed with RTK's formula (the note
// ../shared/notes/geometry-formats.md).
RtkProjection GoldenParams() {
  RtkProjection p;
  p.sid_mm = 1000;
  p.sdd_mm = 1536;
  p.gantry_deg = 271.847274780273;
  p.projection_offset_x_mm = -117.056503295898;
  p.projection_offset_y_mm = -1.01195001602173;
  return p;
}
Matrix34 GoldenMatrix() {
  Matrix34 m;
  m << -166.509307882887, 0, -1531.42837748039, -117056.503295898,  //
      -1.01142410874151, -1536, 0.0326206557691505, -1011.95001602173,  //
      -0.999480303105996, 0, 0.0322354417240802, -1000;
  return m;
}

TEST(RtkGeometry, GoldenVectorFromParameters) {
  // The golden entries are printed with 15 significant digits (up to 1.2e5): 1e-9 relative.
  const Matrix34 m = RtkMatrix(GoldenParams());
  const double abs_err = (m - GoldenMatrix()).cwiseAbs().maxCoeff();
  const double rel_err = RelativeMatrixDifference(m, GoldenMatrix());
  std::printf("RTK golden: max |entry difference| %.3g (largest entry 1.2e5), relative %.3g\n",
              abs_err, rel_err);
  testing::RecordFigure("export.rtk_golden",
                        "%s (largest entry %s; relative %s)",
                        testing::Sci(abs_err).c_str(),
                        testing::Sci(GoldenMatrix().cwiseAbs().maxCoeff()).c_str(),
                        testing::Sci(rel_err).c_str());
  EXPECT_LT(rel_err, 1e-12);
  EXPECT_LT(abs_err, 1e-7);
}

TEST(RtkGeometry, GoldenVectorParametersRecoveredFromACamera) {
  // The golden matrix as a carmba camera (a 1000 x 800 detector of 0.5 x 0.4 mm pixels, so
  // fx != fy), then exported: the published parameters must come back.
  RtkDetector det;
  det.width = 1000;
  det.height = 800;
  det.spacing_u_mm = 0.5;
  det.spacing_v_mm = 0.4;
  const Matrix34 P = PixelMatrixFromRtk(GoldenMatrix(), det);
  GeometrySet set;
  set.views.push_back(DecomposeP(P, det.width, det.height));
  set.views[0].id = "golden";
  EXPECT_LT(RelativeMatrixDifference(ProjectionMatrix(set.views[0]), P), 1e-12);
  RtkDetector out_det;
  auto ps = RtkFromGeometry(set, 1536, &out_det);
  ASSERT_TRUE(ps.ok()) << ps.status().message();
  const RtkProjection& p = (*ps)[0];
  const RtkProjection g = GoldenParams();
  std::printf("recovered: SID %.12g SDD %.12g gantry %.12g out %.3g in %.3g src %.3g %.3g "
              "proj %.12g %.12g\n",
              p.sid_mm, p.sdd_mm, p.gantry_deg, p.out_of_plane_deg, p.in_plane_deg,
              p.source_offset_x_mm, p.source_offset_y_mm, p.projection_offset_x_mm,
              p.projection_offset_y_mm);
  const double recovered =
      std::max({std::abs(p.sid_mm - g.sid_mm),
                std::abs(p.sdd_mm - g.sdd_mm),
                std::abs(p.gantry_deg - g.gantry_deg),
                std::abs(std::remainder(p.out_of_plane_deg, 360.0)),
                std::abs(std::remainder(p.in_plane_deg, 360.0)),
                std::abs(p.source_offset_x_mm),
                std::abs(p.source_offset_y_mm),
                std::abs(p.projection_offset_x_mm - g.projection_offset_x_mm),
                std::abs(p.projection_offset_y_mm - g.projection_offset_y_mm)});
  testing::RecordFigure("export.rtk_recovered", "%s", testing::Sci(recovered).c_str());
  EXPECT_NEAR(p.sid_mm, g.sid_mm, 1e-9);
  EXPECT_NEAR(p.sdd_mm, g.sdd_mm, 1e-9);
  EXPECT_NEAR(p.gantry_deg, g.gantry_deg, 1e-9);
  EXPECT_NEAR(std::remainder(p.out_of_plane_deg, 360.0), 0, 1e-9);
  EXPECT_NEAR(std::remainder(p.in_plane_deg, 360.0), 0, 1e-9);
  EXPECT_NEAR(p.source_offset_x_mm, 0, 1e-9);
  EXPECT_NEAR(p.source_offset_y_mm, 0, 1e-9);
  EXPECT_NEAR(p.projection_offset_x_mm, g.projection_offset_x_mm, 1e-9);
  EXPECT_NEAR(p.projection_offset_y_mm, g.projection_offset_y_mm, 1e-9);
  EXPECT_NEAR(out_det.spacing_u_mm, 0.5, 1e-12);
  EXPECT_NEAR(out_det.spacing_v_mm, 0.4, 1e-12);
  EXPECT_LT(RelativeMatrixDifference(p.matrix, GoldenMatrix()), 1e-12);
}

TEST(RtkGeometry, RoundTripThroughTheXmlFile) {
  Camera cam = ThesisCamera();  // fx != fy: the anisotropy goes into the projection spacing
  const GeometrySet set = RandomViews(11, 40, cam);
  RtkDetector det;
  auto ps = RtkFromGeometry(set, 1000, &det);
  ASSERT_TRUE(ps.ok()) << ps.status().message();
  const std::string path = TempPath("rtk_geometry.xml");
  WriteText(path, RtkGeometryXml(*ps));
  auto back = ReadRtkGeometryXml(path);
  ASSERT_TRUE(back.ok()) << back.status().message();
  ASSERT_EQ(back->size(), set.views.size());
  double worst = 0, worst_px = 0;
  for (size_t k = 0; k < set.views.size(); ++k) {
    const Matrix34 P = ProjectionMatrix(set.views[k]);
    const Matrix34 Q = PixelMatrixFromRtk((*back)[k].matrix, det);
    // The parameters alone (RTK recomputes the matrix from them) give the same matrix too.
    const Matrix34 Qp = PixelMatrixFromRtk(RtkMatrix((*back)[k]), det);
    worst = std::max({worst, RelativeMatrixDifference(P, Q), RelativeMatrixDifference(P, Qp)});
    for (const Eigen::Vector3d& x :
         {Eigen::Vector3d(20, -110, -590), Eigen::Vector3d(60, -80, -560)}) {
      Eigen::Vector2d a, b;
      ASSERT_TRUE(ProjectWithMatrix(P, x, &a));
      ASSERT_TRUE(ProjectWithMatrix(Qp, x, &b));
      worst_px = std::max(worst_px, (a - b).norm());
    }
  }
  std::printf(
      "RTK round trip over %zu views: relative matrix difference %.3g, projections %.3g px\n",
      set.views.size(),
      worst,
      worst_px);
  testing::RecordFigure("export.rtk_round_trip",
                        "%zu random C-arm views with the thesis's fx != fy: "
                        "RTK relative matrix difference %s (projections %s px)",
                        set.views.size(),
                        testing::Sci(worst).c_str(),
                        testing::Sci(worst_px).c_str());
  EXPECT_LT(worst, kRoundTripTol);
  EXPECT_LT(worst_px, 1e-6);
}

TEST(RtkGeometry, RefusesWhatItCannotCarry) {
  GeometrySet set = RandomViews(3, 2, ThesisCamera());
  RtkDetector det;
  GeometrySet mirrored = set;
  mirrored.views[1].ct_mirrored = true;
  auto r = RtkFromGeometry(mirrored, 1000, &det);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("view 'v1': the CT frame is mirrored"), std::string::npos)
      << r.status().message();
  GeometrySet sizes = set;
  sizes.views[1].camera.width = 400;
  r = RtkFromGeometry(sizes, 1000, &det);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("image size 400x408 differs"), std::string::npos)
      << r.status().message();
  GeometrySet aspect = set;
  aspect.views[1].camera.params[kFy] *= 1.001;
  r = RtkFromGeometry(aspect, 1000, &det);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("fx/fy"), std::string::npos) << r.status().message();
  // Different fx with the same fx/fy is carried by a per-view SDD.
  GeometrySet zoom = set;
  zoom.views[1].camera.params[kFx] *= 1.1;
  zoom.views[1].camera.params[kFy] *= 1.1;
  r = RtkFromGeometry(zoom, 1000, &det);
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_NEAR((*r)[1].sdd_mm / (*r)[0].sdd_mm, 1.1, 1e-12);
}

TEST(RtkGeometry, ReaderRefusesInconsistentOrForeignFiles) {
  RtkDetector det;
  auto ps = RtkFromGeometry(RandomViews(5, 1, ThesisCamera()), 1000, &det);
  ASSERT_TRUE(ps.ok());
  const std::string good = RtkGeometryXml(*ps);
  const std::string path = TempPath("bad.xml");
  // A parameter changed without its matrix (0.01 deg moves entries by ~0.2).
  std::string bad = good;
  {
    std::ostringstream o;
    o << (*ps)[0].in_plane_deg + 0.01;
    const size_t s = bad.find("<InPlaneAngle>") + 14, e = bad.find("</InPlaneAngle>");
    bad.replace(s, e - s, o.str());
  }
  WriteText(path, bad);
  auto r = ReadRtkGeometryXml(path);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("projection 1: <Matrix> differs"), std::string::npos)
      << r.status().message();
  std::string v4 = good;
  v4.replace(v4.find("version=\"3\""), 11, "version=\"4\"");
  WriteText(path, v4);
  r = ReadRtkGeometryXml(path);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("version '4': expected 2 or 3"), std::string::npos);
  WriteText(path, "<other/>");
  r = ReadRtkGeometryXml(path);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("expected the element <RTKThreeDCircularGeometry"),
            std::string::npos);
}

TEST(PlastimatchGeometry, RoundTripThroughTheProjectionMatrixFile) {
  const GeometrySet set = RandomViews(21, 40, ThesisCamera());
  auto pms = PlastimatchFromGeometry(set, 1000);
  ASSERT_TRUE(pms.ok()) << pms.status().message();
  double worst = 0;
  for (size_t k = 0; k < set.views.size(); ++k) {
    const std::string path = TempPath("pm.txt");
    WriteText(path, PlastimatchProjMatText((*pms)[k]));
    auto back = ReadPlastimatchProjMat(path);
    ASSERT_TRUE(back.ok()) << back.status().message();
    worst = std::max(worst, RelativeMatrixDifference(PixelMatrixFromPlastimatch(*back),
                                                     ProjectionMatrix(set.views[k])));
    // The isocentre lies on the principal axis at depth sad.
    const Eigen::Vector3d d = (*pms)[k].isocentre_ct_mm - SourceInCt(set.views[k]);
    EXPECT_NEAR(d.norm(), (*pms)[k].sad_mm, 1e-9);
    EXPECT_NEAR(d.normalized().dot(PrincipalAxisInCt(set.views[k])), 1, 1e-12);
  }
  std::printf("plastimatch round trip over %zu views: relative matrix difference %.3g\n",
              set.views.size(), worst);
  testing::RecordFigure("export.plastimatch_round_trip", "%s", testing::Sci(worst).c_str());
  EXPECT_LT(worst, kRoundTripTol);
}

TEST(PlastimatchGeometry, MatchesPlastimatchsOwnWriter) {
  if (std::system("plastimatch --version >/dev/null 2>&1") != 0) {
    GTEST_SKIP() << "plastimatch is not installed (Debian package plastimatch; scripts/setup.sh "
                    "installs it)";
  }
  // plastimatch drr -G writes the projection matrix of the geometry its arguments describe:
  // it must be ours (to its float precision) for non-square, anisotropic, off-centre views.
  Camera cam = ThesisCamera();
  cam.width = 360;
  cam.height = 300;
  cam.params[kCx] = 150.25;
  cam.params[kCy] = 170.5;
  const GeometrySet set = RandomViews(31, 4, cam);
  auto pms = PlastimatchFromGeometry(set, 1100);
  ASSERT_TRUE(pms.ok());
  double worst = 0;
  for (size_t k = 0; k < pms->size(); ++k) {
    const std::string prefix = TempPath("g" + std::to_string(k) + "_");
    const std::string cmd = "plastimatch drr -G -O " + prefix + " " +
                            PlastimatchDrrArgs((*pms)[k]) + " >/dev/null 2>&1";
    ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
    auto theirs = ReadPlastimatchProjMat(prefix + "0000.txt");
    ASSERT_TRUE(theirs.ok()) << theirs.status().message();
    EXPECT_NEAR(theirs->ic[0], (*pms)[k].ic[0], 1e-4);
    EXPECT_NEAR(theirs->ic[1], (*pms)[k].ic[1], 1e-4);
    EXPECT_NEAR(theirs->sad_mm, (*pms)[k].sad_mm, 1e-3);
    EXPECT_LT((theirs->nrm - (*pms)[k].nrm).norm(), 1e-6);
    worst = std::max(worst, RelativeMatrixDifference(PixelMatrixFromPlastimatch(*theirs),
                                                     ProjectionMatrix(set.views[k])));
  }
  std::printf("plastimatch drr -G against carmba's P: relative difference %.3g (float I/O)\n",
              worst);
  testing::RecordFigure("export.plastimatch_writer", "%s", testing::Sci(worst).c_str());
  EXPECT_LT(worst, 1e-6);  // plastimatch parses its arguments into floats (~6e-8 relative)
}

TEST(ViewGeometryJson, RoundTripAndEditedFiles) {
  GeometrySet set = RandomViews(41, 3, ThesisCamera());
  set.views[2].ct_mirrored = true;
  set.views[1].sid_mm = 1100;
  const std::string path = TempPath("geometry.json");
  WriteText(path, GeometryToJson(set).dump(2));
  auto back = ReadGeometryJson(path);
  ASSERT_TRUE(back.ok()) << back.status().message();
  ASSERT_EQ(back->views.size(), 3u);
  for (int k = 0; k < 3; ++k) {
    EXPECT_LT(RelativeMatrixDifference(ProjectionMatrix(back->views[k]),
                                       ProjectionMatrix(set.views[k])),
              1e-15);
  }
  EXPECT_TRUE(back->views[2].ct_mirrored);
  EXPECT_EQ(*back->views[1].sid_mm, 1100);
  // A mirrored view's P projects CT points like its pose projects the mirrored point.
  const Eigen::Vector3d x(25, -100, -580);
  Eigen::Vector2d a;
  ASSERT_TRUE(ProjectWithMatrix(ProjectionMatrix(set.views[2]), x, &a));
  ViewGeometry plain = set.views[2];
  plain.ct_mirrored = false;
  Eigen::Vector2d b;
  ASSERT_TRUE(ProjectWithMatrix(ProjectionMatrix(plain), Eigen::Vector3d(x[0], -x[1], x[2]), &b));
  EXPECT_LT((a - b).norm(), 1e-9);

  auto bad = [&](const std::function<void(nlohmann::json&)>& edit, const std::string& expected) {
    nlohmann::json j = GeometryToJson(set);
    edit(j);
    WriteText(path, j.dump());
    auto r = ReadGeometryJson(path);
    ASSERT_FALSE(r.ok()) << expected;
    EXPECT_NE(r.status().message().find(expected), std::string::npos) << r.status().message();
    EXPECT_EQ(r.status().message().find('\n'), std::string::npos);
  };
  bad([](nlohmann::json& j) { j["views"][1]["P"][0][3] = 1.0; },
      "views[1].P: differs from K [R | t]");
  bad([](nlohmann::json& j) { j["views"][0].erase("cam_from_ct"); }, "views[0].cam_from_ct");
  bad([](nlohmann::json& j) { j["views"][0]["cam_from_ct"]["rvec"][1] = "x"; },
      "views[0].cam_from_ct.rvec[1]: expected a finite number");
  bad([](nlohmann::json& j) { j["views"][2]["camera"]["fx"] = -5; }, "views[2].camera");
  bad([](nlohmann::json& j) { j["format"] = "other"; }, "key 'format'");
  bad([](nlohmann::json& j) { j["views"] = nlohmann::json::array(); }, "key 'views'");
}

TEST(ViewGeometry, IsocentreIsTheAxesIntersection) {
  GeometrySet set = RandomViews(51, 5, ThesisCamera());
  // Views aimed exactly at one point: the least-squares intersection is that point.
  const Eigen::Vector3d iso(10, -120, -600);
  for (size_t k = 0; k < set.views.size(); ++k) {
    set.views[k] =
        ViewLookingAt(set.views[k].id, set.views[k].camera, SourceInCt(set.views[k]), iso, 0.3 * k);
  }
  set.reference_point_ct_mm.reset();
  auto c = GeometryIsocentre(set);
  ASSERT_TRUE(c.ok()) << c.status().message();
  EXPECT_LT((*c - iso).norm(), 1e-9);
  set.views.resize(1);
  EXPECT_FALSE(GeometryIsocentre(set).ok());
}

TEST(Undistort, DotsMoveToThePinholeProjection) {
  // A 16-bit image of Gaussian dots drawn at the DISTORTED projections of a grid of rays; after
  // undistortion each dot's centroid must sit at the rays' pinhole projection.
  Camera cam = ThesisCamera();
  cam.params[kP1] = 1e-3;  // with the thesis's k1 = -2.5: ~6 px at the outer dots
  cv::Mat img(cam.height, cam.width, CV_16UC1, cv::Scalar(1000));
  std::vector<Eigen::Vector2d> pinhole;
  const double sigma = 1.5;
  for (int i = -3; i <= 3; ++i) {
    for (int j = -3; j <= 3; ++j) {
      const double p[3] = {i * 0.028, j * 0.026, 1};
      double uv[2];
      ASSERT_TRUE(ProjectCamPoint(cam.params.data(), p, uv));
      pinhole.emplace_back(cam.params[kFx] * p[0] + cam.params[kCx],
                           cam.params[kFy] * p[1] + cam.params[kCy]);
      for (int v = static_cast<int>(uv[1]) - 8; v <= static_cast<int>(uv[1]) + 8; ++v) {
        for (int u = static_cast<int>(uv[0]) - 8; u <= static_cast<int>(uv[0]) + 8; ++u) {
          if (u < 0 || v < 0 || u >= cam.width || v >= cam.height) continue;
          const double r2 = (u - uv[0]) * (u - uv[0]) + (v - uv[1]) * (v - uv[1]);
          img.at<uint16_t>(v, u) +=
              static_cast<uint16_t>(40000 * std::exp(-r2 / (2 * sigma * sigma)));
        }
      }
    }
  }
  auto out = UndistortImage(img, cam);
  ASSERT_TRUE(out.ok()) << out.status().message();
  ASSERT_EQ(out->type(), CV_16UC1);
  ASSERT_EQ(out->size(), img.size());
  double worst = 0, worst_before = 0;
  for (const auto& q : pinhole) {
    auto centroid = [&](const cv::Mat& m) {
      double s = 0, su = 0, sv = 0;
      for (int v = static_cast<int>(q[1]) - 8; v <= static_cast<int>(q[1]) + 8; ++v) {
        for (int u = static_cast<int>(q[0]) - 8; u <= static_cast<int>(q[0]) + 8; ++u) {
          const double w = std::max(0.0, m.at<uint16_t>(v, u) - 1000.0);
          s += w;
          su += w * u;
          sv += w * v;
        }
      }
      return Eigen::Vector2d(su / s, sv / s);
    };
    worst = std::max(worst, (centroid(*out) - q).norm());
    worst_before = std::max(worst_before, (centroid(img) - q).norm());
  }
  std::printf("undistorted dots: worst centroid offset %.4f px (before undistortion %.2f px)\n",
              worst, worst_before);
  testing::RecordFigure("export.undistort", "%.3f px (up to %.1f px before)", worst, worst_before);
  EXPECT_GT(worst_before, 3.0);  // the distortion is there to remove
  EXPECT_LT(worst, 0.05);        // bilinear resampling of 1.5 px Gaussians
  EXPECT_FALSE(UndistortImage(cv::Mat(10, 10, CV_16UC1), cam).ok());
}

}  // namespace
}  // namespace carmba
