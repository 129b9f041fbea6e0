// Structural checks of DICOM files that need no DICOM library: the "DICM" marker, and a walk over
// the elements that finds truncation before a parser sees the file (GDCM, as packaged by Debian,
// aborts on an assertion for some truncated files). Used by the CT series reader (ct/ct_volume.h)
// and the X-ray image reader (io/dicom_xray.h).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace carmba {

// True when the file has the DICOM preamble: "DICM" at byte 128.
bool HasDicmMarker(const std::string& path);

// Walks the file meta group and the data set of a whole file's bytes (explicit or implicit VR
// little endian, nested sequences and encapsulated pixel data) and checks that every element's
// value lies within the file. Returns "" when the structure is sound, else what is wrong (e.g.
// "truncated: element (7fe0,0010) at byte 1234 needs 524288 bytes, the file has 2000").
// *is_dicom is false for data that does not look like DICOM at all (no preamble and no group
// 0002/0008 element at the start); then "" is returned. Explicit VR big endian is walked too;
// deflated data sets are refused.
// When info is given, it receives every element read with an explicit VR (file meta group, data
// set, sequence items) and the transfer syntax UID of the file meta group, for checks against a
// DICOM dictionary (gdcm_util::CheckDicomFile).
struct DicomElementVr {
  uint16_t group = 0, element = 0;
  char vr[2] = {0, 0};
  size_t pos = 0;  // the element's byte offset in the file
};
struct DicomStructureInfo {
  std::vector<DicomElementVr> explicit_vrs;
  std::string transfer_syntax;  // (0002,0010) without padding; "" without a file meta group
};
std::string CheckDicomStructure(const std::string& bytes, bool* is_dicom,
                                DicomStructureInfo* info = nullptr);

}  // namespace carmba
