#include "util/dicom_structure.h"

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>

namespace carmba {

bool HasDicmMarker(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  char buf[132];
  if (!f.read(buf, 132)) return false;
  return std::memcmp(buf + 128, "DICM", 4) == 0;
}

namespace {

// A structural check of a DICOM file before GDCM parses it: GDCM (as packaged by Debian) aborts
// on an assertion for some truncated files. Walks the file meta group and the data set (explicit
// or implicit VR little endian, explicit VR big endian, nested sequences and encapsulated pixel
// data) and checks that every element's value lies within the file. *dicom is false for files that do not look like
// DICOM at all (to be skipped). Deflated data sets are left to GDCM.
class DicomWalker {
 public:
  explicit DicomWalker(const std::string& data) : d_(data) {}

  // Returns "" when the structure is sound, else what is wrong.
  std::string Check(bool* dicom) {
    *dicom = false;
    size_t pos = 0;
    bool explicit_vr = true;
    if (d_.size() >= 132 && d_.compare(128, 4, "DICM") == 0) {
      *dicom = true;
      pos = 132;
      std::string ts;
      while (pos + 8 <= d_.size() && U16(pos) == 0x0002) {
        const uint16_t elem = U16(pos + 2);
        size_t value_pos, len;
        if (!ElementHeader(pos, true, &value_pos, &len)) return error_;
        if (len == kUndefined) return At(pos, "undefined length in the file meta group");
        // GDCM (as packaged by Debian) aborts on an assertion for a sequence in the file meta
        // group (ReadExplicitDataElement).
        if (d_.compare(pos + 4, 2, "SQ") == 0)
          return At(pos, "a sequence (SQ) in the file meta group");
        if (value_pos + len > d_.size()) return Truncated(pos, len);
        if (elem == 0x0010) {
          ts = d_.substr(value_pos, len);
          while (!ts.empty() && (ts.back() == '\0' || ts.back() == ' ')) ts.pop_back();
        }
        pos = value_pos + len;
      }
      // GDCM reads group-0002 elements until the next tag is another group's, and aborts on an
      // assertion when the file ends instead (found by fuzz_dicom_xray).
      if (pos + 8 > d_.size()) return At(pos, "the file ends in its file meta group (no data set)");
      // Deflated data sets are left to GDCM. Explicit VR big endian is walked too: GDCM takes a
      // big-endian element's length as given and allocates it (an OOM in fuzz_dicom_xray).
      if (ts == "1.2.840.10008.1.2.1.99") return "";
      big_endian_ = ts == "1.2.840.10008.1.2.2";
      explicit_vr = ts != "1.2.840.10008.1.2";
    } else {
      // No preamble: plausible only if it starts with a group-0008 (or 0002) element.
      if (d_.size() < 8 || (U16(0) != 0x0008 && U16(0) != 0x0002)) return "";
      *dicom = true;
      explicit_vr = IsUpper(d_[4]) && IsUpper(d_[5]);
    }
    if (!Walk(&pos, explicit_vr, false, 0)) return error_;
    // GDCM (as packaged by Debian) aborts on an assertion (ImageCodec::DecodeByStreams, already
    // while reading the image: Bitmap::ComputeLossyFlag) for compressed 8-bit pixel data with
    // fewer bits stored (found by fuzz_dicom_xray).
    // GDCM asserts Samples per Pixel <= 4 while reading the image (PixelFormat::
    // SetSamplesPerPixel; found by fuzz_dicom_xray).
    if (samples_per_pixel_ > 4) {
      return error_ = "Samples per Pixel (0028,0002) is " + std::to_string(samples_per_pixel_) +
                      ", expected 1 to 4";
    }
    if (encapsulated_ && bits_allocated_ == 8 && bits_stored_ >= 0 && bits_stored_ != 8) {
      return error_ = "Bits Stored (0028,0101) " + std::to_string(bits_stored_) +
                      " with Bits Allocated 8 in compressed pixel data: GDCM cannot decode it, "
                      "expected Bits Stored 8";
    }
    return "";
  }

