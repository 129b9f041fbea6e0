// Small GDCM helpers shared by the CT series reader and writer (ct/ct_volume_read.cc,
// ct_volume_write.cc) and the X-ray image reader and writer (io/dicom_xray.cc). Header-only: the
// modules that include it link GDCM.
#pragma once

#include <gdcmAttribute.h>
#include <gdcmDataSet.h>
#include <gdcmDicts.h>
#include <gdcmGlobal.h>
#include <gdcmTrace.h>
#include <gdcmTransferSyntax.h>

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "util/dicom_structure.h"

namespace carmba {

// GDCM's own warnings go to stderr; carmba's are Status messages.
inline void SilenceGdcm() {
  static const bool done = [] {
    gdcm::Trace::SetDebug(false);
    gdcm::Trace::SetWarning(false);
    gdcm::Trace::SetError(false);
    return true;
  }();
  (void)done;
}

namespace gdcm_util {

// A DICOM string value without its padding (trailing spaces / NULs) and leading spaces.
inline std::string Trim(std::string s) {
  while (!s.empty() && (s.back() == ' ' || s.back() == '\0')) s.pop_back();
  size_t b = 0;
  while (b < s.size() && s[b] == ' ') ++b;
  return s.substr(b);
}

// The string value of an element, or "" when absent or empty.
inline std::string GetString(const gdcm::DataSet& ds, uint16_t group, uint16_t element) {
  const gdcm::Tag tag(group, element);
  if (!ds.FindDataElement(tag)) return "";
  const gdcm::ByteValue* bv = ds.GetDataElement(tag).GetByteValue();
  if (!bv || bv->GetLength() == 0) return "";
  return Trim(std::string(bv->GetPointer(), bv->GetLength()));
}

// Sets a string element, padded to even length (NUL for UI, space otherwise).
inline void PutString(gdcm::DataSet* ds, uint16_t g, uint16_t e, gdcm::VR vr, std::string value) {
  if (value.size() % 2) value.push_back(vr == gdcm::VR::UI ? '\0' : ' ');
  gdcm::DataElement de(gdcm::Tag(g, e));
  de.SetVR(vr);
  de.SetByteValue(value.data(), static_cast<uint32_t>(value.size()));
  ds->Replace(de);
}

// Sets an unsigned short element.
template <uint16_t G, uint16_t E>
void PutUS(gdcm::DataSet* ds, uint16_t v) {
  gdcm::Attribute<G, E> a = {v};
  ds->Replace(a.GetAsDataElement());
}

// CheckDicomStructure, then the explicit VRs of the public elements against GDCM's dictionary:
// GDCM (as packaged by Debian, assertions on) aborts when it reads an element through its typed
// Attribute<> whose VR the dictionary does not allow (e.g. Bits Allocated written as LO; found by
// fuzz_dicom_xray). Repeating groups (50xx curves, 60xx overlays) are looked up as 5000 / 6000;
// private (odd) groups and elements the dictionary does not know are not checked. Returns "" when
// the file is sound, else what is wrong; *is_dicom as CheckDicomStructure.
inline std::string CheckDicomFile(const std::string& bytes, bool* is_dicom) {
  DicomStructureInfo info;
  std::string problem = CheckDicomStructure(bytes, is_dicom, &info);
  if (!problem.empty() || !*is_dicom) return problem;
  // A transfer syntax GDCM does not know makes it guess the data set's encoding.
  if (!info.transfer_syntax.empty() &&
      gdcm::TransferSyntax::GetTSType(info.transfer_syntax.c_str()) ==
          gdcm::TransferSyntax::TS_END) {
    std::string shown;
    for (char c : info.transfer_syntax.substr(0, 64)) shown += (c >= 0x20 && c < 0x7f) ? c : '?';
    return "unknown Transfer Syntax UID (0002,0010) '" + shown + "'";
  }
  const gdcm::Dict& dict = gdcm::Global::GetInstance().GetDicts().GetPublicDict();
  for (const DicomElementVr& e : info.explicit_vrs) {
    if (e.group % 2 == 1 || e.element == 0x0000) continue;  // private, group length
    uint16_t group = e.group;
    if ((group & 0xff00) == 0x5000 || (group & 0xff00) == 0x6000) group &= 0xff00;
    const gdcm::VR expected = dict.GetDictEntry(gdcm::Tag(group, e.element)).GetVR();
    if (expected == gdcm::VR::INVALID || expected == gdcm::VR::UN) continue;
    const char vr_text[3] = {e.vr[0], e.vr[1], 0};
    const gdcm::VR found = gdcm::VR::GetVRTypeFromFile(vr_text);
    if (found == gdcm::VR::INVALID || found == gdcm::VR::UN || expected.Compatible(found)) continue;
    char b[160];
    std::snprintf(b, sizeof(b), "at byte %zu: element (%04x,%04x) has VR '%s', expected %s",
                  e.pos, e.group, e.element, vr_text, gdcm::VR::GetVRString(expected));
    return b;
  }
  return "";
}

}  // namespace gdcm_util
}  // namespace carmba
