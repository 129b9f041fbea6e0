// A calibration config in the solver config's vocabulary (loss, outliers, backend) and in its
// older spelling (robust_loss, robust_loss_scale_px, outlier_threshold_sigma, solver) reads to the
// same options and the same engine options (CalibrationOptions::ToSolverConfig, the one mapping).
#include <gtest/gtest.h>

#include "calib/calibrate.h"
#include "problem/solver_config.h"
#include "scratch.h"

namespace carmba {
namespace {

class CalibConfigVocabulary : public ::testing::Test {
 protected:
  StatusOr<CalibrationOptions> Read(const std::string& text) {
    dir_.Write("c.yaml", text);
    CalibrationOptions o;
    const Status s = LoadCalibrationOptions(dir_.File("c.yaml"), &o);
    if (!s.ok()) return s;
    return o;
  }
  test::ScratchDir dir_{"calib_config"};
};

TEST_F(CalibConfigVocabulary, BothSpellingsReadTheSame) {
  auto old_spelling = Read("robust_loss: cauchy\nrobust_loss_scale_px: 2.5\n"
                           "outlier_threshold_sigma: 3\nsolver: ceres\n");
  auto new_spelling = Read("loss: {type: cauchy, scale_px: 2.5}\noutliers: {list_sigma: 3}\n"
                           "backend: ceres\n");
  ASSERT_TRUE(old_spelling.ok()) << old_spelling.status().message();
  ASSERT_TRUE(new_spelling.ok()) << new_spelling.status().message();
  for (const CalibrationOptions* o : {&*old_spelling, &*new_spelling}) {
    EXPECT_EQ(o->solve.loss, ba::Loss::kCauchy);
    EXPECT_EQ(o->solve.loss_scale_px, 2.5);
    EXPECT_EQ(o->solve.outlier_sigma, 3);
    EXPECT_EQ(o->solve.backend, ba::Backend::kCeres);
  }
  const ba::BaOptions a = old_spelling->ToSolverConfig().ToBaOptions();
  const ba::BaOptions b = new_spelling->ToSolverConfig().ToBaOptions();
  EXPECT_EQ(a.loss, ba::Loss::kCauchy);
  EXPECT_EQ(b.loss, ba::Loss::kCauchy);
  EXPECT_EQ(a.loss_scale_px, b.loss_scale_px);
  EXPECT_EQ(a.outlier_sigma, 3);
  EXPECT_EQ(b.backend, ba::Backend::kCeres);

  // trivial = none; carmba_lm = lm; the defaults are carmba's LM without a loss.
  auto plain = Read("loss: {type: trivial}\nbackend: carmba_lm\n");
  ASSERT_TRUE(plain.ok()) << plain.status().message();
  EXPECT_EQ(plain->solve.loss, ba::Loss::kTrivial);
  EXPECT_EQ(plain->solve.backend, ba::Backend::kCarmbaLm);
  const ba::BaOptions p = plain->ToSolverConfig().ToBaOptions();
  EXPECT_EQ(p.backend, ba::Backend::kCarmbaLm);
  EXPECT_EQ(p.loss, ba::Loss::kTrivial);
  // The pixel sigma estimated (no pixel_sigma_px): the engine's a-posteriori factor; given: a
  // priori.
  EXPECT_EQ(p.covariance_scale, ba::CovarianceScale::kGlobal);
  auto given = Read("pixel_sigma_px: 0.3\n");
  ASSERT_TRUE(given.ok()) << given.status().message();
  EXPECT_EQ(given->ToSolverConfig().covariance_scale, ba::CovarianceScale::kApriori);
  // A robust loss is solved by Ceres whatever the back end says (carmba's LM is plain least
  // squares).
  auto robust_lm = Read("loss: {type: huber}\nbackend: carmba_lm\n");
  ASSERT_TRUE(robust_lm.ok());
  EXPECT_EQ(robust_lm->ToSolverConfig().backend, ba::Backend::kCeres);
}

// The keys a calibration config shares with a solver config are read by the solver config's
// reader (ReadSolveKeys): what one accepts, the other accepts, and a value one refuses, both
// refuse with the same message.
TEST_F(CalibConfigVocabulary, TheSharedKeysAreTheSolverConfigs) {
  auto soft = Read(
      "loss: {type: soft_l1, scale_px: 0.5}\nmax_iterations: 7\nnum_threads: 2\n"
      "fix: [k3]\n");
  ASSERT_TRUE(soft.ok()) << soft.status().message();
  EXPECT_EQ(soft->solve.loss, ba::Loss::kSoftL1);
  EXPECT_EQ(soft->solve.loss_scale_px, 0.5);
  EXPECT_EQ(soft->solve.max_iterations, 7);
  EXPECT_EQ(soft->solve.num_threads, 2);
  EXPECT_EQ(soft->solve.fix, std::vector<std::string>{"k3"});
  EXPECT_EQ(soft->ToSolverConfig().ToBaOptions().loss, ba::Loss::kSoftL1);
  for (const char* text :
       {"loss: {type: l2}\n", "fix: [f]\n", "outliers: {list_sigma: 1e9}\n", "backend: lm2\n"}) {
    auto calib = Read(text);
    dir_.Write("s.yaml", std::string("name: s\n") + text);
    auto solver = LoadSolverConfig(dir_.File("s.yaml"));
    ASSERT_FALSE(calib.ok()) << text;
    ASSERT_FALSE(solver.ok()) << text;
    // The same message after the file name.
    const std::string a = calib.status().message(), b = solver.status().message();
    EXPECT_EQ(a.substr(a.find(": ")), b.substr(b.find(": "))) << a << "\n" << b;
  }
  // A calibration lists its outliers; dropping them is refused, naming the key.
  auto reject = Read("outliers: {list_sigma: 4, reject_sigma: 3}\n");
  ASSERT_FALSE(reject.ok());
  EXPECT_NE(reject.status().message().find("outliers.reject_sigma: expected 0"), std::string::npos)
      << reject.status().message();
}

TEST_F(CalibConfigVocabulary, BothSpellingsOfOneThingAreAnError) {
  auto r = Read("loss: {type: huber}\nrobust_loss: huber\n");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("give 'loss' or its older spelling 'robust_loss', not both"),
            std::string::npos)
      << r.status().message();
  auto b = Read("backend: ceres\nsolver: lm\n");
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.status().message().find("'backend' or its older spelling 'solver'"),
            std::string::npos);
  auto t = Read("loss: {type: none}\n");
  ASSERT_FALSE(t.ok());
  EXPECT_NE(t.status().message().find("type"), std::string::npos) << t.status().message();
}

}  // namespace
}  // namespace carmba
