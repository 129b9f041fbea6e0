// The simulator's model of C-arm flex (issue 14): a mobile C-arm sags under its own weight as it
// turns, so the source and detector shift by millimetres and the intrinsics depend on the
// positioner angles (a = primary, LAO +; b = secondary, cranial +; DICOM PS3.3 C.8.7.5):
//   cx(a, b) = cx0 + cx_primary_px sin(a) + cx_secondary_px sin(b)
//   cy(a, b) = cy0 + cy_primary_px (1 - cos a) + cy_secondary_px sin(b)
//   f(a, b)  = f0 (1 + f_primary (1 - cos a) + f_secondary sin(b))        (fx and fy alike)
// distortion unchanged. Magnitudes like the published ones (shared/notes/joint-ba.md): the
// principal point moves by several px with LAO/RAO (Daly et al. 2008: piercing point up to ~10 mm
// over the orbit; Gorges et al.: clearly with LAO/RAO, hardly with CRAN/CAUD), the focal length by
// a fraction of a percent (source / detector shifts of 6-8 mm at SID ~1000 mm). A rigid C-arm has
// all six at zero. This is the TRUTH model; the bundle adjustment's `smooth` model
// (ba/smooth_intrinsics.h) is a different, generic family (Fourier x polynomial).
#pragma once

#include <array>
#include <cmath>

#include "camera/camera_model.h"

namespace carmba {

struct CarmFlex {
  double cx_primary_px = 0;
  double cx_secondary_px = 0;
  double cy_primary_px = 0;
  double cy_secondary_px = 0;
  double f_primary = 0;    // relative
  double f_secondary = 0;  // relative

  bool Rigid() const {
    return cx_primary_px == 0 && cx_secondary_px == 0 && cy_primary_px == 0 &&
           cy_secondary_px == 0 && f_primary == 0 && f_secondary == 0;
  }
  // A flexing mobile C-arm with published-like magnitudes (the tests' and the study's default).
  static CarmFlex Typical() { return {6.0, 0.5, 2.5, 0.3, 0.004, 0.001}; }

  // The intrinsics at the angles (degrees) of a C-arm whose intrinsics at (0, 0) are `base`.
  std::array<double, kNumIntrinsics> Apply(const std::array<double, kNumIntrinsics>& base,
                                           double primary_deg,
                                           double secondary_deg) const {
    constexpr double kRad = 0.017453292519943295;
    const double a = primary_deg * kRad, b = secondary_deg * kRad;
    std::array<double, kNumIntrinsics> x = base;
    const double s = 1.0 + f_primary * (1.0 - std::cos(a)) + f_secondary * std::sin(b);
    x[kFx] *= s;
    x[kFy] *= s;
    x[kCx] += cx_primary_px * std::sin(a) + cx_secondary_px * std::sin(b);
    x[kCy] += cy_primary_px * (1.0 - std::cos(a)) + cy_secondary_px * std::sin(b);
    return x;
  }
};

}  // namespace carmba
