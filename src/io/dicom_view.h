// The nominal camera and pose of a DICOM X-ray frame, from its geometry tags (io/dicom_xray.h),
// through carmba's one C-arm conversion (camera/carm_geometry.h CamFromWorld,
// CameraFromDetector). A starting point: calibration and pose estimation replace it.
//
// SIGNS. DICOM's positioner angles (PS3.3 C.8.7.5.1.2) and CarmGeometry use the same convention,
// so the angles pass through unchanged (tests/sim/dicom_view_test.cc checks one file per sign):
//   * primary  > 0 = LAO: the detector towards the patient's left, the beam (camera z) gains +x
//     (LPS), the source moves to the patient's right (-x);
//   * secondary > 0 = cranial: the detector towards the head, the beam gains +z (superior), the
//     source moves towards the feet.
//
// FRAMES AND ASSUMPTIONS
//   * cam_from_patient maps the DICOM patient frame (LPS, mm) with its ORIGIN AT THE ISOCENTRE to
//     carmba's camera frame: the file does not say where the isocentre is in the patient, so a
//     patient-frame position is only known up to that offset. The positioner angles are defined
//     relative to the patient, so the rotation holds for any patient position on the table.
//   * The image is taken as seen from the source (CarmGeometry's camera: at 0 / 0, image x =
//     patient right, image y = feet). A file whose pixels are stored mirrored (as seen from the
//     detector) needs its image flipped first. When the file has Patient Orientation (0020,0020)
//     (the patient directions of the image's +x and +y, letters L R A P H F), each axis whose
//     nominal direction lies within 25 deg of a patient axis is checked against its first letter;
//     a disagreement is a warning (e.g. "image x points L in Patient Orientation (0020,0020)
//     'L\F', R in the nominal pose: the image is mirrored or the angles are not the image's"),
//     not an error: the pose is still returned.
//   * No in-plane detector rotation (the XA Positioner Module has none), no central-ray offset.
//   * fx = SID / column spacing, fy = SID / row spacing (Imager Pixel Spacing (0018,1164) is
//     "row\column"), cx, cy = the image centre; no distortion.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "camera/camera.h"
#include "camera/carm_geometry.h"
#include "io/dicom_xray.h"
#include "util/status.h"

namespace carmba {

struct NominalDicomView {
  // Needs both positioner angles and the source-to-patient distance: SOD (0018,1111), or else
  // SID / Estimated Radiographic Magnification Factor (0018,1114).
  std::optional<Rigid3> cam_from_patient;
  // Needs SID and Imager Pixel Spacing: fx, fy, cx, cy (no distortion), width x height px.
  std::optional<Camera> camera;
  // The tags that were absent and left a part out, e.g. "Distance Source to Patient (0018,1111)".
  std::vector<std::string> missing;
  // Disagreements between Patient Orientation and the nominal pose (see above).
  std::vector<std::string> warnings;
};

// `name` (the view's name, e.g. file.dcm#frame2) prefixes the errors: secondary angle outside
// [-90, 90], SOD not smaller than SID (when both are present).
// `patient_orientation` is DicomXrayImage::patient_orientation ("" = not checked).
StatusOr<NominalDicomView> NominalViewFromDicom(const XrayFrameGeometry& geometry,
                                                int width_px,
                                                int height_px,
                                                const std::string& name,
                                                const std::string& patient_orientation = "");

}  // namespace carmba
