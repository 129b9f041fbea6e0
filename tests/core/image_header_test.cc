// Image sizes from the header, before decoding (util/image_header.h): each format's header parsed
// by hand-made bytes, and an absurd size refused with its bound.
#include "scratch.h"
#include "util/image_header.h"

#include <gtest/gtest.h>
#include <stdlib.h>
#include <unistd.h>

#include <cstdint>
#include <fstream>
#include <string>

namespace carmba {
namespace {

class ImageHeaderTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::MakeScratchDir("image_header");
  }
  void TearDown() override { std::system(("rm -rf '" + dir_ + "'").c_str()); }
  std::string Write(const std::string& name, const std::string& bytes) {
    const std::string path = dir_ + "/" + name;
    std::ofstream(path, std::ios::binary) << bytes;
    return path;
  }
  std::string dir_;
};

std::string Be32(uint32_t v) {
  return {static_cast<char>(v >> 24), static_cast<char>(v >> 16), static_cast<char>(v >> 8),
          static_cast<char>(v)};
}
std::string Le32(uint32_t v) {
  return {static_cast<char>(v), static_cast<char>(v >> 8), static_cast<char>(v >> 16),
          static_cast<char>(v >> 24)};
}
std::string Le16(uint16_t v) { return {static_cast<char>(v), static_cast<char>(v >> 8)}; }
std::string Be16(uint16_t v) { return {static_cast<char>(v >> 8), static_cast<char>(v)}; }

std::string Png(uint32_t w, uint32_t h, int depth, int colour) {
  return std::string("\x89PNG\r\n\x1a\n", 8) + Be32(13) + "IHDR" + Be32(w) + Be32(h) +
         static_cast<char>(depth) + static_cast<char>(colour) + std::string(3, '\0') + Be32(0);
}

// A JPEG with an APP0 segment before its SOF0.
std::string Jpeg(uint16_t w, uint16_t h) {
  return std::string("\xFF\xD8\xFF\xE0", 4) + Be16(16) + "JFIF" + std::string(10, '\0') +
         std::string("\xFF\xC0", 2) + Be16(11) + '\x08' + Be16(h) + Be16(w) + '\x01' +
         std::string(3, '\0');
}

std::string Bmp(int32_t w, int32_t h, uint16_t bits) {
  return "BM" + Le32(0) + Le32(0) + Le32(54) + Le32(40) + Le32(static_cast<uint32_t>(w)) +
         Le32(static_cast<uint32_t>(h)) + Le16(1) + Le16(bits) + std::string(24, '\0');
}

// A little- or big-endian TIFF whose IFD (width LONG, height SHORT, bits and samples SHORT)
// follows a gap.
std::string Tiff(bool le, uint32_t w, uint16_t h, uint16_t bits = 16, uint16_t samples = 1) {
  auto u16 = [&](uint16_t v) { return le ? Le16(v) : Be16(v); };
  auto u32 = [&](uint32_t v) { return le ? Le32(v) : Be32(v); };
  std::string s = std::string(le ? "II" : "MM") + u16(42) + u32(100) + std::string(92, '\0');
  s += u16(4);
  s += u16(256) + u16(4) + u32(1) + u32(w);
  s += u16(257) + u16(3) + u32(1) + u16(h) + u16(0);
  s += u16(258) + u16(3) + u32(1) + u16(bits) + u16(0);
  s += u16(277) + u16(3) + u32(1) + u16(samples) + u16(0);
  return s + u32(0);
}

TEST_F(ImageHeaderTest, ReadsEachFormatsSize) {
  struct Case {
    std::string name, bytes, format;
    int64_t w, h, channels, bytes_per_sample;
  };
  const Case cases[] = {
      {"a.png", Png(640, 480, 16, 0), "PNG", 640, 480, 1, 2},
      {"b.png", Png(30000, 30000, 8, 6), "PNG", 30000, 30000, 4, 1},
      {"c.jpg", Jpeg(1024, 768), "JPEG", 1024, 768, 1, 1},
      {"d.bmp", Bmp(800, -600, 24), "BMP", 800, 600, 3, 1},
      {"e.tif", Tiff(true, 70000, 3000), "TIFF", 70000, 3000, 1, 2},
      {"f.tif", Tiff(false, 512, 256), "TIFF", 512, 256, 1, 2},
      {"g.pgm", "P5\n# comment\n4096 2048\n65535\n", "PNM", 4096, 2048, 1, 2},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    bool found = false;
    auto h = ReadImageHeader(Write(c.name, c.bytes), &found);
    ASSERT_TRUE(h.ok()) << h.status().message();
    ASSERT_TRUE(found);
    EXPECT_EQ(h->format, c.format);
    EXPECT_EQ(h->width, c.w);
    EXPECT_EQ(h->height, c.h);
    EXPECT_EQ(h->channels, c.channels);
    EXPECT_EQ(h->bytes_per_sample, c.bytes_per_sample);
  }
  bool found = true;
  auto h = ReadImageHeader(Write("x.txt", "not an image"), &found);
  ASSERT_TRUE(h.ok());
  EXPECT_FALSE(found);
}

// Reported: a 30000 x 30000 PNG used 4.46 GB and 14 s. The header alone is refused, with the bound
// and where it is stated.
TEST_F(ImageHeaderTest, AbsurdSizeIsRefusedFromTheHeader) {
  const std::string big = Write("big.png", Png(30000, 30000, 8, 0));
  const Status s = CheckImageFileSize(big);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message(), big + ": 30000 x 30000 px PNG image, expected 1 .. 1e+08 px per image "
                               "(util/plausible.h kImagePixels; refused before decoding)");
  EXPECT_TRUE(CheckImageFileSize(Write("ok.png", Png(10000, 10000, 16, 6))).ok());  // 8e8 B
  EXPECT_FALSE(CheckImageFileSize(Write("zero.bmp", Bmp(0, 10, 8))).ok());
  // Within the pixels, over the bytes: 9000 x 9000 of 4 samples of 32 bits is 1.3e9 bytes.
  const std::string deep = Write("deep.tif", Tiff(true, 9000, 9000, 32, 4));
  const Status d = CheckImageFileSize(deep);
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.message(), deep + ": 9000 x 9000 px TIFF image of 4 x 4 bytes decodes to "
                                "1.296e+09 bytes, expected 1 .. 1.07374e+09 bytes "
                                "(util/plausible.h kImageBytes; refused before decoding)");
}

// Found by fuzz_image under ASan (CI, fb66dba): a classic TIFF whose last IFD entry claims type
// LONG8 (16, valid only in BigTIFF) made the parser read an 8-byte value from a 4-byte field, past
// the entry's end. The value is now read at the field's size. The file is the fuzzer's regression
// seed (tests/fuzz/seeds/regress_image), so the ASan build replays it on every run.
TEST_F(ImageHeaderTest, Long8InAClassicTiffIsReadAtTheFieldsSize) {
  const std::string path = std::string(CARMBA_SOURCE_DIR) +
                           "/tests/fuzz/seeds/regress_image/tiff_long8_in_classic_ifd.tif";
  bool found = false;
  auto h = ReadImageHeader(path, &found);
  ASSERT_TRUE(h.ok()) << h.status().message();
  ASSERT_TRUE(found);
  EXPECT_EQ(h->format, "TIFF");
  EXPECT_EQ(h->width, 640);
  EXPECT_EQ(h->height, 0);
}

}  // namespace
}  // namespace carmba
