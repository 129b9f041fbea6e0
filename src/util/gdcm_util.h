// Small GDCM helpers shared by the CT series reader and writer (ct/ct_volume_read.cc,
// ct_volume_write.cc) and the X-ray image reader and writer (io/dicom_xray.cc). Header-only: the
// modules that include it link GDCM.
#pragma once

#include <gdcmAttribute.h>
#include <gdcmDataSet.h>
#include <gdcmTrace.h>

#include <cstdint>
#include <string>

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

}  // namespace gdcm_util
}  // namespace carmba