 private:
  static constexpr size_t kUndefined = 0xffffffffu;
  static bool IsUpper(char c) { return c >= 'A' && c <= 'Z'; }
  uint16_t U16(size_t p) const {
    const unsigned lo = static_cast<unsigned char>(d_[p + (big_endian_ ? 1 : 0)]);
    const unsigned hi = static_cast<unsigned char>(d_[p + (big_endian_ ? 0 : 1)]);
    return static_cast<uint16_t>(lo | (hi << 8));
  }
  uint32_t U32(size_t p) const {
    return big_endian_ ? (static_cast<uint32_t>(U16(p)) << 16) | U16(p + 2)
                       : U16(p) | (static_cast<uint32_t>(U16(p + 2)) << 16);
  }
  std::string At(size_t pos, const std::string& what) {
    char b[64];
    std::snprintf(b, sizeof(b), "at byte %zu: ", pos);
    return error_ = b + what;
  }
  std::string Truncated(size_t pos, size_t len) {
    char b[160];
    std::snprintf(b, sizeof(b),
                  "truncated: element (%04x,%04x) at byte %zu needs %zu bytes, the file has %zu",
                  U16(pos), U16(pos + 2), pos, len, d_.size());
    return error_ = b;
  }
  bool ElementHeader(size_t pos, bool explicit_vr, size_t* value_pos, size_t* len) {
    if (pos + 8 > d_.size()) {
      At(pos, "truncated element header");
      return false;
    }
    const uint16_t group = U16(pos);
    if (group == 0xfffe || !explicit_vr) {
      *len = U32(pos + 4);
      *value_pos = pos + 8;
      return true;
    }
    const std::string vr = d_.substr(pos + 4, 2);
    // The VRs of PS3.5 6.2 only: GDCM (as packaged by Debian) aborts on an assertion for others
    // in the file meta group (e.g. "UM"; found by fuzz_dicom_xray).
    static const char* kVrs[] = {"AE", "AS", "AT", "CS", "DA", "DS", "DT", "FL", "FD", "IS", "LO",
                                 "LT", "OB", "OD", "OF", "OL", "OV", "OW", "PN", "SH", "SL", "SQ",
                                 "SS", "ST", "SV", "TM", "UC", "UI", "UL", "UN", "UR", "US", "UT",
                                 "UV"};
    bool known = false;
    for (const char* v : kVrs) known = known || vr == v;
    if (!known) {
      At(pos, IsUpper(vr[0]) && IsUpper(vr[1]) ? "invalid VR '" + vr + "'" : "invalid VR");
      return false;
    }
    static const char* kLong[] = {"OB", "OW", "OF", "SQ", "UT", "UN", "OD", "OL", "OV", "UC",
                                  "UR", "SV", "UV"};
    bool is_long = false;
    for (const char* l : kLong) is_long = is_long || vr == l;
    if (is_long) {
      if (pos + 12 > d_.size()) {
        At(pos, "truncated element header");
        return false;
      }
      *len = U32(pos + 8);
      *value_pos = pos + 12;
    } else {
      *len = U16(pos + 6);
      *value_pos = pos + 8;
    }
    return true;
  }
  // Walks elements until the end of the file (depth 0), or the item/sequence delimiter.
  bool Walk(size_t* pos, bool explicit_vr, bool in_item, int depth) {
    if (depth > 32) {
      At(*pos, "sequences nested too deeply");
      return false;
    }
    while (*pos < d_.size()) {
      const uint16_t group = U16(*pos), elem = *pos + 4 <= d_.size() ? U16(*pos + 2) : 0;
      size_t value_pos, len;
      if (!ElementHeader(*pos, explicit_vr, &value_pos, &len)) return false;
      if (group == 0xfffe && (elem == 0xe00d || elem == 0xe0dd)) {
        *pos = value_pos;
        if (in_item) return true;
        continue;
      }
      if (len == kUndefined) {
        // A sequence (or encapsulated pixel data): items until the sequence delimiter.
        if (depth == 0 && group == 0x7fe0 && elem == 0x0010) encapsulated_ = true;
        size_t p = value_pos;
        while (true) {
          size_t item_value, item_len;
          if (!ElementHeader(p, explicit_vr, &item_value, &item_len)) return false;
          if (U16(p) != 0xfffe) {
            At(p, "expected an item in a sequence");
            return false;
          }
          if (U16(p + 2) == 0xe0dd) {
            p = item_value;
            break;
          }
          if (item_len == kUndefined) {
            p = item_value;
            if (!Walk(&p, explicit_vr, true, depth + 1)) return false;
          } else {
            if (item_value + item_len > d_.size()) {
              Truncated(p, item_len);
              return false;
            }
            p = item_value + item_len;
          }
        }
        *pos = p;
        continue;
      }
      if (value_pos + len > d_.size()) {
        Truncated(*pos, len);
        return false;
      }
      if (depth == 0 && group == 0x0028 && len == 2) {
        if (elem == 0x0002) samples_per_pixel_ = U16(value_pos);
        if (elem == 0x0100) bits_allocated_ = U16(value_pos);
        if (elem == 0x0101) bits_stored_ = U16(value_pos);
      }
      *pos = value_pos + len;
    }
    if (in_item) {
      At(*pos, "truncated: sequence item without its delimiter");
      return false;
    }
    return true;
  }

  const std::string& d_;
  std::string error_;
  // From the top-level data set: (0028,0002), (0028,0100), (0028,0101) (-1: absent), and
  // whether (7fe0,0010) is encapsulated.
  int samples_per_pixel_ = -1, bits_allocated_ = -1, bits_stored_ = -1;
  bool encapsulated_ = false;
  bool big_endian_ = false;  // the data set's byte order (the file meta group is little endian)
};

}  // namespace

std::string CheckDicomStructure(const std::string& bytes, bool* is_dicom) {
  return DicomWalker(bytes).Check(is_dicom);
}

}  // namespace carmba
