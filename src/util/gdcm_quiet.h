// GDCM's own warnings go to stderr; carmba's are Status messages. Shared by the CT series reader
// and writer (ct/ct_volume_read.cc, ct_volume_write.cc) and the X-ray image reader (io/dicom_xray.cc).
#pragma once

#include <gdcmTrace.h>

namespace carmba {

inline void SilenceGdcm() {
  static const bool done = [] {
    gdcm::Trace::SetDebug(false);
    gdcm::Trace::SetWarning(false);
    gdcm::Trace::SetError(false);
    return true;
  }();
  (void)done;
}

}  // namespace carmba
