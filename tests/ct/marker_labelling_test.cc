#include "ct/marker_labelling.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <random>

#include "geometry/random_vector.h"

namespace carmba {
namespace {

std::vector<ModelPoint> ThesisModel() {
  auto m = ReadModelCsv(std::string(CARMBA_SOURCE_DIR) + "/data/thesis/markers_table_5_1.csv");
  EXPECT_TRUE(m.ok()) << m.status().message();
  return m.ok() ? *m : std::vector<ModelPoint>{};
}

Rigid3 SomeMotion() {
  Rigid3 T;
  T.R = (Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()) *
         Eigen::AngleAxisd(-0.3, Eigen::Vector3d::UnitZ()))
            .toRotationMatrix();
  T.t = Eigen::Vector3d(20, -110, -600);
  return T;
}

constexpr double kToleranceMm = 1.5;
constexpr double kNoiseMm = 0.05;  // CT centre noise in the synthetic data
// The rigid fit recovers the motion to about the noise over the object's ~40 mm lever arm.
constexpr double kRotationTol = 5e-3;

TEST(MarkerLabelling, ReadsTheThesisTableAndPicksTheObjectFrameColumns) {
  const auto model = ThesisModel();
  ASSERT_EQ(model.size(), 9u);
  EXPECT_EQ(model[2].id, 3);
  EXPECT_DOUBLE_EQ(model[2].p_in_object.x(), 13.35);  // x_o of marker 3
  auto ct = ReadModelCsv(std::string(CARMBA_SOURCE_DIR) + "/data/thesis/markers_table_5_1.csv",
                         {"x_ct", "y_ct", "z_ct"});
  ASSERT_TRUE(ct.ok());
  EXPECT_DOUBLE_EQ((*ct)[2].p_in_object.x(), 40.95);
}

TEST(MarkerLabelling, ShuffledMovedNoisyMarkersGetTheirModelIds) {
  const auto model = ThesisModel();
  const Rigid3 ct_from_object = SomeMotion();
  std::mt19937_64 rng(5);
  std::normal_distribution<double> noise(0, kNoiseMm);
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<int> order(model.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
    std::shuffle(order.begin(), order.end(), rng);
    // Drop one marker in half of the trials (a subset is labelled too).
    if (trial % 2) order.pop_back();
    std::vector<Eigen::Vector3d> found;
    for (int j : order) {
      found.push_back(ct_from_object * model[j].p_in_object +
                      RandomVector<3>(noise, rng));
    }
    auto lab = LabelMarkers(found, model, kToleranceMm);
    ASSERT_TRUE(lab.ok()) << lab.status().message();
    for (size_t a = 0; a < order.size(); ++a) EXPECT_EQ(lab->model_index[a], order[a]);
    EXPECT_LT(lab->rms_mm, 3 * kNoiseMm);
    EXPECT_LT((lab->object_from_ct.R * ct_from_object.R - Eigen::Matrix3d::Identity()).norm(),
              kRotationTol);
    // Unique (-1) or far worse.
    EXPECT_TRUE(lab->second_best_rms_mm < 0 || lab->second_best_rms_mm > 1.0);
  }
}

TEST(MarkerLabelling, MirrorImageIsRefused) {
  const auto model = ThesisModel();
  std::vector<Eigen::Vector3d> found;
  for (const auto& m : model) {
    found.push_back(Eigen::Vector3d(-m.p_in_object.x(), m.p_in_object.y(), m.p_in_object.z()));
  }
  auto lab = LabelMarkers(found, model, kToleranceMm);
  ASSERT_FALSE(lab.ok());
  EXPECT_NE(lab.status().message().find("mirror image"), std::string::npos)
      << lab.status().message();
}

TEST(MarkerLabelling, WrongScaleIsRefused) {
  const auto model = ThesisModel();
  std::vector<Eigen::Vector3d> found;
  for (const auto& m : model) found.push_back(1.2 * m.p_in_object);
  auto lab = LabelMarkers(found, model, kToleranceMm);
  ASSERT_FALSE(lab.ok());
  EXPECT_NE(lab.status().message().find("no labelling"), std::string::npos)
      << lab.status().message();
}

TEST(MarkerLabelling, SymmetricModelIsAmbiguous) {
  // The corners of a rectangle box: a rotation by 180 degrees maps it onto itself.
  std::vector<ModelPoint> model;
  int id = 1;
  for (double x : {-10.0, 10.0}) {
    for (double y : {-5.0, 5.0}) {
      for (double z : {0.0, 30.0}) model.push_back(ModelPoint{id++, Eigen::Vector3d(x, y, z)});
    }
  }
  std::vector<Eigen::Vector3d> found;
  for (const auto& m : model) found.push_back(m.p_in_object);
  auto lab = LabelMarkers(found, model, kToleranceMm);
  ASSERT_FALSE(lab.ok());
  EXPECT_NE(lab.status().message().find("ambiguous"), std::string::npos)
      << lab.status().message();
}

// The case: a model of 6 markers, 19 candidates (the 6 plus bone, teeth or stray metal
// that passed detection): the 6 that fit are selected and labelled, the others set aside.
TEST(MarkerLabelling, ExtraCandidatesAreSetAside) {
  auto full = ThesisModel();
  const std::vector<ModelPoint> model(full.begin(), full.begin() + 6);
  const Rigid3 ct_from_object = SomeMotion();
  std::mt19937_64 rng(11);
  std::normal_distribution<double> noise(0, kNoiseMm);
  std::uniform_real_distribution<double> u(-60, 60);
  for (int trial = 0; trial < 10; ++trial) {
    std::vector<Eigen::Vector3d> found;
    std::vector<int> truth;  // model index per candidate, -1 for the extras
    for (int j = 0; j < 6; ++j) {
      found.push_back(ct_from_object * model[j].p_in_object +
                      RandomVector<3>(noise, rng));
      truth.push_back(j);
    }
    const Eigen::Vector3d centre = ct_from_object * Eigen::Vector3d::Zero();
    for (int x = 0; x < 13; ++x) {
      found.push_back(centre + RandomVector<3>(u, rng));
      truth.push_back(-1);
    }
    std::vector<int> order(found.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
    std::shuffle(order.begin(), order.end(), rng);
    std::vector<Eigen::Vector3d> shuffled;
    std::vector<int> expected;
    for (int i : order) {
      shuffled.push_back(found[i]);
      expected.push_back(truth[i]);
    }
    auto lab = LabelMarkers(shuffled, model, kToleranceMm);
    ASSERT_TRUE(lab.ok()) << "trial " << trial << ": " << lab.status().message();
    EXPECT_EQ(lab->selected, 6);
    for (size_t a = 0; a < shuffled.size(); ++a) EXPECT_EQ(lab->model_index[a], expected[a]);
    EXPECT_LT(lab->rms_mm, 3 * kNoiseMm);
  }
}

TEST(MarkerLabelling, AmbiguousSelectionListsTheCandidates) {
  auto full = ThesisModel();
  const std::vector<ModelPoint> model(full.begin(), full.begin() + 5);
  // The pattern twice, 200 mm apart: both copies fit equally.
  std::vector<Eigen::Vector3d> found;
  for (const auto& shift : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(200, 0, 0)}) {
    for (const auto& m : model) found.push_back(m.p_in_object + shift);
  }
  auto lab = LabelMarkers(found, model, kToleranceMm);
  ASSERT_FALSE(lab.ok());
  const std::string msg = lab.status().message();
  EXPECT_NE(msg.find("ambiguous selection of 5 of the 10 candidates"), std::string::npos) << msg;
  EXPECT_NE(msg.find("best uses"), std::string::npos) << msg;
  EXPECT_NE(msg.find("next uses"), std::string::npos) << msg;
}

TEST(MarkerLabelling, NoFittingSubsetListsTheCandidates) {
  auto full = ThesisModel();
  const std::vector<ModelPoint> model(full.begin(), full.begin() + 4);
  std::vector<Eigen::Vector3d> found;
  for (int i = 0; i < 7; ++i) found.push_back(Eigen::Vector3d(100.0 * i, 3.0 * i * i, 0));
  auto lab = LabelMarkers(found, model, kToleranceMm);
  ASSERT_FALSE(lab.ok());
  const std::string msg = lab.status().message();
  EXPECT_NE(msg.find("no subset of the 7 candidates matches the 4 model points"),
            std::string::npos) << msg;
  EXPECT_NE(msg.find("(600.00, 108.00, 0.00)"), std::string::npos) << msg;
}

TEST(MarkerLabelling, FitRigidRefusesCollinearPoints) {
  std::vector<Eigen::Vector3d> p = {{0, 0, 0}, {1, 1, 1}, {2, 2, 2}, {5, 5, 5}};
  Rigid3 T;
  EXPECT_FALSE(FitRigid(p, p, &T));
  p[3] = Eigen::Vector3d(5, 0, 1);
  EXPECT_TRUE(FitRigid(p, p, &T));
  EXPECT_NEAR((T.R - Eigen::Matrix3d::Identity()).norm(), 0, 1e-12);
}

}  // namespace
}  // namespace carmba
