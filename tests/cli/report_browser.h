// Renders a report.html in headless Chromium (Debian package `chromium`, installed by
// scripts/setup.sh) from disk, no server, and checks what a reader would see:
//   * the page's own check (report/report_doc.h) ran after the load event: every <img> decoded
//     (naturalWidth > 0) and no script error;
//   * Chromium printed no console message at all (our pages log nothing; a broken script or a
//     blocked resource shows up here);
//   * a screenshot of the first 1280 x 2000 px is not blank: its grey levels vary and a real
//     share of it is not background white.
// Skips (GTEST_SKIP in the caller's test) when no Chromium is installed.
#pragma once

#include <gtest/gtest.h>
#include <stdlib.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <regex>
#include <sstream>
#include <string>

#include "cli_test_util.h"
#include "util/image_codecs.h"

namespace carmba::test {

inline std::string FindChromium() {
  if (const char* env = std::getenv("CARMBA_CHROMIUM")) return env;
  for (const char* p :
       {"/usr/bin/chromium", "/usr/bin/chromium-browser", "/usr/bin/google-chrome"}) {
    if (std::filesystem::exists(p)) return p;
  }
  return "";
}

struct BrowserResult {
  std::string dom;       // the DOM after load (--dump-dom)
  std::string console;   // Chromium's CONSOLE lines
  int images_loaded = -1, images_total = -1;
  bool js_error = false;
  double grey_stddev = 0;        // of the screenshot
  double non_white_fraction = 0; // pixels darker than 245 of 255
};

// Loads `html` in Chromium; fills `r`. Returns false with a gtest failure if Chromium fails.
inline bool RenderInChromium(const std::string& chromium, const std::string& html,
                             BrowserResult* r) {
  namespace fs = std::filesystem;
  const ScratchDir scratch("browser");
  const std::string& dir = scratch.path();
  const std::string url = "file://" + fs::absolute(html).string();
  const std::string common = "timeout 120 '" + chromium +
                             "' --headless --no-sandbox --disable-gpu --disable-dev-shm-usage "
                             "--no-first-run --hide-scrollbars --enable-logging=stderr --v=0 "
                             "--user-data-dir='" + dir + "/profile' ";
  const std::string dump = common + "--dump-dom '" + url + "' > '" + dir + "/dom.html' 2> '" +
                           dir + "/dom.log'";
  if (std::system(dump.c_str()) != 0) {
    ADD_FAILURE() << dump << "\n" << ReadTextFile(dir + "/dom.log");
    return false;
  }
  const std::string shot = common + "--window-size=1280,2000 --screenshot='" + dir +
                           "/shot.png' '" + url + "' > /dev/null 2> '" + dir + "/shot.log'";
  if (std::system(shot.c_str()) != 0) {
    ADD_FAILURE() << shot << "\n" << ReadTextFile(dir + "/shot.log");
    return false;
  }
  r->dom = ReadTextFile(dir + "/dom.html");
  std::istringstream log(ReadTextFile(dir + "/dom.log") + ReadTextFile(dir + "/shot.log"));
  for (std::string line; std::getline(log, line);) {
    if (line.find(":CONSOLE") != std::string::npos) r->console += line + "\n";
  }
  std::smatch m;
  if (std::regex_search(r->dom, m, std::regex("data-images-loaded=\"(\\d+)\""))) {
    r->images_loaded = std::stoi(m[1]);
  }
  if (std::regex_search(r->dom, m, std::regex("data-images-total=\"(\\d+)\""))) {
    r->images_total = std::stoi(m[1]);
  }
  r->js_error = std::regex_search(r->dom, std::regex("<body[^>]*data-js-error"));
  const cv::Mat grey = carmba::ImRead(dir + "/shot.png", cv::IMREAD_GRAYSCALE);
  if (grey.empty()) {
    ADD_FAILURE() << "no screenshot: " << ReadTextFile(dir + "/shot.log");
    return false;
  }
  cv::Scalar mean, stddev;
  cv::meanStdDev(grey, mean, stddev);
  r->grey_stddev = stddev[0];
  r->non_white_fraction = cv::countNonZero(grey < 245) / static_cast<double>(grey.total());
  return true;
}

// A blank page has stddev 0 and no non-white pixel; a page of text only has ~2 % non-white.
constexpr double kMinGreyStddev = 8.0;
constexpr double kMinNonWhite = 0.01;

// The checks of the header, with at least `min_images` plots on the page.
inline void ExpectReportRenders(const std::string& html, int min_images) {
  const std::string chromium = FindChromium();
  if (chromium.empty()) {
    GTEST_SKIP() << "no Chromium found (install the Debian package 'chromium', or set "
                    "CARMBA_CHROMIUM); the report's browser check is skipped";
  }
  BrowserResult r;
  if (!RenderInChromium(chromium, html, &r)) return;
  EXPECT_FALSE(r.js_error) << r.dom.substr(0, 2000);
  EXPECT_EQ(r.console, "") << html;
  ASSERT_GE(r.images_total, 0) << "the page's check did not run:\n" << r.dom.substr(0, 2000);
  EXPECT_GE(r.images_total, min_images) << html;
  EXPECT_EQ(r.images_loaded, r.images_total) << html;
  EXPECT_GT(r.grey_stddev, kMinGreyStddev) << html;
  EXPECT_GT(r.non_white_fraction, kMinNonWhite) << html;
}

}  // namespace carmba::test
