// Detection of an object's metal markers (spheres) in an X-ray view: blobs, not a grid.
//
// Pipeline per image (DetectMarkerBlobs):
//   1. Float grey levels and the field of view: the grid detector's steps (detect/detect_steps.h:
//      ToFloatGrey, FindFieldOfView with `fov` = DetectionOptions' roi / circle / auto mask).
//   2. Expected diameter D px: `diameter_px` [min, max], or `diameter_mm` x `px_per_mm` (the
//      nominal magnification at the object: focal length / source-to-object distance, i.e.
//      SID / SOD / detector pitch) within +-`diameter_tolerance`.
//   3. Contrast image: 1 - (the flat-fielded search image of the grid detector, over 2.4 D_max) /
//      255, the attenuation of features narrower than ~2.4 D_max; anatomy, fall-off, heel and
//      glare become 0. Its noise level s: 1.4826 MAD inside the field. Components above
//      max(4 s, 0.3 min_contrast) (8-connected) are the candidates.
//   4. Per candidate: its peak contrast and its half-peak region (the pixels of the component
//      above half its peak), split into connected pieces. Rejected, with the reason listed:
//        "low contrast"          peak < max(8 s, min_contrast) (bone edges, soft tissue, noise);
//        "too small" / "too large"   the half-peak piece's equivalent diameter outside
//                                  [D_min, D_max] (too large and round: other metal);
//        "elongated"             axis ratio > max_elongation and longer than 2.6 D_max
//                                  (a wire, a bone edge, a catheter);
//        "merged"                two markers overlapping: one piece with an axis ratio >
//                                  max_elongation (and axis extents more than 1.5 px apart:
//                                  a 3 x 4 pixel region is a small disc, not two; and, below
//                                  an axis ratio of 1.7, an area above 1.25 x the expected one:
//                                  a stretch the area does not show is a small disc's noise) or
//                                  an area
//                                  above merge_area_ratio x the expected one, up to twice the
//                                  diameter long; or two pieces of
//                                  one candidate whose centres are closer than merge_distance x D
//                                  (both flagged). A merged blob is never used: its centroid is
//                                  neither marker's. A piece so judged that is not stretched is
//                                  judged again on its own surroundings: its region above half
//                                  way from the median contrast on a ring 1-1.6 D about it to its
//                                  own peak, with only neighbours standing half the peak
//                                  threshold above their own surroundings. A marker on a plateau
//                                  of anatomy narrower than the flat field (the real-CT recall
//                                  scenes' sinuses and bone) is then one marker, not "merged";
//        "field-of-view border"  the blob's disc reaches the mask border;
//        "refinement failed"     no centroid, or the centroid moved by more than max(1.5 px, D/4)
//                                  from the piece's centre (pulled by an edge in its ring).
//   5. Sub-pixel centre: the calibration detector's centroid (RefineCentroid: flat-field contrast
//      over a disc, background plane on a ring), with the distance to the nearest other candidate
//      bounding its window, given the noise model of step 6 (so that the centre moves towards the
//      less noisy core centroid as far as the noise makes it the better estimate); then moved back
//      by the detector blur's pull towards the darker side of a sloping background
//      (correct_blur_pull; MarkerBlob::blur_correction_px).
//   6. Covariance (2x2, px^2) per centre from the local image noise (detect_steps.h
//      CentroidNoise): the ring's pixel noise, scaled for quantum noise inside the disc, with
//      the noise's correlation measured once per image from horizontal second differences at
//      lags 1 and 2 inside the field, which a linearly changing background does not reach
//      (their variance ratio is (6 - 8 rho^4 + 2 rho^16) / (6 - 8 rho + 2 rho^4) for a Gaussian
//      correlation rho^(k^2); F = sum over lags |k| <= 4 of rho^(kx^2 + ky^2); rho = 0, F = 1
//      for white noise; first differences took anatomy's gradients for correlated noise: rho
//      0.78 against the 0.5-0.68 of the recall scenes' 0.4-0.8 px blur). The ring's noise is
//      floored at half the image's pixel noise and an integer image's quantisation (a ring clipped
//      at the image's maximum has none to measure: a zero covariance would be an infinitely trusted
//      centre). Checked against a seeded Monte Carlo (tests/detect/marker_views_test.cc
//      MarkerBlobs.CovarianceAgreesWithMonteCarlo). Widened where an edge or a line is in the ring:
//      by the core-to-whole shift's part beyond its own noise (the same linear propagation gives
//      the shift's covariance) and beyond unreliable_shift_px, and by a share of the pull a line
//      across the ring can exert.
// Polarity: dark blobs (metal on a bright background, the X-ray convention of carmba's images).
#pragma once

#include <opencv2/core.hpp>

#include <string>
#include <vector>

#include "detect/grid_detector.h"

