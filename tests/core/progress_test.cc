// util/progress.h (the progress bar and its formatting) and util/text_match.h (closest-name
// suggestions for misspelt flags and commands).
#include <gtest/gtest.h>

#include <cstdio>
#include <string>
#include <thread>
#include <vector>

#include "util/progress.h"
#include "util/text_match.h"

namespace carmba {
namespace {

// Everything written to a FILE* by `write`.
template <typename F>
std::string Captured(F write) {
  FILE* f = std::tmpfile();
  EXPECT_NE(f, nullptr);
  write(f);
  std::fflush(f);
  std::rewind(f);
  std::string s;
  char buf[256];
  size_t n = 0;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) s.append(buf, n);
  std::fclose(f);
  return s;
}

TEST(ProgressFormat, BarCountPercentElapsedAndEta) {
  EXPECT_EQ(FormatProgressBar("calibrate", 5, 20, "images", 10.0, "img_0005.png", 20),
            "calibrate [#####...............]  5/20 images  25%  10s, ETA 30s  img_0005.png");
  EXPECT_EQ(FormatProgressBar("study", 20, 20, "runs", 75.0, "", 10),
            "study [##########] 20/20 runs 100%  1m15s, ETA 0s");
  // Before the first item there is no rate: ETA unknown.
  EXPECT_EQ(FormatProgressBar("solve", 0, 3, "views", 0.0, "", 4),
            "solve [....] 0/3 views   0%  0s, ETA ?");
  // A long item name keeps its end (the file name).
  const std::string line =
      FormatProgressBar("x", 1, 1, "images", 0, std::string(60, 'd') + "/frame_0001.png", 2);
  EXPECT_NE(line.find("...dddd"), std::string::npos) << line;
  EXPECT_EQ(line.substr(line.size() - 15), "/frame_0001.png");
  EXPECT_EQ(line.size(), std::string("x [##] 1/1 images 100%  0s, ETA 0s  ").size() + 40);
  // Over-counting never draws past the bar; zero items is complete.
  EXPECT_EQ(FormatProgressBar("x", 7, 5, "runs", 1, "", 5).substr(0, 9), "x [#####]");
  EXPECT_EQ(FormatProgressBar("x", 0, 0, "runs", 0, "", 3).substr(0, 7), "x [###]");
}

TEST(ProgressFormat, Durations) {
  EXPECT_EQ(FormatDuration(0.4), "0s");
  EXPECT_EQ(FormatDuration(59.4), "59s");
  EXPECT_EQ(FormatDuration(185), "3m05s");
  EXPECT_EQ(FormatDuration(3725), "1h02m");
  EXPECT_EQ(FormatDuration(-1), "?");
  EXPECT_EQ(FormatDuration(1e9), "?");
}

TEST(ProgressStyleChoice, BarOnlyOnATerminal) {
  EXPECT_EQ(ChooseProgressStyle(/*stderr_is_terminal=*/true, /*verbose=*/false),
            ProgressStyle::kBar);
  EXPECT_EQ(ChooseProgressStyle(true, true), ProgressStyle::kBar);
  EXPECT_EQ(ChooseProgressStyle(false, true), ProgressStyle::kLines);
  EXPECT_EQ(ChooseProgressStyle(false, false), ProgressStyle::kNone);
}

// Not a terminal: lines (no carriage return) with --verbose, nothing without.
TEST(ProgressOutput, PipeGetsLinesOrNothing) {
  const std::string lines = Captured([](FILE* f) {
    Progress p("detect", 3, "images", ProgressStyle::kLines, f);
    p.Tick("a.png");
    p.Tick("b.png");
    p.Tick("");
  });
  EXPECT_EQ(lines.find('\r'), std::string::npos) << lines;
  EXPECT_NE(lines.find("detect: 1/3 images done (0s): a.png\n"), std::string::npos) << lines;
  EXPECT_NE(lines.find("detect: 2/3 images done (0s): b.png\n"), std::string::npos) << lines;
  EXPECT_NE(lines.find("detect: 3/3 images done (0s)\n"), std::string::npos) << lines;
  const std::string none = Captured([](FILE* f) {
    Progress p("detect", 2, "images", ProgressStyle::kNone, f);
    p.Tick("a.png");
    p.Tick("b.png");
  });
  EXPECT_EQ(none, "");
}

// A terminal: the bar is redrawn in place and ended by one newline; the last item is always
// drawn, from any number of threads.
TEST(ProgressOutput, TerminalBarEndsWithTheLastItem) {
  const std::string bar = Captured([](FILE* f) {
    Progress p("study s", 400, "runs", ProgressStyle::kBar, f);
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t) {
      threads.emplace_back([&p]() {
        for (int i = 0; i < 100; ++i) p.Tick();
      });
    }
    for (auto& t : threads) t.join();
  });
  ASSERT_FALSE(bar.empty());
  EXPECT_EQ(bar[0], '\r');
  EXPECT_EQ(bar.back(), '\n');
  EXPECT_EQ(std::count(bar.begin(), bar.end(), '\n'), 1);
  EXPECT_NE(bar.find("] 400/400 runs 100%"), std::string::npos) << bar;
  // Throttled: far fewer redraws than items.
  EXPECT_LT(std::count(bar.begin(), bar.end(), '\r'), 50);
}

TEST(TextMatch, EditDistance) {
  EXPECT_EQ(EditDistance("", ""), 0);
  EXPECT_EQ(EditDistance("abc", ""), 3);
  EXPECT_EQ(EditDistance("", "abc"), 3);
  EXPECT_EQ(EditDistance("kitten", "sitting"), 3);
  EXPECT_EQ(EditDistance("--confg", "--config"), 1);
  EXPECT_EQ(EditDistance("--spacing-mn", "--spacing-mm"), 1);
  EXPECT_EQ(EditDistance("flaw", "lawn"), 2);
}

TEST(TextMatch, ClosestOrNothing) {
  const std::vector<std::string> flags = {"--config", "--cols", "--out", "--rows", "--spacing-mm"};
  EXPECT_EQ(ClosestMatch("--confg", flags), "--config");
  EXPECT_EQ(ClosestMatch("--colz", flags), "--cols");
  EXPECT_EQ(ClosestMatch("--spacing", flags), "--spacing-mm");
  EXPECT_EQ(ClosestMatch("--output", flags), "--out");
  // Nothing is plausibly meant.
  EXPECT_EQ(ClosestMatch("--threshold-hu", flags), "");
  EXPECT_EQ(ClosestMatch("slove", {"solve", "study", "simulate"}), "solve");
}

}  // namespace
}  // namespace carmba
