// Marker detection and automatic correspondence on seeded, randomised rendered scenes that no
// shipped file describes (issue 11 on data it was not developed on): per scene a random marker
// layout (6-10 steel spheres of 1.5-3 mm in a 60 x 60 x 40 mm block, >= 12 mm apart), a random
// object orientation, C-arm angles, source-object distance (600-800 mm) and focal length
// (1800-2400 px); two spurious steel beads of the markers' own size and a wire on the object,
// none of them in the CT; the image intensifier's fall-off, heel and glare at random strengths;
// 16-bit 512 x 512 views. Two anatomies: a random crop of a real XA frame (GDCM's example) in PNG
// views, and a real head CT (Debian's invesalius-examples) fixed to the object at a random place
// and orientation, each view attenuated by its DRR (sim/ct_anatomy.h), in DICOM XA files read as
// a user's would be (io/dicom_xray.h).
// Counted as in the clutter scene test (marker_test_util.h): every visible marker that no other
// marker or bead overlaps must be labelled at its true centre (or within its own covariance, which
// the detector widens next to an edge or a wire), no bead may be labelled, and no overlapped
// marker either; a marker within 1.25-1.5 diameters of another or with the wire across it may be
// left out, but if labelled it must be at its centre. By hand: CARMBA_MARKER_RECALL_SCENES=N
// (default 8) scenes, CARMBA_MARKER_RECALL_SEED=S another set, CARMBA_MARKER_RECALL_DUMP=DIR keeps
// each scene's images, scene.yaml and truth.json in DIR/seed_N, CARMBA_MARKER_RECALL_POSITIONER_MM
// and _DEG move the object per view where the DICOM geometry does not say (MakeScene).
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <random>
#include <sstream>

#include "ct/ct_invesalius.h"
#include "detect/marker_views.h"
#include "figures.h"
#include "geometry/random_vector.h"
#include "marker_test_util.h"
#include "scratch.h"
#include "sim/xray_scene.h"
#include "test_env.h"
#include "util/file_util.h"