namespace carmba {

class YamlMap;

struct MarkerBlobOptions {
  // Expected diameter: [min, max] px, or (when empty) diameter_mm x px_per_mm +- tolerance.
  std::vector<double> diameter_px;
  double diameter_mm = 0;
  double px_per_mm = 0;  // focal length (px) / source-to-object distance (mm)
  double diameter_tolerance = 0.35;
  // Contrast (attenuation 1 - I / background) a marker reaches at least; 0 = noise-based only.
  double min_contrast = 0.05;
  double max_elongation = 1.3;    // axis ratio of a single marker's half-peak region
  double merge_area_ratio = 1.6;  // half-peak area / expected area above which it is two
  double merge_distance = 1.25;   // pieces closer than this x D are one merged blob
  // A centre whose core and whole-blob centroids are further apart than this (px), beyond what
  // the pixel noise explains (MarkerBlob::shift_beyond_noise_px), is widened by a share of the
  // excess.
  double unreliable_shift_px = 0.05;
  // Remove the blur's pull on each centre (MarkerBlob::blur_correction_px), with the blur's
  // variance taken from the noise's correlation (MarkerBlobDetection::blur_variance_px2).
  bool correct_blur_pull = true;
  // Field of view / region of interest (only roi_px, fov_circle_px, auto_fov_mask,
  // fov_margin_px are used).
  DetectionOptions fov;

  bool Check(std::string* error) const;
  // [min, max] expected diameter in px.
  std::pair<double, double> DiameterRangePx() const;
};
// Reads the keys above (names as fields; `fov` keys at the top level) from a YAML map.
void ReadMarkerBlobOptions(YamlMap& map, MarkerBlobOptions* options);

struct MarkerBlob {
  cv::Point2d uv_px;  // full-image pixel coordinates
  cv::Matx22d covariance_px2 = cv::Matx22d::zeros();
  double diameter_px = 0;  // half-contrast diameter
  double contrast = 0;     // peak attenuation
  // Distance between the blob's core and whole-blob centroids (RefineCentroid's shift_px): a
  // background edge or a wire across the marker, or noise. Where the part beyond the noise
  // (shift_beyond_noise_px) exceeds unreliable_shift_px its centre is not trusted to the noise
  // covariance: the covariance is widened by a share of (that part - unreliable_shift_px) per
  // axis (marker_blobs.cc kShiftRmsShare).
  double background_shift_px = 0;
  // The part of that shift the pixel noise does not explain (detect_steps.h ShiftBeyondNoise):
  // what the widening uses.
  double shift_beyond_noise_px = 0;
  // Added to the measured centre (included in uv_px): the detector blur's pull towards the darker
  // side of a sloping background, s^2 x the log background's gradient (MarkerBlobOptions::
  // correct_blur_pull).
  cv::Point2d blur_correction_px;
};

struct MarkerBlobDetection {
  bool ok = false;
  std::string reason;                  // why nothing could be detected (empty when ok)
  std::vector<MarkerBlob> blobs;       // accepted candidates
  std::vector<RejectedBlob> rejected;  // with the reason (grid_detector.h)
  double noise_contrast = 0;           // s of step 3
  double correlation_factor = 1;       // F of step 6
  double noise_rho1 = 0;               // rho of step 6 (neighbouring pixels' noise correlation)
  // The detector blur's variance per axis (px^2) that rho implies: noise blurred by a Gaussian
  // of variance s^2 has rho = exp(-1 / (4 s^2)); 0 for white noise, at most kMaxBlurVariancePx2.
  double blur_variance_px2 = 0;
  cv::Point2d fov_centre;
  double fov_radius = 0;               // 0: no circular field found
};

// The largest blur-pull correction among the detection's blobs (px; MarkerBlob::
// blur_correction_px).
double LargestBlurCorrectionPx(const MarkerBlobDetection& detection);

// Detects marker blobs in an image of any depth (CV_8U/CV_16U/CV_32F, 1 or 3 channels).
MarkerBlobDetection DetectMarkerBlobs(const cv::Mat& image, const MarkerBlobOptions& options);

// The noise correlation factor F of step 6 for a float image inside `mask`, and rho (`rho1`).
// `sigma_pixel`: the pixels' noise sigma (grey levels) from the same differences.
double NoiseCorrelationFactor(const cv::Mat& f, const cv::Mat& mask, double* rho1 = nullptr,
                              double* sigma_pixel = nullptr);

// The largest blur variance (px^2) taken from the noise's correlation: a Gaussian blur of
// sigma 2 px. A rho near 1 more likely means structure the differences did not remove.
constexpr double kMaxBlurVariancePx2 = 4.0;

// The blur variance per axis (px^2) of noise with neighbour correlation `rho1`, for noise blurred
// by a Gaussian: rho1 = exp(-1 / (4 s^2)); 0 for rho1 <= 0, at most kMaxBlurVariancePx2.
double BlurVarianceFromNoiseCorrelation(double rho1);

}  // namespace carmba
