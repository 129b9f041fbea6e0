// util/image_codecs.h: OpenCV's codecs (libopencv_imgcodecs and the ~110 libraries it brings)
// are loaded on the first image read or written, not at every process start, and behave as
// cv::imread / cv::imwrite / cv::imencode.
#include "util/image_codecs.h"

#include <gtest/gtest.h>

#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <vector>

#include "cli/cli_test_util.h"

namespace carmba::test {
namespace {

constexpr char kCodecsLibrary[] = "libopencv_imgcodecs";

bool CodecsMapped() {
  std::ifstream maps("/proc/self/maps");
  std::stringstream text;
  text << maps.rdbuf();
  return text.str().find(kCodecsLibrary) != std::string::npos;
}

// Read while this executable's static objects are constructed: after the dynamic loader has
// loaded every library the test executable (linking every carmba library) needs, before any test.
const bool kCodecsMappedAtStart = CodecsMapped();

TEST(ImageCodecs, LoadedOnFirstUseAndNotAtProcessStart) {
  EXPECT_FALSE(kCodecsMappedAtStart) << "a carmba library links " << kCodecsLibrary;

  const ScratchDir dir("codecs");
  cv::Mat image(7, 5, CV_16UC1);
  for (int r = 0; r < image.rows; ++r) {
    for (int c = 0; c < image.cols; ++c) image.at<uint16_t>(r, c) = 1000 * r + 37 * c + 1;
  }
  ASSERT_TRUE(ImWrite(dir.File("a.png"), image));
  EXPECT_TRUE(CodecsMapped());

  const cv::Mat back = ImRead(dir.File("a.png"), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(back.type(), CV_16UC1);
  EXPECT_EQ(cv::norm(image, back, cv::NORM_INF), 0.0);

  std::vector<uint8_t> bytes;
  ASSERT_TRUE(ImEncode(".png", image, &bytes));
  std::ifstream file(dir.File("a.png"), std::ios::binary);
  const std::vector<uint8_t> written{std::istreambuf_iterator<char>(file), {}};
  EXPECT_EQ(bytes, written);

  EXPECT_TRUE(ImRead(dir.File("missing.png"), cv::IMREAD_UNCHANGED).empty());
  EXPECT_FALSE(ImWrite(dir.File("no_such_dir/a.png"), image));
}

TEST(ImageCodecs, TheCommandDoesNotLinkThem) {
  // The dynamic loader's list of the libraries `carmba` needs, without running it (ldd's way).
  const CommandResult r = RunCarmbaWithEnv("LD_TRACE_LOADED_OBJECTS=1", "");
  EXPECT_NE(r.out.find("libopencv_core"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find(kCodecsLibrary), std::string::npos) << r.out;
}

}  // namespace
}  // namespace carmba::test
