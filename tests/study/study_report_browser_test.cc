// The study report renders in a real browser: headless Chromium (Debian package `chromium`)
// loads DIR/report.html from disk (no server); tests/cli/report_browser.h checks that every plot
// image decoded, no console message or script error, and that a screenshot is not blank.
// Skipped when no Chromium is installed.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <cstdio>
#include <fstream>
#include <regex>
#include <string>

#include "../cli/report_browser.h"
#include "mean_study.h"
#include "scratch.h"
#include "study/runner.h"
#include "util/file_util.h"

namespace carmba {
namespace {

TEST(StudyReportBrowserTest, ChromiumRendersEveryPlot) {
  const test::ScratchDir scratch("report");  // removed when it goes
  const std::string& dir = scratch.path();
  std::ofstream(dir + "/p.yaml") << "true_mean: 1\nsamples: 30\n";
  std::ofstream(dir + "/mean.yaml") << "estimator: mean\n";
  std::ofstream(dir + "/median.yaml") << "estimator: median\n";
  std::ofstream(dir + "/s.yaml") << "name: browser <check> & co\ntrials: 6\nproblems:\n"
                                    "  - {name: p, file: p.yaml}\nconfigs:\n"
                                    "  - {name: mean, file: mean.yaml}\n"
                                    "  - {name: median, file: median.yaml}\n"
                                    "sweeps:\n  noise_sd: [0.1, 0.4, 1]\n";
  StatusOr<StudySpec> spec = LoadStudySpec(dir + "/s.yaml");
  ASSERT_TRUE(spec.ok()) << spec.status().message();
  StudyRunOptions o;
  o.out_dir = dir + "/out";
  o.jobs = 2;
  StudyRunStats stats;
  ASSERT_TRUE(RunStudy(*spec, testing::MeanRun, o, &stats).ok());
  EXPECT_EQ(stats.report_warning, "");
  StatusOr<std::string> html = ReadFile(dir + "/out/report.html");
  ASSERT_TRUE(html.ok());
  // 1 problem: 1 error metric vs 1 swept variable, 1 consistency plot, 2 residual histograms
  // (one per config), 1 budget figure.
  for (const char* id : {"error-vs-noise-1", "sigma-consistency", "residual-histogram-1",
                         "residual-histogram-2", "error-budget-1"}) {
    EXPECT_NE(html->find(std::string("data-plot=\"") + id + "\""), std::string::npos) << id;
  }
  EXPECT_EQ(html->find("residual-histogram-3"), std::string::npos);
  EXPECT_NE(html->find("browser &lt;check&gt; &amp; co"), std::string::npos);  // escaped title
  // The summary's tables are on the page too.
  EXPECT_NE(html->find("<h2>Accuracy</h2>"), std::string::npos);
  test::ExpectReportRenders(dir + "/out/report.html", 5);
}

}  // namespace
}  // namespace carmba
