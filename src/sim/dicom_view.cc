#include "sim/dicom_view.h"

#include <cmath>

namespace carmba::sim {

StatusOr<NominalDicomView> NominalViewFromDicom(const XrayFrameGeometry& g,
                                                int width_px,
                                                int height_px,
                                                const std::string& name) {
  NominalDicomView out;
  if (g.secondary_angle_deg && std::fabs(*g.secondary_angle_deg) > 90.0) {
    return Status::Error(name + ": Positioner Secondary Angle " +
                         std::to_string(*g.secondary_angle_deg) +
                         " deg (with its increment), expected [-90, 90]");
  }
  if (g.sid_mm && g.sod_mm && !(*g.sod_mm < *g.sid_mm)) {
    return Status::Error(name + ": Distance Source to Patient (0018,1111) " +
                         std::to_string(*g.sod_mm) +
                         " mm is not smaller than Distance Source to Detector (0018,1110) " +
                         std::to_string(*g.sid_mm) + " mm");
  }
  if (!g.primary_angle_deg) out.missing.push_back("Positioner Primary Angle (0018,1510)");
  if (!g.secondary_angle_deg) out.missing.push_back("Positioner Secondary Angle (0018,1511)");
  if (!g.sod_mm) out.missing.push_back("Distance Source to Patient (0018,1111)");
  if (!g.sid_mm) out.missing.push_back("Distance Source to Detector (0018,1110)");
  if (!g.pixel_spacing_row_mm) out.missing.push_back("Imager Pixel Spacing (0018,1164)");
  if (g.primary_angle_deg && g.secondary_angle_deg && g.sod_mm) {
    CarmGeometry carm;
    carm.sod_mm = *g.sod_mm;
    // The detector distance does not enter the pose; any SID beyond the SOD passes Check().
    carm.sid_mm = g.sid_mm ? *g.sid_mm : 2 * *g.sod_mm;
    carm.primary_angle_deg = *g.primary_angle_deg;
    carm.secondary_angle_deg = *g.secondary_angle_deg;
    std::string err;
    if (!carm.Check(&err)) return Status::Error(name + ": " + err);
    out.cam_from_patient = CamFromWorld(carm);
  }
  if (g.sid_mm && g.pixel_spacing_row_mm && g.pixel_spacing_col_mm) {
    DetectorSpec d;
    d.width_px = width_px;
    d.height_px = height_px;
    d.pitch_x_mm = *g.pixel_spacing_col_mm;
    d.pitch_y_mm = *g.pixel_spacing_row_mm;
    std::string err;
    if (!d.Check(&err)) return Status::Error(name + ": " + err);
    out.camera = CameraFromDetector(d, *g.sid_mm);
  }
  return out;
}

}  // namespace carmba::sim