namespace carmba {
namespace {

// Points uniform in the block, at least `min_sep` mm from each other and from `avoid`.
std::vector<Eigen::Vector3d> RandomPoints(std::mt19937_64& rng, int n, double min_sep,
                                          const std::vector<Eigen::Vector3d>& avoid) {
  std::uniform_real_distribution<double> ux(-30, 30), uz(-20, 20);
  std::vector<Eigen::Vector3d> out;
  for (int tries = 0; static_cast<int>(out.size()) < n && tries < 10000; ++tries) {
    const double z = uz(rng);  // last component first (geometry/random_vector.h)
    const Eigen::Vector2d xy = RandomVector<2>(ux, rng);
    const Eigen::Vector3d p(xy[0], xy[1], z);
    bool ok = true;
    for (const auto& q : out) ok &= (p - q).norm() >= min_sep;
    for (const auto& q : avoid) ok &= (p - q).norm() >= min_sep;
    if (ok) out.push_back(p);
  }
  return out;
}

struct RandomScene {
  std::string yaml;
  double diameter_mm = 2, sod_mm = 700;
};

// The anatomy behind the markers.
enum class Anatomy {
  kXaFrame,  // a random crop of a real XA frame (GDCM's example), 16-bit PNG views
  kRealCt,   // a real head CT fixed to the object (its DRR per view), DICOM XA views
};

const char* kXaFrame = "/usr/share/doc/libgdcm3.0/examples/00191113.dcm";

// The C-arm positioner's error: every view's object moved by up to `mm` per axis and turned by up
// to `deg` per rotation-vector component, which the DICOM angles do not record. By hand:
// CARMBA_MARKER_RECALL_POSITIONER_MM and _DEG (default none).
struct PositionerError {
  double mm = 0, deg = 0;
};
PositionerError PositionerFromEnv() {
  return {testing::EnvOr("CARMBA_MARKER_RECALL_POSITIONER_MM", 0.0),
          testing::EnvOr("CARMBA_MARKER_RECALL_POSITIONER_DEG", 0.0)};
}

// One random scene (YAML text) with its marker CSV written into `dir`. Both anatomies draw the
// same numbers up to the views, so that a seed gives the same markers, beads, wire and views.
// The positioner's error is drawn from a generator of its own: the rest of the scene stays the
// same.
RandomScene MakeScene(uint64_t seed,
                      Anatomy anatomy,
                      const std::string& dir,
                      const PositionerError& positioner = {}) {
  std::mt19937_64 rng(seed);
  auto U = [&](double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng); };
  RandomScene s;
  const int n = std::uniform_int_distribution<int>(6, 10)(rng);
  const auto markers = RandomPoints(rng, n, 12.0, {});
  const auto beads = RandomPoints(rng, 2, 8.0, markers);
  std::ofstream csv(JoinPath(dir, "markers.csv"));
  csv << "id,x_mm,y_mm,z_mm\n";
  for (size_t i = 0; i < markers.size(); ++i) {
    csv << i + 1 << "," << markers[i].x() << "," << markers[i].y() << "," << markers[i].z() << "\n";
  }
  s.diameter_mm = U(1.5, 3.0);
  s.sod_mm = U(600, 800);
  const double f = U(1800, 2400);
  std::ostringstream y;
  y << "kind: xray\nseed: " << seed
    << "\noutput: {format: " << (anatomy == Anatomy::kRealCt ? "dcm" : "png")
    << ", bit_depth: 16}\n"
    << "camera: {image_size: [512, 512], fx: " << f << ", fy: " << f * U(0.98, 1.02)
    << ", cx: 255.5, cy: 255.5, distortion: [" << U(-0.8, 0.3) << ", 0, 0, 0, 0]}\n"
    << "carm: {sid_mm: 1000, sod_mm: " << s.sod_mm << "}\n"
    << "imaging:\n  supersampling: 3\n  white_level: 50000\n  photons_per_pixel: " << U(1500, 4000)
    << "\n  read_noise_gray: 40\n  blur_sigma_px: " << U(0.4, 0.8)
    << "\n  vignetting: " << U(0.1, 0.35) << "\n  heel: {gradient: " << U(0, 0.1)
    << ", direction_deg: " << U(0, 360) << "}\n"
    << "  glare: {fraction: " << U(0, 0.1) << ", sigma_px: " << U(40, 80) << "}\n"
    << "  fov: {circular: true, radius_px: 240, edge_px: 6}\n";
  const double strength = U(0.3, 0.6), crop = U(0.5, 0.8);
  if (anatomy == Anatomy::kXaFrame) {
    y << "  background: {file: " << kXaFrame << ", strength: " << strength << ", crop: " << crop
      << "}\n";
  }
  y << "markers: {csv: markers.csv, id_column: id, columns: [x_mm, y_mm, z_mm], diameter_mm: "
    << s.diameter_mm << ", material: steel}\n"
    << "block: {enabled: true, padding_mm: 5, material: pmma}\n"
    << "clutter:\n  spheres:\n";
  for (const auto& b : beads) {
    y << "    - {center_mm: [" << b.x() << ", " << b.y() << ", " << b.z() << "], diameter_mm: "
      << s.diameter_mm << ", material: steel}\n";
  }
  y << "  wires:\n    - {from_mm: [" << U(-40, -30) << ", " << U(-30, 30) << ", " << U(-20, 20)
    << "], to_mm: [" << U(30, 40) << ", " << U(-30, 30) << ", " << U(-20, 20)
    << "], diameter_mm: 0.5, material: steel}\n";
  const double r0 = U(-180, 180), r1 = U(-60, 60), r2 = U(-180, 180);
  y << "object_pose: {rotation_deg: [" << r0 << ", " << r1 << ", " << r2
    << "], center_mm: [0, 0, 0]}\nviews:\n";
  std::mt19937_64 positioner_rng(seed ^ 0x5eedULL);
  auto E = [&](double a) { return std::uniform_real_distribution<double>(-a, a)(positioner_rng); };
  for (int v = 0; v < 5; ++v) {
    y << "  - {name: v" << v << ", primary_deg: " << U(-45, 45)
      << ", secondary_deg: " << U(-30, 30);
    if (positioner.mm > 0)
      y << ", object_center_mm: [" << E(positioner.mm) << ", " << E(positioner.mm) << ", "
        << E(positioner.mm) << "]";
    if (positioner.deg > 0) {
      y << ", object_rotation_deg: [" << r0 + E(positioner.deg) << ", " << r1 + E(positioner.deg)
        << ", " << r2 + E(positioner.deg) << "]";
    }
    y << "}\n";
  }
  // The head of a real CT about the marker block, placed and turned at random, its water
  // attenuation that of a fluoroscopy spectrum through less or more tissue.
  if (anatomy == Anatomy::kRealCt) {
    y << "anatomy: {ct: " << kInvesaliusCraniumPath << ", center_mm: [" << U(-40, 40) << ", "
      << U(-40, 40) << ", " << U(-40, 40) << "], rotation_deg: [" << U(-180, 180) << ", "
      << U(-180, 180) << ", " << U(-180, 180) << "], mu_water_per_mm: " << U(0.006, 0.015)
      << ", subsample: 3}\n";
  }
  s.yaml = y.str();
  return s;
}

// The set's counts as src/docs/results.md's recall tables state them (scripts/results.py runs
// the sets): "recall.<xa|realct>.set<S>" = "scenes views skipped expected correct wrong beads
// overlap_labelled overlapping off_centre lost" (lost: views skipped with 4 or more markers
// expected), and ".missed" = "why:count;..." over the markers not labelled.
void RecordRecallFigures(
    Anatomy anatomy, uint64_t set, int scenes, int views, int views_skipped, const Tally& t) {
  const std::string key = std::string("recall.") +
                          (anatomy == Anatomy::kXaFrame ? "xa" : "realct") + ".set" +
                          std::to_string(set);
  testing::RecordFigure(key,
                        "%d %d %d %d %d %d %d %d %d %d %d",
                        scenes,
                        views,
                        views_skipped,
                        t.expected,
                        t.correct,
                        t.wrong,
                        t.spurious_labelled,
                        t.overlap_labelled,
                        t.overlapping_pairs,
                        t.off_centre,
                        t.views_lost_identifiable);
  std::string missed;
  for (const auto& [why, n] : t.missed)
    missed += (missed.empty() ? "" : ";") + why + ":" + std::to_string(n);
  testing::RecordFigureText(key + ".missed", missed);
  testing::RecordFigure(key + ".nees",
                        "%d %.6g %d %.6g %.6g %d %.6g",
                        t.nees_n,
                        t.nees_sum,
                        t.nees_beyond_1e3,
                        t.radial_sum,
                        t.radial_sum2,
                        t.nees_widened_n,
                        t.nees_widened_sum);
}

// Renders `scenes` scenes of the seed set `base` with `anatomy`, detects and labels every view,
// and tallies them (printing every marker left out or labelled off its centre).
void RunRecall(Anatomy anatomy, int scenes, uint64_t base, Tally* tally) {
  const test::ScratchDir scratch("marker_recall");  // removed when it goes
  const std::string& dir = scratch.path();
  Tally& total = *tally;
  int used = 0, views_skipped = 0, views = 0;
  for (uint64_t seed = base * 1000; used < scenes && seed < base * 1000 + 10 * scenes; ++seed) {
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    const RandomScene rs = MakeScene(seed, anatomy, dir, PositionerFromEnv());
    {
      std::ofstream(JoinPath(dir, "scene.yaml")) << rs.yaml;
    }
    // A draw whose markers leave the field of view is refused by the simulator's scene check;
    // the next seed is drawn instead (recorded below).
    auto scene = sim::LoadXrayScene(JoinPath(dir, "scene.yaml"));
    if (!scene.ok()) continue;
    ++used;
    nlohmann::json truth;
    ASSERT_TRUE(sim::SimulateXrayScene(*scene, dir, &truth).ok());
    std::vector<std::string> files;
    for (const auto& v : truth["views"])
      files.push_back(JoinPath(dir, v["file"].get<std::string>()));
    ObjectViewsOptions o;
    o.blobs.diameter_mm = rs.diameter_mm;
    o.source_to_object_mm = rs.sod_mm;
    auto labelled = DetectAndLabelObjectViews(files, scene->camera, SceneMarkers(*scene), o);
    ASSERT_TRUE(labelled.ok()) << "seed " << seed << ": " << labelled.status().message();
    for (const ObjectView& v : *labelled) {
      ++views;
      if (!v.labelled) {
        ++views_skipped;
        std::cout << "  seed " << seed << " " << v.name << " skipped: " << v.skipped << "\n";
      }
    }
    if (const char* dump = std::getenv("CARMBA_MARKER_RECALL_DUMP")) {
      const std::string keep = JoinPath(dump, "seed_" + std::to_string(seed));
      std::filesystem::remove_all(keep);
      std::filesystem::create_directories(dump);
      std::filesystem::copy(dir, keep, std::filesystem::copy_options::recursive);
      std::ofstream(JoinPath(keep, "truth.json")) << truth.dump(1);
    }
    const Tally t = Score(*scene, truth, *labelled);
    std::cout << "seed " << seed << ": " << scene->phantom.spheres.size() << " markers, d "
              << rs.diameter_mm << " mm: " << t.correct << " / " << t.expected << " correct, "
              << t.wrong << " wrong, " << t.off_centre << " off their covariance, "
              << t.spurious_labelled << " beads labelled, " << t.overlap_labelled << " of "
              << t.overlapping_pairs << " overlapped labelled\n";
    total.Add(t);
  }
  std::filesystem::remove_all(dir);
  std::cout << "randomised marker scenes: " << used << " scenes, " << views << " views ("
            << views_skipped << " skipped, " << total.views_lost_identifiable
            << " of them with 4 or more visible separated markers): " << total.correct << " of "
            << total.expected << " visible separated markers labelled correctly, " << total.wrong
            << " wrong, " << total.off_centre << " off their covariance, "
            << total.spurious_labelled << " beads labelled, " << total.overlap_labelled << " of "
            << total.overlapping_pairs << " overlapped markers labelled; " << total.crossed_by_wire
            << " markers with the wire across them (labelled or not, at their centre if labelled); "
            << "labelled centres' NEES per dof " << total.NeesPerDof() << " over " << total.nees_n
            << ", " << total.nees_beyond_1e3 << " beyond chi2(2) at 1e-3; mean radial error "
            << total.MeanRadialPx() << " +- " << total.MeanRadialSePx() << " px\n";
  ASSERT_EQ(used, scenes) << "too few random draws fit the field of view";
  RecordRecallFigures(anatomy, base, scenes, views, views_skipped, total);
}

// At least `min_fraction` of the visible separated markers labelled, no wrong label, at most
// 0.5 % of the labelled centres off their covariance (0.05 % over the development sets), no bead
// labelled, no overlapped marker labelled, no view lost with 4 or more markers that could be
// identified (visible and apart from other markers, the beads and the wire).
void ExpectRecall(const Tally& total, int scenes, double min_fraction) {
  EXPECT_GT(total.expected, 30 * scenes);
  EXPECT_GE(total.correct, min_fraction * total.expected);
  EXPECT_EQ(total.wrong, 0);
  EXPECT_LE(total.off_centre, 0.005 * total.correct);
  EXPECT_EQ(total.spurious_labelled, 0);
  EXPECT_EQ(total.overlap_labelled, 0);
  EXPECT_EQ(total.views_lost_identifiable, 0);
}

int Scenes() { return testing::EnvOr("CARMBA_MARKER_RECALL_SCENES", 8); }
uint64_t SeedSet() { return testing::EnvOr<uint64_t>("CARMBA_MARKER_RECALL_SEED", 1); }

// The scenes' anatomy a crop of a real XA frame: every visible separated marker (>= 99.5 %, the
// plate detector's recall target), no wrong label, no bead labelled, no overlapped marker
// labelled.
TEST(MarkerRecall, XaFrameAnatomyEveryVisibleSeparatedMarkerLabelled) {
  Tally total;
  ASSERT_NO_FATAL_FAILURE(RunRecall(Anatomy::kXaFrame, Scenes(), SeedSet(), &total));
  ExpectRecall(total, Scenes(), 0.995);
}

// The same scenes with a real head CT's DRR as anatomy, read from DICOM XA files. Bone edges,
// sinuses and teeth lose markers that the XA frame does not; src/docs/results.md has every seed
// set's run. Held here: the 99 % on set 1, no wrong label, no bead, no overlapped marker.
TEST(MarkerRecall, RealCtAnatomyFromDicomXaNoWrongLabel) {
  if (!std::filesystem::exists(kInvesaliusCraniumPath)) {
    GTEST_SKIP() << "the skull CT " << kInvesaliusCraniumPath
                 << " is not installed (Debian package invesalius-examples, scripts/setup.sh)";
  }
  Tally total;
  ASSERT_NO_FATAL_FAILURE(RunRecall(Anatomy::kRealCt, Scenes(), SeedSet(), &total));
  ExpectRecall(total, Scenes(), 0.99);
}

// The scene of `seed` with `anatomy`, rendered, its views detected and labelled, and scored.
struct LabelledScene {
  std::vector<ObjectView> views;
  Tally tally;
};
void LabelScene(uint64_t seed,
                Anatomy anatomy,
                LabelledScene* out,
                const PositionerError& positioner = {}) {
  const test::ScratchDir dir("recall_scene");
  const RandomScene rs = MakeScene(seed, anatomy, dir.path(), positioner);
  std::ofstream(dir.File("scene.yaml")) << rs.yaml;
  auto scene = sim::LoadXrayScene(dir.File("scene.yaml"));
  ASSERT_TRUE(scene.ok()) << scene.status().message();
  nlohmann::json truth;
  ASSERT_TRUE(sim::SimulateXrayScene(*scene, dir.path(), &truth).ok());
  std::vector<std::string> files;
  for (const auto& v : truth["views"]) files.push_back(dir.File(v["file"].get<std::string>()));
  ObjectViewsOptions o;
  o.blobs.diameter_mm = rs.diameter_mm;
  o.source_to_object_mm = rs.sod_mm;
  auto views = DetectAndLabelObjectViews(files, scene->camera, SceneMarkers(*scene), o);
  ASSERT_TRUE(views.ok()) << views.status().message();
  out->views = std::move(*views);
  out->tally = Score(*scene, truth, out->views);
}

// View `view` of the real-CT scene of `seed` must be labelled at a predicted pose, with no wrong
// label and no bead, and at most `max_missed` of the scene's expected markers not labelled.
void ExpectViewLabelledAtThePrediction(uint64_t seed,
                                       size_t view,
                                       const PositionerError& positioner = {},
                                       int max_missed = 1) {
  LabelledScene s;
  ASSERT_NO_FATAL_FAILURE(LabelScene(seed, Anatomy::kRealCt, &s, positioner));
  ASSERT_LT(view, s.views.size());
  const ObjectView& v = s.views[view];
  ASSERT_TRUE(v.labelled) << v.skipped;
  EXPECT_EQ(v.labelling.method, "predicted");
  EXPECT_GE(v.labelling.num_labelled, 4);
  EXPECT_EQ(s.tally.wrong, 0);
  EXPECT_EQ(s.tally.spurious_labelled, 0);
  EXPECT_GE(s.tally.correct, s.tally.expected - max_missed);
}

// A view that cannot be labelled on its own is labelled at the pose that a later labelled view
// and the DICOM geometry predict (detect/marker_views.h): seed 17007's first view (6 markers) has
// two 4-marker labellings about equally good (RMS 0.024 and 0.039 px, 2 markers shared) and is
// refused as ambiguous; the next views are labelled by search, and the first one again from them.
// The only such view over the real-CT seed sets 1-32 since the blob covariances follow the
// second-difference noise correlation (2026-12-06; seed 15011's first view, the example before,
// is now labelled on its own).
TEST(MarkerRecall, AViewRefusedAloneIsLabelledFromALaterOne) {
  if (!std::filesystem::exists(kInvesaliusCraniumPath)) {
    GTEST_SKIP() << "the skull CT " << kInvesaliusCraniumPath << " is not installed";
  }
  ExpectViewLabelledAtThePrediction(17007, 0);
}

// At a predicted pose the markers are paired within predict_gate_px (40 px) first; the wide gate
// can pair a marker with another blob, and the pose refined on a few pairs then loses the others.
// Paired again within gate_px (pose/marker_correspondence.h), seed 13001's view 3 (refused as
// ambiguous between two 4-marker labellings before) is labelled.
TEST(MarkerRecall, APredictionIsPairedAgainWithinTheTightGate) {
  if (!std::filesystem::exists(kInvesaliusCraniumPath)) {
    GTEST_SKIP() << "the skull CT " << kInvesaliusCraniumPath << " is not installed";
  }
  ExpectViewLabelledAtThePrediction(13001, 3);
}

// A prediction off by a few mm (the C-arm's positioner: the object moved by up to 2 mm and
// 0.5 deg per view where the DICOM angles do not say) is moved by the image offset most markers
// agree on before it is paired within gate_px (pose/marker_correspondence.h). In seed 16004 (7
// markers of 1.6 mm) the pairing within the wide gate kept no marker in view 1 and the search
// found two wrong 5-marker labellings at RMS 0.7 px: the view was refused as ambiguous. The
// scene's other views lose 4 markers (3 merged, 1 without a blob), which the vote does not touch.
TEST(MarkerRecall, AnOffPredictionIsMovedByTheOffsetTheMarkersAgreeOn) {
  if (!std::filesystem::exists(kInvesaliusCraniumPath)) {
    GTEST_SKIP() << "the skull CT " << kInvesaliusCraniumPath << " is not installed";
  }
  ExpectViewLabelledAtThePrediction(16004, 1, {2.0, 0.5}, 4);
}

// A bead beside a hidden marker is not labelled as it (pose/marker_correspondence.h): in seed
// 13003 (7 markers of 1.8 mm, 4-6 of them as blobs of their own per view) a pose predicted from
// view 0 paired a bead 15-26 px from its marker within the wide gate in views 1 and 2, and the
// pose refined on 4 pairs bent to it (RMS 0.64 and 0.42 px). The tight pairing at the prediction
// holds the other markers without it: the wide one is not taken, and neither is the bead.
TEST(MarkerRecall, APairOnlyTheWideGateMadeIsNotTaken) {
  if (!std::filesystem::exists(kInvesaliusCraniumPath)) {
    GTEST_SKIP() << "the skull CT " << kInvesaliusCraniumPath << " is not installed";
  }
  LabelledScene s;
  ASSERT_NO_FATAL_FAILURE(LabelScene(13003, Anatomy::kRealCt, &s));
  EXPECT_TRUE(s.views[0].labelled) << s.views[0].skipped;
  EXPECT_EQ(s.tally.wrong, 0);
  EXPECT_EQ(s.tally.spurious_labelled, 0);
  EXPECT_GE(s.tally.correct, 18);
}

// A marker of 4 px is a half-peak region of about 12 pixels, whose pixel outline alone can give an
// axis ratio of 1.37 (3 x 4 pixels): not "merged" unless its axes' extents also differ by more
// than those steps (detect/marker_blobs.cc). Seed 3014 (1.6 mm markers) lost 4 of its 43 markers
// as merged, now 2 (axis extents 1.56 px apart: a missing corner pixel or two markers 2 px
// apart look alike at this size).
TEST(MarkerRecall, ASmallMarkerIsNotTakenForTwo) {
  if (!std::filesystem::exists(kInvesaliusCraniumPath)) {
    GTEST_SKIP() << "the skull CT " << kInvesaliusCraniumPath << " is not installed";
  }
  LabelledScene s;
  ASSERT_NO_FATAL_FAILURE(LabelScene(3014, Anatomy::kRealCt, &s));
  EXPECT_LE(s.tally.missed["merged"], 2);
  EXPECT_EQ(s.tally.wrong, 0);
  EXPECT_GE(s.tally.correct, s.tally.expected - 2);
}

// Noise on a small disc's outline stretches its half-peak region without the area a second
// marker would add (detect/marker_blobs.cc NoiseStretched): seed 1006's marker 10 in view 3
// (1.6 mm, 5 px, alone on textured bone: axis ratio 1.37, 0.95 of a marker's area) was rejected
// as "merged"; it is labelled at its centre.
TEST(MarkerRecall, ANoiseStretchedMarkerIsNotTakenForTwo) {
  if (!std::filesystem::exists(kInvesaliusCraniumPath)) {
    GTEST_SKIP() << "the skull CT " << kInvesaliusCraniumPath << " is not installed";
  }
  LabelledScene s;
  ASSERT_NO_FATAL_FAILURE(LabelScene(1006, Anatomy::kRealCt, &s));
  EXPECT_EQ(s.tally.missed["merged"], 0);
  EXPECT_EQ(s.tally.wrong, 0);
  EXPECT_EQ(s.tally.off_centre, 0);
  EXPECT_EQ(s.tally.correct, s.tally.expected);
}

// A view with 4 identifiable markers has no pair to spare: when the true labelling is refused
// because one of its centres is pulled 1.06 px off (its 4 pairs disagree) and a wrong labelling
// of 4 markers fits at 0.023 px, either could be the true one (pose/marker_correspondence.h,
// "rival"). XA seed 2011's view 4 was labelled wrong (4 markers, 3 of them wrong); it is refused
// as ambiguous.
TEST(MarkerRecall, FourMarkersWithAPulledRivalAreNotGuessed) {
  LabelledScene s;
  ASSERT_NO_FATAL_FAILURE(LabelScene(2011, Anatomy::kXaFrame, &s));
  ASSERT_EQ(s.views.size(), 5u);
  EXPECT_FALSE(s.views[4].labelled);
  EXPECT_NE(s.views[4].skipped.find("ambiguous marker labelling"), std::string::npos)
      << s.views[4].skipped;
  EXPECT_EQ(s.tally.wrong, 0);
  EXPECT_GE(s.tally.correct, 24);
}

// Two labellings of 5 markers that each take a spurious bead, contradict each other and fit at
// 0.75 px do not lose a view whose 4 markers visible apart fit at the blobs' noise
// (pose/marker_correspondence.cc FarBetterFit): XA seed 16004's view 1 (7 markers of 1.6 mm, one
// crossed by the wire and two merged) was skipped as ambiguous; it is labelled, right.
TEST(MarkerRecall, ContradictingLabellingsWithBeadsGiveWayToOneThatFits) {
  LabelledScene s;
  ASSERT_NO_FATAL_FAILURE(LabelScene(16004, Anatomy::kXaFrame, &s));
  ASSERT_EQ(s.views.size(), 5u);
  EXPECT_TRUE(s.views[1].labelled) << s.views[1].skipped;
  EXPECT_LT(s.views[1].labelling.rms_px, 0.1);
  EXPECT_EQ(s.tally.wrong, 0);
  EXPECT_EQ(s.tally.spurious_labelled, 0);
  EXPECT_GE(s.tally.correct, s.tally.expected - 2);
}

}  // namespace
}  // namespace carmba
