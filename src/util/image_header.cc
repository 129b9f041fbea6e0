#include "util/image_header.h"

#include <algorithm>
#include <fstream>
#include <vector>

#include "util/plausible.h"

namespace carmba {
namespace {

// The first bytes of a file (all of it when shorter).
StatusOr<std::string> ReadPrefix(const std::string& path, size_t n) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Error(path + ": cannot open file");
  std::string s(n, '\0');
  in.read(&s[0], static_cast<std::streamsize>(n));
  s.resize(static_cast<size_t>(in.gcount()));
  return s;
}

uint64_t Be(const std::string& s, size_t at, int n) {
  uint64_t v = 0;
  for (int i = 0; i < n; ++i) v = (v << 8) | static_cast<unsigned char>(s[at + i]);
  return v;
}
uint64_t Le(const std::string& s, size_t at, int n) {
  uint64_t v = 0;
  for (int i = n - 1; i >= 0; --i) v = (v << 8) | static_cast<unsigned char>(s[at + i]);
  return v;
}

bool ParsePng(const std::string& s, ImageHeader* h) {
  if (s.size() < 26 || s.compare(0, 8, "\x89PNG\r\n\x1a\n") != 0 || s.compare(12, 4, "IHDR") != 0) {
    return false;
  }
  h->format = "PNG";
  h->width = static_cast<int64_t>(Be(s, 16, 4));
  h->height = static_cast<int64_t>(Be(s, 20, 4));
  const int depth = static_cast<unsigned char>(s[24]), colour = static_cast<unsigned char>(s[25]);
  h->bytes_per_sample = depth == 16 ? 2 : 1;
  h->channels = colour == 2 ? 3 : colour == 4 ? 2 : colour == 6 ? 4 : colour == 3 ? 3 : 1;
  return true;
}

bool ParseBmp(const std::string& s, ImageHeader* h) {
  if (s.size() < 30 || s[0] != 'B' || s[1] != 'M' || Le(s, 14, 4) < 40) return false;
  h->format = "BMP";
  h->width = static_cast<int32_t>(Le(s, 18, 4));
  h->height = static_cast<int32_t>(Le(s, 22, 4));
  if (h->height < 0) h->height = -h->height;  // top-down
  if (h->width < 0) h->width = -h->width;
  h->channels = Le(s, 28, 2) > 24 ? 4 : Le(s, 28, 2) > 8 ? 3 : 1;
  return true;
}

// The SOFn segment (FFC0..FFCF except C4 DHT, C8 JPG, CC DAC) gives precision, height, width,
// components. Segments before it are skipped by their lengths.
bool ParseJpeg(const std::string& s, ImageHeader* h) {
  if (s.size() < 4 || static_cast<unsigned char>(s[0]) != 0xFF ||
      static_cast<unsigned char>(s[1]) != 0xD8) {
    return false;
  }
  size_t at = 2;
  while (at + 4 <= s.size()) {
    if (static_cast<unsigned char>(s[at]) != 0xFF) return false;
    const int marker = static_cast<unsigned char>(s[at + 1]);
    if (marker == 0xFF) {  // fill byte
      ++at;
      continue;
    }
    const size_t len = Be(s, at + 2, 2);
    const bool sof = marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 &&
                     marker != 0xCC;
    if (sof) {
      if (at + 10 > s.size()) return false;
      h->format = "JPEG";
      h->bytes_per_sample = static_cast<unsigned char>(s[at + 4]) > 8 ? 2 : 1;
      h->height = static_cast<int64_t>(Be(s, at + 5, 2));
      h->width = static_cast<int64_t>(Be(s, at + 7, 2));
      h->channels = static_cast<unsigned char>(s[at + 9]);
      return true;
    }
    at += 2 + len;
  }
  return false;
}

// PNM: "P5 <w> <h> <max>" with comments (#...) between the fields.
bool ParsePnm(const std::string& s, ImageHeader* h) {
  if (s.size() < 3 || s[0] != 'P' || s[1] < '1' || s[1] > '6') return false;
  const char kind = s[1];
  std::vector<int64_t> fields;
  const size_t want = (kind == '1' || kind == '4') ? 2 : 3;
  size_t at = 2;
  while (fields.size() < want && at < s.size()) {
    const char c = s[at];
    if (c == '#') {
      while (at < s.size() && s[at] != '\n') ++at;
    } else if (c >= '0' && c <= '9') {
      int64_t v = 0;
      while (at < s.size() && s[at] >= '0' && s[at] <= '9' && v < (int64_t{1} << 40)) {
        v = v * 10 + (s[at++] - '0');
      }
      fields.push_back(v);
      continue;
    } else if (c != ' ' && c != '\t' && c != '\n' && c != '\r') {
      return false;
    }
    ++at;
  }
  if (fields.size() < 2) return false;
  h->format = "PNM";
  h->width = fields[0];
  h->height = fields[1];
  h->channels = (kind == '3' || kind == '6') ? 3 : 1;
  h->bytes_per_sample = fields.size() > 2 && fields[2] > 255 ? 2 : 1;
  return true;
}

// TIFF: the first IFD's ImageWidth (256), ImageLength (257), BitsPerSample (258) and
// SamplesPerPixel (277). The IFD may lie anywhere in the file: it is read from `path` at its
// offset.
bool ParseTiff(const std::string& path, const std::string& s, ImageHeader* h) {
  if (s.size() < 8) return false;
  const bool le = s.compare(0, 2, "II") == 0;
  if (!le && s.compare(0, 2, "MM") != 0) return false;
  auto get = [&](const std::string& b, size_t at, int n) {
    return le ? Le(b, at, n) : Be(b, at, n);
  };
  const uint64_t magic = get(s, 2, 2);
  const bool big = magic == 43;
  if (magic != 42 && !big) return false;
  if (big && s.size() < 16) return false;
  const uint64_t ifd = big ? get(s, 8, 8) : get(s, 4, 4);
  std::ifstream in(path, std::ios::binary);
  in.seekg(static_cast<std::streamoff>(ifd));
  const size_t count_size = big ? 8 : 2, entry_size = big ? 20 : 12;
  std::string b(count_size, '\0');
  if (!in.read(&b[0], static_cast<std::streamsize>(count_size))) return false;
  const uint64_t n = std::min<uint64_t>(get(b, 0, static_cast<int>(count_size)), 4096);
  std::string e(n * entry_size, '\0');
  in.read(&e[0], static_cast<std::streamsize>(e.size()));
  e.resize(static_cast<size_t>(in.gcount()));
  h->format = "TIFF";
  for (size_t i = 0; (i + 1) * entry_size <= e.size(); ++i) {
    const size_t at = i * entry_size;
    const uint64_t tag = get(e, at, 2), type = get(e, at + 2, 2);
    const size_t value_at = at + (big ? 12 : 8);
    // SHORT (3) values sit in the first two bytes of the value field, LONG (4) in four, LONG8 (16)
    // in eight; the field itself is four bytes in classic TIFF (where LONG8 is not a valid type)
    // and eight in BigTIFF, so nothing is read past the entry.
    const int field_size = big ? 8 : 4;
    const int value_size = type == 3 ? 2 : type == 16 ? field_size : 4;
    const uint64_t value = get(e, value_at, value_size);
    if (tag == 256) h->width = static_cast<int64_t>(value);
    if (tag == 257) h->height = static_cast<int64_t>(value);
    if (tag == 258 && get(e, at + 4, big ? 8 : 4) == 1)
      h->bytes_per_sample = value > 8 ? (value + 7) / 8 : 1;
    if (tag == 277) h->channels = static_cast<int64_t>(value);
  }
  return h->width > 0 || h->height > 0;
}

}  // namespace

