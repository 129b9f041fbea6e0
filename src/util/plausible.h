// Plausible ranges of outside input, stated once.
//
// Every number carmba reads from a file or a flag (camera.json, markers / observations CSV,
// problem, config, scene and study YAML, command-line flags) is checked against one of these
// ranges by the options' or data's Check(). A value outside is not a measurement of a C-arm: a
// typo, a unit slip (m for mm) or a corrupted file. Rejecting it up front with the key and the
// range beats a misleading failure deep inside the numerics (an absurd focal length made POSIT
// fail to undistort a pixel; a 25 m grid pitch made the plate pose undetermined).
//
// The bounds are generous: they must never reject legitimate data (a 1000 mm C-arm with a 0.1 mm
// pixel pitch, a webcam of OpenCV's sample photos, a simulated noise-free scene). Each says why.
// Messages print numbers with %g (FormatCompact), so an absurd 1e200 reads as 1e+200, never as a
// 200-digit number.
#pragma once

#include <string>

namespace carmba {

// A closed interval [lo, hi] with its unit ("" for none).
struct PlausibleRange {
  double lo;
  double hi;
  const char* unit;
};

namespace plausible {

// --- Images and cameras (camera.json, observations CSV, simulated detectors) -----------------
// Image width / height: DICOM's Rows and Columns are 16-bit; flat panels are <= 4k px.
inline constexpr PlausibleRange kImageSizePx{1, 65535, "px"};
// fx, fy = source-to-detector distance / pixel pitch: a C-arm (1000 mm / 0.1..0.4 mm) has
// 2500..10000 px, a webcam ~500 px; 1e6 px would be a 1 degree field of view over 16k px.
inline constexpr PlausibleRange kFocalPx{1, 1e6, "px"};
// cx, cy in image widths / heights from the image's left / top edge: an off-centre detector crop
// moves the principal point, but not by more than one image size beyond either edge.
inline constexpr PlausibleRange kPrincipalPointImageSizes{-1, 2, "image sizes"};
// k1, k2, p1, p2, k3 (OPENCV5, normalised coordinates): image intensifiers' pincushion and lens
// distortion give |k| < 10; a narrow field of view leaves k3 poorly determined, so a fit can reach
// large values harmlessly, hence a wide bound.
inline constexpr PlausibleRange kDistortion{-1e6, 1e6, ""};
// Standard deviation of an intrinsic in camera.json's covariance, in the intrinsic's unit (px or
// none): larger than the largest plausible value itself says nothing.
inline constexpr PlausibleRange kIntrinsicSigma{0, 1e6, ""};
// Pixels of one image (one frame), read from the file's header before anything is decoded: the
// largest flat panels are 4k x 4k (17 Mpx) and a 50 Mpx camera photo is the largest input seen;
// 1e8 px leaves twice that. Without the bound OpenCV decodes up to 2^30 px: a 30000 x 30000 PNG
// took 4.46 GB and 14 s before the detector even started.
inline constexpr PlausibleRange kImagePixels{1, 1e8, "px"};
// Decoded bytes of one image file (all frames and channels): 1 GiB is 1e8 px of 16-bit grey with
// room for a multi-frame run; a corrupt DICOM Rows / Columns / Number of Frames would otherwise
// ask for terabytes.
inline constexpr PlausibleRange kImageBytes{1, 1073741824.0, "bytes"};
// Pixel coordinates of an observation: 10 x the largest detector either way (points a little
// outside the image arise from extrapolated or legacy coordinates).
inline constexpr PlausibleRange kPixelCoordinatePx{-1e5, 1e5, "px"};

// Simulated detected photons per pixel (0 = noise-free): a fluoroscopy frame has 100..1000, a
// radiograph 1e4..1e5; beyond 1e9 the quantum noise is below a 16-bit grey level, and the Poisson
// sampler never returned for 1e300.
inline constexpr PlausibleRange kPhotonsPerPixel{0, 1e9, "photons"};
// Grey levels of a simulated image (white level, read noise, outside-field level): 16-bit images
// reach 65535; 1e6 leaves room for float output.
inline constexpr PlausibleRange kGreyLevel{0, 1e6, "grey levels"};

// --- Objects, CT, geometry ----------------------------------------------------------------------
// A coordinate of a marker or grid point (object or CT patient frame): 10 m either way, far
// beyond an operating table; a metre-for-millimetre slip lands outside.
inline constexpr PlausibleRange kCoordinateMm{-1e4, 1e4, "mm"};
// A thickness, margin or padding of a simulated object: 0 .. 10 m.
inline constexpr PlausibleRange kLengthMm{0, 1e4, "mm"};
// A distance of the C-arm geometry (source-to-detector, source-to-object, object distance): up
// to 10 m.
inline constexpr PlausibleRange kDistanceMm{1, 1e4, "mm"};
// The source-to-object distance of a C-arm (the marker detector's magnification fx / SOD): a
// C-arm's object sits 300..1000 mm from the source; below 50 mm it would be inside the tube
// housing, so a value in metres (0.6) is refused rather than turned into a 10x magnification.
inline constexpr PlausibleRange kSourceToObjectMm{50, 1e4, "mm"};
// An angle in degrees (C-arm view angles, expected validation angles): one turn either way.
inline constexpr PlausibleRange kAngleDeg{-360, 360, "deg"};
// Detector pixel pitch: flat panels and intensifier cameras have 0.1..1 mm; CT voxels 0.1..5 mm.
inline constexpr PlausibleRange kPixelPitchMm{1e-3, 10, "mm"};
// A CT marker's nominal diameter: fiducial spheres are 1..10 mm; 0.1 mm is below any CT voxel,
// 100 mm is not a marker.
inline constexpr PlausibleRange kMarkerDiameterMm{0.1, 100, "mm"};
// CT values: DICOM stores int16 after the rescale, -1024 HU is air.
inline constexpr PlausibleRange kHounsfield{-1024, 32767, "HU"};
// Number of markers in an object: the thesis has 9; 10000 is a bead phantom at most.
inline constexpr PlausibleRange kMarkerCount{0, 10000, ""};
// A distance tolerance or added sigma in mm (labelling tolerance, extra CT sigma): as a sigma.
inline constexpr PlausibleRange kToleranceMm{1e-6, 1e3, "mm"};
// Calibration grid pitch: plates use 5..50 mm, OpenCV's chessboards ~25 mm; below 0.1 mm the
// points are closer than a detector pixel, above 1 m the plate cannot fit the field of view.
inline constexpr PlausibleRange kGridSpacingMm{0.1, 1000, "mm"};
// Calibration grid rows / columns: at the >= 8 px pitch that detection needs, 1000 points in a
// row fill more than any detector.
inline constexpr PlausibleRange kGridRowsCols{2, 1000, ""};

// Distance of a calibration plate from the X-ray source (or camera), as solved: a C-arm's plate
// sits 300..1000 mm from the source, a camera's chessboard 200..3000 mm. Outside 100 .. 5000 mm the
// grid pitch is wrong, most often by a unit (2 for 20 mm put a 20 mm-pitch plate at 78 mm; 200
// would put it at 7.8 m): the solve is consistent at any scale, only the pitch fixes the distance.
inline constexpr PlausibleRange kPlateDistanceMm{100, 5000, "mm"};

// Views of a (synthetic) calibration: 1000 views calibrate in 73 ms; 1e5 is a day of images.
inline constexpr PlausibleRange kViews{1, 1e5, ""};

// --- Noise and solver settings
// --------------------------------------------------------------------- Pixel noise sigma (problem
// sigma_px, calibration pixel_sigma_px, study noise): a simulated noise-free scene still needs a
// positive sigma to whiten residuals (1e-6 px); more than 1000 px is not a measurement.
inline constexpr PlausibleRange kPixelSigmaPx{1e-6, 1e3, "px"};
// CT marker sigma (problem sigma_mm, study CT noise): 1e-6 mm (a fixed prior) .. 1 m.
inline constexpr PlausibleRange kCtSigmaMm{1e-6, 1e3, "mm"};
// Robust loss scale: from the smallest pixel sigma up to 1e4 px (a loss that is nearly trivial).
inline constexpr PlausibleRange kLossScalePx{1e-6, 1e4, "px"};
// Ceres' relative tolerances (function, gradient, parameter): 1 stops at once; below 1e-32 they
// are far below double precision (1e-16) and only mean "never stop on this test".
inline constexpr PlausibleRange kSolverTolerance{1e-32, 1, ""};
// A threshold in sigmas (outlier rejection): 3..5 is usual; 1e3 sigmas rejects nothing.
inline constexpr PlausibleRange kSigmaMultiple{1e-3, 1e3, ""};
// Solver iterations: a pose or calibration converges in tens; 1e6 is hours of a stuck solve.
inline constexpr PlausibleRange kMaxIterations{0, 1e6, ""};
// Threads / parallel jobs: more than 1024 is no machine carmba runs on (0 jobs = all cores).
inline constexpr PlausibleRange kThreads{1, 1024, ""};
inline constexpr PlausibleRange kJobs{0, 1024, ""};

}  // namespace plausible

// A number printed compactly with %g (6 significant digits): 1e+200, 2061.39, -0.5.
std::string FormatCompact(double v);

// "lo .. hi unit", e.g. "1 .. 1e+06 px".
std::string FormatRange(const PlausibleRange& range);

// True if `v` is finite and within `range`.
bool InRange(double v, const PlausibleRange& range);

// Checks `v` against `range`. On failure sets *error to
//   "<name>: expected <lo> .. <hi> <unit>, got <v>"
// (the caller prefixes the file and line) and returns false.
bool CheckRange(const std::string& name,
                double v,
                const PlausibleRange& range,
                std::string* error);
// For integers (counts, sizes): the value printed in full ("got 100000", not "1e+05").
bool CheckRange(const std::string& name, int v, const PlausibleRange& range, std::string* error);

}  // namespace carmba
