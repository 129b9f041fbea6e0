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
// data, defined-length sequences and items) and checks that every element's value lies within
// the file and its item. *dicom is false for files that do not look like DICOM at all (to be
// skipped). Deflated data sets are refused.
class DicomWalker {
 public:
  DicomWalker(const std::string& data, DicomStructureInfo* info) : d_(data), info_(info) {}

  // Returns "" when the structure is sound, else what is wrong.
  std::string Check(bool* dicom) {
    *dicom = false;
    size_t pos = 0;
    bool explicit_vr = true;
    const bool preamble = d_.size() >= 132 && d_.compare(128, 4, "DICM") == 0;
    if (preamble || (d_.size() >= 8 && U16(0) == 0x0002)) {
      // A file meta group, after the preamble or (legacy files) at the start of the file.
      *dicom = true;
      pos = preamble ? 132 : 0;
      // GDCM reads a meta group without preamble as implicit VR when it finds no VR, and
      // aborts on an assertion when the file ends in it; carmba accepts explicit VR only there.
      if (!preamble && !(IsUpper(d_[4]) && IsUpper(d_[5])))
        return At(0, "a file meta group without preamble in implicit VR (not supported)");
      // GDCM reads a file whose preamble is not followed by a file meta group with guesses of
      // its own (e.g. big endian for a tag (ffff,0000)), which this walk cannot follow: an OOM in
      // fuzz_dicom_xray.
      if (preamble && (d_.size() < 140 || U16(132) != 0x0002))
        return At(132, "no file meta group after the preamble (expected an element of group 0002)");
      std::string ts;
      bool has_ts = false;
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
          has_ts = true;
          ts = d_.substr(value_pos, len);
          while (!ts.empty() && (ts.back() == '\0' || ts.back() == ' ')) ts.pop_back();
        }
        pos = value_pos + len;
      }
      // GDCM reads group-0002 elements until the next tag is another group's, and aborts on an
      // assertion when the file ends instead (found by fuzz_dicom_xray, with and without the
      // preamble).
      if (pos + 8 > d_.size()) return At(pos, "the file ends in its file meta group (no data set)");
      // Without a transfer syntax GDCM guesses the data set's encoding.
      if (!has_ts || ts.empty())
        return At(pos, "no Transfer Syntax UID (0002,0010) in the file meta group");
      if (info_) info_->transfer_syntax = ts;
      // Deflated data sets cannot be walked without inflating them, and GDCM allocates what a
      // corrupt one declares (an OOM in fuzz_dicom_xray): refused (a retired-in-practice syntax
      // no C-arm writes). Explicit VR big endian is walked too: GDCM takes a big-endian element's
      // length as given and allocates it (an OOM in fuzz_dicom_xray).
      if (ts == "1.2.840.10008.1.2.1.99") {
        return At(pos, "Deflated Explicit VR Little Endian (1.2.840.10008.1.2.1.99) is not "
                       "supported, expected an uncompressed or compressed-pixel transfer syntax");
      }
      big_endian_ = ts == "1.2.840.10008.1.2.2";
      explicit_vr = ts != "1.2.840.10008.1.2";
    } else {
      // No preamble: plausible only if it starts with a group-0008 element.
      if (d_.size() < 8 || U16(0) != 0x0008) return "";
      *dicom = true;
      explicit_vr = IsUpper(d_[4]) && IsUpper(d_[5]);
    }
    if (!Walk(&pos, d_.size(), explicit_vr, Scope::kTop, 0)) return error_;
    // GDCM (as packaged by Debian) aborts on an assertion (ImageCodec::DecodeByStreams, already
    // while reading the image: Bitmap::ComputeLossyFlag) for compressed 8-bit pixel data with
    // fewer bits stored (found by fuzz_dicom_xray).
    // GDCM asserts Samples per Pixel is 1, 3 or 4 while reading the image (PixelFormat::
    // SetSamplesPerPixel; found by fuzz_dicom_xray).
    if (samples_per_pixel_ >= 0 && samples_per_pixel_ != 1 && samples_per_pixel_ != 3 &&
        samples_per_pixel_ != 4) {
      return error_ = "Samples per Pixel (0028,0002) is " + std::to_string(samples_per_pixel_) +
                      ", expected 1, 3 or 4";
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
    if (info_) {
      DicomElementVr e;
      e.group = group;
      e.element = U16(pos + 2);
      e.vr[0] = vr[0];
      e.vr[1] = vr[1];
      e.pos = pos;
      info_->explicit_vrs.push_back(e);
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
  enum class Scope {
    kTop,            // the data set: elements until the end of the file
    kItemUndefined,  // an item of undefined length: elements until its delimiter (fffe,e00d)
    kItemDefined,    // an item of defined length: elements filling [*pos, end) exactly
  };
  bool IsItemTag(size_t p) const { return U16(p) == 0xfffe && U16(p + 2) == 0xe000; }

  // Walks the elements of a data set or of a sequence item (see Scope). GDCM aborts on
  // assertions where an item or delimiter stands outside its place, or where a defined-length
  // sequence or item does not add up (DataSet::ReadWithLength; found by fuzz_dicom_xray), so
  // sequences of defined length are walked too, and every item or delimiter (group fffe) is
  // checked.
  bool Walk(size_t* pos, size_t end, bool explicit_vr, Scope scope, int depth) {
    if (depth > 32) {
      At(*pos, "sequences nested too deeply");
      return false;
    }
    while (*pos < end) {
      const size_t at = *pos;
      if (at + 8 > end && end != d_.size()) {
        At(at, "an element runs past the end of its item");
        return false;
      }
      const uint16_t group = U16(at), elem = at + 4 <= d_.size() ? U16(at + 2) : 0;
      size_t value_pos, len;
      if (!ElementHeader(at, explicit_vr, &value_pos, &len)) return false;
      if (group == 0xfffe) {
        if (elem == 0xe00d && scope == Scope::kItemUndefined && len == 0) {
          *pos = value_pos;
          return true;
        }
        char b[96];
        std::snprintf(b, sizeof(b), "an item or delimiter (fffe,%04x) out of place", elem);
        At(at, b);
        return false;
      }
      const std::string vr = explicit_vr ? d_.substr(at + 4, 2) : "";
      if (len == kUndefined) {
        const bool pixels = group == 0x7fe0 && elem == 0x0010;
        if (explicit_vr && vr != "SQ" && vr != "UN" && !(pixels && (vr == "OB" || vr == "OW"))) {
          At(at, "undefined length for VR '" + vr + "'");
          return false;
        }
        if (depth == 0 && pixels) encapsulated_ = true;
        size_t p = value_pos;
        // A sequence written as UN holds implicit VR little endian items (PS3.5 6.2.2).
        if (!WalkSequence(&p, kUndefined, explicit_vr && vr != "UN", pixels, depth)) return false;
        *pos = p;
        continue;
      }
      if (value_pos + len > end) {
        if (end == d_.size()) {
          Truncated(at, len);
        } else {
          At(at, "an element runs past the end of its sequence item");
        }
        return false;
      }
      // A sequence of defined length: SQ, or (implicit VR / UN) a value starting with an item.
      const bool sequence =
          vr == "SQ" || ((vr.empty() || vr == "UN") && len >= 8 && IsItemTag(value_pos));
      if (sequence) {
        size_t p = value_pos;
        if (!WalkSequence(&p, value_pos + len, explicit_vr && vr != "UN", false, depth))
          return false;
      }
      if (depth == 0 && group == 0x0028 && len >= 2) {
        // The first of duplicates counts, as in GDCM (DataSet::Insert keeps the first).
        if (elem == 0x0002 && samples_per_pixel_ < 0) samples_per_pixel_ = U16(value_pos);
        if (elem == 0x0100 && bits_allocated_ < 0) bits_allocated_ = U16(value_pos);
        if (elem == 0x0101 && bits_stored_ < 0) bits_stored_ = U16(value_pos);
      }
      *pos = value_pos + len;
    }
    if (scope == Scope::kItemUndefined) {
      At(*pos, "truncated: sequence item without its delimiter");
      return false;
    }
    return true;
  }

  // The items of a sequence from *pos: until the sequence delimiter (end == kUndefined) or filling
  // [*pos, end) exactly. `fragments`: encapsulated pixel data, whose items are bytes, not data
  // sets.
  bool WalkSequence(size_t* pos, size_t end, bool explicit_vr, bool fragments, int depth) {
    size_t p = *pos;
    while (end == kUndefined || p < end) {
      const size_t bound = end == kUndefined ? d_.size() : end;
      if (p + 8 > bound) {
        if (end == kUndefined) {
          At(p, "truncated element header");
        } else {
          At(p, "an item runs past the end of its sequence");
        }
        return false;
      }
      if (U16(p) != 0xfffe) {
        At(p, "expected an item in a sequence");
        return false;
      }
      const uint16_t elem = U16(p + 2);
      const size_t item_len = U32(p + 4), item_value = p + 8;
      if (elem == 0xe0dd && end == kUndefined) {
        if (item_len != 0) {
          At(p, "a sequence delimiter with a non-zero length");
          return false;
        }
        p = item_value;
        break;
      }
      if (elem != 0xe000) {
        char b[96];
        std::snprintf(b, sizeof(b), "an item or delimiter (fffe,%04x) out of place", elem);
        At(p, b);
        return false;
      }
      if (item_len == kUndefined) {
        if (fragments) {
          At(p, "a pixel data fragment of undefined length");
          return false;
        }
        p = item_value;
        if (!Walk(&p, d_.size(), explicit_vr, Scope::kItemUndefined, depth + 1)) return false;
        if (end != kUndefined && p > end) {
          At(p, "an item runs past the end of its sequence");
          return false;
        }
        continue;
      }
      if (item_value + item_len > bound) {
        if (end == kUndefined) {
          Truncated(p, item_len);
        } else {
          At(p, "an item runs past the end of its sequence");
        }
        return false;
      }
      if (!fragments) {
        size_t q = item_value;
        if (!Walk(&q, item_value + item_len, explicit_vr, Scope::kItemDefined, depth + 1))
          return false;
      }
      p = item_value + item_len;
    }
    *pos = p;
    return true;
  }

  const std::string& d_;
  DicomStructureInfo* info_;
  std::string error_;
  // From the top-level data set: (0028,0002), (0028,0100), (0028,0101) (-1: absent), and
  // whether (7fe0,0010) is encapsulated.
  int samples_per_pixel_ = -1, bits_allocated_ = -1, bits_stored_ = -1;
  bool encapsulated_ = false;
  bool big_endian_ = false;  // the data set's byte order (the file meta group is little endian)
};

}  // namespace

std::string CheckDicomStructure(const std::string& bytes, bool* is_dicom,
                                DicomStructureInfo* info) {
  return DicomWalker(bytes, info).Check(is_dicom);
}

}  // namespace carmba