StatusOr<ImageHeader> ReadImageHeader(const std::string& path, bool* found) {
  auto s = ReadPrefix(path, 1 << 16);  // JPEG's SOF follows EXIF / ICC segments of up to 64 kB
  if (!s.ok()) return s.status();
  ImageHeader h;
  *found = ParsePng(*s, &h) || ParseJpeg(*s, &h) || ParseBmp(*s, &h) || ParsePnm(*s, &h) ||
           ParseTiff(path, *s, &h);
  return h;
}

Status CheckImageSize(const std::string& path, const ImageHeader& h) {
  const std::string size = std::to_string(h.width) + " x " + std::to_string(h.height) + " px " +
                           h.format + " image";
  const double pixels = static_cast<double>(h.width) * static_cast<double>(h.height);
  if (h.width < 1 || h.height < 1 || !InRange(pixels, plausible::kImagePixels)) {
    return Status::Error(path + ": " + size + ", expected " + FormatRange(plausible::kImagePixels) +
                         " per image (util/plausible.h kImagePixels; refused before decoding)");
  }
  const double bytes = pixels * static_cast<double>(std::max<int64_t>(1, h.channels)) *
                       static_cast<double>(std::max<int64_t>(1, h.bytes_per_sample));
  if (!InRange(bytes, plausible::kImageBytes)) {
    return Status::Error(path + ": " + size + " of " + std::to_string(h.channels) + " x " +
                         std::to_string(h.bytes_per_sample) + " bytes decodes to " +
                         FormatCompact(bytes) + " bytes, expected " +
                         FormatRange(plausible::kImageBytes) +
                         " (util/plausible.h kImageBytes; refused before decoding)");
  }
  return Status::Ok();
}

Status CheckImageFileSize(const std::string& path) {
  bool found = false;
  auto h = ReadImageHeader(path, &found);
  if (!h.ok()) return h.status();
  return found ? CheckImageSize(path, *h) : Status::Ok();
}

}  // namespace carmba
