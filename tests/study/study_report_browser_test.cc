// The study report renders in a real browser: headless Chromium (Debian package `chromium`)
// loads DIR/report.html from disk (no server) and dumps the DOM after the page's scripts ran.
// The page's self-check (study/report_html.h) records how many plots were laid out with a
// non-empty bounding box. Skipped when no Chromium is installed.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <cstdio>
#include <fstream>
#include <regex>
#include <string>

#include "mean_study.h"
#include "study/runner.h"
#include "util/file_util.h"

namespace carmba {
namespace {

std::string FindChromium() {
  if (const char* env = std::getenv("CARMBA_CHROMIUM")) return env;
  for (const char* p : {"/usr/bin/chromium", "/usr/bin/chromium-browser", "/usr/bin/google-chrome"}) {
    if (FileExists(p)) return p;
  }
  return "";
}

TEST(StudyReportBrowserTest, ChromiumRendersEveryPlot) {
  const std::string chromium = FindChromium();
  if (chromium.empty()) {
    GTEST_SKIP() << "no Chromium found (install the Debian package 'chromium', or set "
                    "CARMBA_CHROMIUM); the report's browser check is skipped";
  }
  std::string dir = ::testing::TempDir() + "/carmba_report_XXXXXX";
  ASSERT_NE(::mkdtemp(dir.data()), nullptr);
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
  ASSERT_TRUE(RunStudy(*spec, testing::MeanRun, o, nullptr).ok());

  const std::string dom = dir + "/dom.html";
  const std::string cmd = "timeout 120 '" + chromium +
                          "' --headless --no-sandbox --disable-gpu --disable-dev-shm-usage "
                          "--no-first-run --user-data-dir='" + dir + "/profile' --dump-dom 'file://" +
                          dir + "/out/report.html' > '" + dom + "' 2> '" + dir + "/chromium.log'";
  const int rc = std::system(cmd.c_str());
  ASSERT_EQ(rc, 0) << cmd << "\n" << ReadFile(dir + "/chromium.log").value();
  StatusOr<std::string> html = ReadFile(dom);
  ASSERT_TRUE(html.ok());
  EXPECT_FALSE(std::regex_search(*html, std::regex("<body[^>]*data-js-error"))) << *html;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(*html, m, std::regex("data-plots-rendered=\"(\\d+)\"")))
      << "the page's script did not run:\n" << html->substr(0, 2000);
  const int rendered = std::stoi(m[1]);
  ASSERT_TRUE(std::regex_search(*html, m, std::regex("data-plots-total=\"(\\d+)\"")));
  const int total = std::stoi(m[1]);
  // 1 problem: 1 error metric vs 1 swept variable, 1 consistency plot, 2 residual histograms
  // (one per config), 1 budget source.
  EXPECT_EQ(total, 5);
  EXPECT_EQ(rendered, total);
  for (const char* kind :
       {"error-vs-noise", "sigma-consistency", "residual-histogram", "error-budget"}) {
    EXPECT_NE(html->find(std::string("data-plot=\"") + kind + "\""), std::string::npos) << kind;
  }
  // Every plot drew its marks: polylines for lines, circles for points, rects for bars.
  EXPECT_NE(html->find("<polyline"), std::string::npos);
  EXPECT_NE(html->find("<circle"), std::string::npos);
  EXPECT_NE(html->find("browser &lt;check&gt; &amp; co"), std::string::npos);  // escaped title
}

}  // namespace
}  // namespace carmba
