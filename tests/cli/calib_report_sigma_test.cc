// The calibration report says which pixel sigma it used wherever it shows an uncertainty, and a
// correlation above 0.99 between two intrinsics is a warning in the report and on stderr (it used
// to say "No warnings" with cy-p1 at -0.998).
#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "synthetic/synthetic_views.h"
#include "cli_test_util.h"
#include "detect/observations.h"
#include "util/file_util.h"

namespace carmba::test {
namespace {

std::string Section(const std::string& md, const std::string& heading) {
  const size_t a = md.find("\n## " + heading);
  if (a == std::string::npos) return "";
  const size_t b = md.find("\n## ", a + 4);
  return md.substr(a, b == std::string::npos ? std::string::npos : b - a);
}

class CalibReportSigma : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(WriteSyntheticGridObservations(dir_.File("obs.csv")));
  }
  CommandResult Calibrate(const std::string& out, const std::string& extra = "") {
    return RunCarmba("calibrate --no-mrcal --no-opencv --no-plots --observations " +
                     dir_.File("obs.csv") + " " + extra + " --out " + dir_.File(out));
  }
  ScratchDir dir_;
};

TEST_F(CalibReportSigma, CorrelatedIntrinsicsAreWarnedAbout) {
  const auto r = Calibrate("all_free");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // The correlations, from camera.json's covariance (independent of the warning code).
  const auto cam = nlohmann::json::parse(*ReadFile(dir_.File("all_free/camera.json")));
  const auto& c = cam.at("covariance").at("matrix");
  const char* names[] = {"fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"};
  std::vector<std::string> pairs;
  for (int i = 0; i < 9; ++i) {
    for (int j = i + 1; j < 9; ++j) {
      const double den = std::sqrt(c[i][i].get<double>() * c[j][j].get<double>());
      if (den > 0 && std::abs(c[i][j].get<double>() / den) > 0.99) {
        pairs.push_back(std::string(names[i]) + " and " + names[j] + " correlate at");
      }
    }
  }
  // This data has such pairs (a narrow field of view: fx-fy, cx-p2, cy-p1): the test is not empty.
  ASSERT_FALSE(pairs.empty());
  const std::string md = *ReadFile(dir_.File("all_free/report.md"));
  const std::string cond = Section(md, "Conditioning");
  EXPECT_EQ(md.find("No warnings"), std::string::npos) << cond;
  for (const auto& p : pairs) {
    EXPECT_NE(cond.find("- WARNING: " + p), std::string::npos) << p << "\n" << cond;
    EXPECT_NE(r.err.find("carmba calibrate: warning: " + p), std::string::npos) << p;
  }
  size_t correlation_warnings = 0;  // (the others are about the principal point's sigma)
  for (const auto& w : cam.at("warnings")) {
    correlation_warnings += w.get<std::string>().find(" correlate at ") != std::string::npos;
  }
  EXPECT_EQ(correlation_warnings, pairs.size());
  // Estimated sigma: a-posteriori, in every section with an uncertainty, and on stdout.
  EXPECT_EQ(cam.at("sigma_px_kind"), "a-posteriori");
  for (const char* s : {"Residuals", "Intrinsics", "Projection uncertainty"}) {
    EXPECT_NE(Section(md, s).find("a-posteriori"), std::string::npos) << s;
    EXPECT_EQ(Section(md, s).find("a-priori"), std::string::npos) << s;
  }
  EXPECT_NE(r.out.find("(a-posteriori pixel sigma "), std::string::npos) << r.out;
}

TEST_F(CalibReportSigma, GivenSigmaIsAPriori) {
  dir_.Write("config.yaml", "pixel_sigma_px: 0.5\n");
  const auto r = Calibrate("given", "--config " + dir_.File("config.yaml"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string md = *ReadFile(dir_.File("given/report.md"));
  for (const char* s : {"Residuals", "Intrinsics", "Projection uncertainty"}) {
    EXPECT_NE(Section(md, s).find("a-priori (given: pixel_sigma_px)"), std::string::npos)
        << s << "\n" << Section(md, s);
    EXPECT_NE(Section(md, s).find("0.5000 px"), std::string::npos) << s;
    EXPECT_EQ(Section(md, s).find("a-posteriori"), std::string::npos) << s;
  }
  EXPECT_NE(r.out.find("(a-priori pixel sigma 0.5 px)"), std::string::npos) << r.out;
}

}  // namespace
}  // namespace carmba::test
