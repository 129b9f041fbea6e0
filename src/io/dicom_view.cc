#include "io/dicom_view.h"

#include <cmath>

namespace carmba {

namespace {

// The patient-direction letter (LPS: +x L, +y P, +z H) of a unit direction within 25 deg of a
// patient axis, else 0.
char DirectionLetter(const Eigen::Vector3d& d) {
  static const char kPlus[3] = {'L', 'P', 'H'}, kMinus[3] = {'R', 'A', 'F'};
  int axis = 0;
  d.cwiseAbs().maxCoeff(&axis);
  if (std::fabs(d(axis)) < std::cos(25.0 * M_PI / 180.0)) return 0;
  return d(axis) > 0 ? kPlus[axis] : kMinus[axis];
}

}  // namespace

StatusOr<NominalDicomView> NominalViewFromDicom(const XrayFrameGeometry& g,
                                                int width_px,
                                                int height_px,
                                                const std::string& name,
                                                const std::string& patient_orientation) {
  NominalDicomView out;
  std::optional<double> sod_mm = g.sod_mm;
  if (!sod_mm && g.sid_mm && g.magnification) {
    if (!(*g.magnification > 1)) {
      return Status::Error(name + ": Estimated Radiographic Magnification Factor (0018,1114) " +
                           std::to_string(*g.magnification) + ", expected > 1 (SID / SOD)");
    }
    sod_mm = *g.sid_mm / *g.magnification;
  }
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
  if (!sod_mm) out.missing.push_back("Distance Source to Patient (0018,1111)");
  if (!g.sid_mm) out.missing.push_back("Distance Source to Detector (0018,1110)");
  if (!g.pixel_spacing_row_mm) out.missing.push_back("Imager Pixel Spacing (0018,1164)");
  if (g.primary_angle_deg && g.secondary_angle_deg && sod_mm) {
    CarmGeometry carm;
    carm.sod_mm = *sod_mm;
    // The detector distance does not enter the pose; any SID beyond the SOD passes Check().
    carm.sid_mm = g.sid_mm ? *g.sid_mm : 2 * *sod_mm;
    carm.primary_angle_deg = *g.primary_angle_deg;
    carm.secondary_angle_deg = *g.secondary_angle_deg;
    std::string err;
    if (!carm.Check(&err)) return Status::Error(name + ": " + err);
    out.cam_from_patient = CamFromWorld(carm);
    const size_t sep = patient_orientation.find('\\');
    if (!patient_orientation.empty() && sep != std::string::npos && sep > 0 &&
        sep + 1 < patient_orientation.size()) {
      const char given[2] = {patient_orientation[0], patient_orientation[sep + 1]};
      const char* axis_name[2] = {"x", "y"};
      for (int a = 0; a < 2; ++a) {
        const char nominal = DirectionLetter(out.cam_from_patient->R.row(a).transpose());
        if (nominal != 0 && given[a] != nominal) {
          out.warnings.push_back(
              name + ": image " + axis_name[a] + " points " + given[a] +
              " in Patient Orientation (0020,0020) '" + patient_orientation + "', " + nominal +
              " in the nominal pose: the image is mirrored or the angles are not the image's");
        }
      }
    }
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

}  // namespace carmba
