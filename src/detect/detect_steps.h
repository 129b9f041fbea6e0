// Steps of the grid detector (detect/grid_detector.h, "Pipeline per image") shared with the marker
// blob detector (detect/marker_blobs.h): one implementation of the float conversion, the field of
// view, the flat-fielded search image and the sub-pixel centroid.
#pragma once

#include <opencv2/core.hpp>

#include <string>

#include "detect/grid_detector.h"

namespace carmba {

// Step 1a: the (cropped, `o.roi_px`) image as CV_32F grey levels; `offset` is the crop's corner.
// False with the reason for an empty image or one without contrast.
bool ToFloatGrey(const cv::Mat& image, const DetectionOptions& o, cv::Mat* f, cv::Point* offset,
                 std::string* reason);

// Step 2: the field of view (grid_detector.h step 2).
struct FieldOfView {
  cv::Mat mask;              // CV_8U, 255 inside the field (shrunk by the margin)
  bool have_circle = false;  // the circle is known (given, or found)
  cv::Point2d centre;
  double radius = 0;
  cv::Mat refine_valid;      // the fully exposed part of the mask (sub-pixel refinement)
};
FieldOfView FindFieldOfView(const cv::Mat& f, const DetectionOptions& o, cv::Point offset);

// 255 x the ratio of the lightly blurred image to its morphological closing over ~2.4 blob
// diameters (CV_8U; 255 outside `mask`): dark blobs keep their contrast wherever they lie.
cv::Mat FlatFieldedSearchImage(const cv::Mat& f, const cv::Mat& mask, double blob_diameter_px);

// The noise of a centroid (RefineCentroid's optional output). Given, it also moves the centre
// towards the less noisy core centroid as far as the noise makes that the better estimate (see
// grid_detector.cc above RefineCentroid, "centre").
//   in:  rho1, the correlation of neighbouring pixels' noise, the correlation at lag (dx, dy)
//        taken as rho1^(dx^2 + dy^2) (white noise blurred by a Gaussian; 0 = white), used up to
//        |dx|, |dy| <= 3; correlation_factor F = the sum of that correlation over all lags (the
//        plane's variance from the ring's many pixels is F times the white-noise one).
//   out: covariance_px2, the 2x2 covariance of the centre from the pixel noise of the disc
//        (sum_ij g_i g_j^T rho(i - j), exact for the disc's weights and their cut-off; the
//        core's weights are those of its interpolated sub-samples) and the noise of the
//        background plane fitted to the ring (first order, the disc, the 5 % floor and the
//        centre's share of the core held), with the pixel variance sigma_gray^2 measured on the
//        ring (1.4826 MAD of the plane's residuals) and, for dark blobs, scaled by I / background
//        (quantum noise); sigma_gray; peak_contrast (dark: the largest attenuation 1 - I /
//        background); background (the plane's level at the centre).
struct CentroidNoise {
  double rho1 = 0.0;
  double correlation_factor = 1.0;
  // Input: the least sigma_gray the covariance uses, sqrt(max(floor_variance_per_grey x
  // background, floor_variance_gray)). A ring with no noise to measure (clipped at the image's
  // maximum, e.g. saturated skin edges of an 8-bit radiograph) must not give a zero covariance;
  // the marker detector sets them from the image's quantum noise (a quarter of its variance at
  // the ring's level) and an integer image's quantisation (1/12 grey^2).
  double floor_variance_per_grey = 0.0;
  double floor_variance_gray = 0.0;
  cv::Matx22d covariance_px2 = cv::Matx22d::zeros();
  // Out: the part of the core-to-whole shift that noise does not explain (ShiftBeyondNoise, from
  // the shift vector's covariance under the same pixel noise), px.
  double shift_beyond_noise_px = 0;
  double sigma_gray = 0;
  double peak_contrast = 0;
  double background = 0;
  // Out: how many separate arcs of the ring hold pixels of the blob's own polarity more than 2.5
  // ring sigmas beyond the background plane (at least 3 pixels each, arcs apart by more than
  // 30 deg): a line across the ring (a wire) makes two, an edge or a neighbour's tail one.
  int ring_arcs = 0;
  // Out: the mean contrast of the ring's pixels beyond 2.5 sigmas (in peak_contrast's units), and
  // the width of a line that would leave the arcs: their pixels over (arcs x the ring's radial
  // width), px.
  double ring_arc_contrast = 0;
  double ring_arc_width_px = 0;
  // Out: the gradient of the log of the ring's background plane at the centre (1/px): where the
  // background is not flat, a detector blur of variance s^2 moves a dark blob's contrast profile
  // (1 - I / background) by -s^2 x this gradient, towards the darker side.
  cv::Vec2d log_background_gradient = cv::Vec2d(0, 0);
};

// The whole-blob centroid's weights are the contrast minus this fraction of the blob's peak,
// clipped at zero. The floor trades the low-contrast tails' noise and the centroid's sub-pixel
// phase error (an S-curve over the blob's position on the pixel grid, fixed for a fixed geometry)
// against robustness where anatomy crosses the blob:
// - the calibration plate's spheres on their smooth plate: 15 %. Against 5 %, the centres'
//   noise-driven scatter is 17-18 % smaller (tests/detect/simulated_scene_test.cc: thesis 0.0284 ->
//   0.0236 px, pincushion 0.0164 -> 0.0135 px RMS) and the noise-free error the same (0.0036,
//   0.0045 px); over 21 noise seeds of the thesis joint scene's plate views, a radial-only
//   calibration's cy is off by -0.12 sigma on average instead of -0.56;
// - markers on anatomy: 5 % (15 % labelled markers wrong on the recall sets).
constexpr double kPlateCentroidFloor = 0.15;
constexpr double kMarkerCentroidFloor = 0.05;

// The part of a core-to-whole shift (px) that the pixel noise does not explain: noise alone
// makes a shift vector (core centroid - whole-blob centroid) of covariance `shift_covariance_px2`
// (propagated like the centre's: grid_detector.cc CentroidCovariance), whose squared length
// exceeds kShiftNoiseQuantile x its trace in about 5 % of blobs on a clean background; what lies
// beyond that, in quadrature, is the background's (an edge or a wire across the disc).
constexpr double kShiftNoiseQuantile = 3.0;  // chi2(2) at 95 % over 2
double ShiftBeyondNoise(double shift_px, const cv::Matx22d& shift_covariance_px2);

// Sub-pixel centre of a blob around `c` on the float image `f` (grid_detector.cc documents the
// window, disc, ring and weights): only pixels with `valid` != 0 are used; `nn_px` the distance to
// the nearest other blob, `disc_px` the largest centroid disc wanted, `floor` the weights' floor
// (above). `r_half_px`: the blob's half-contrast radius. False when no blob is there or the
// disc/ring reaches the invalid area.
bool RefineCentroid(const cv::Mat& f,
                    const cv::Mat& valid,
                    bool dark,
                    double nn_px,
                    double disc_px,
                    double floor,
                    cv::Point2d* c,
                    double* r_half_px,
                    CentroidNoise* noise = nullptr,
                    double* shift_px = nullptr);

// The image as one grey channel: BGR and BGRA converted, grey images as they are (no copy).
cv::Mat GreyImage(const cv::Mat& image);

}  // namespace carmba
