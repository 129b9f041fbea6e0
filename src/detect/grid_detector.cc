#include "detect/grid_detector.h"
#include "detect/detect_steps.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "io/image_files.h"
#include "util/format.h"
#include "util/plausible.h"
#include "util/yaml_reader.h"

namespace carmba {

bool DetectionOptions::Check(std::string* error) const {
  if (polarity != "dark" && polarity != "bright" && polarity != "auto") {
    *error = "polarity: expected dark, bright or auto, got '" + polarity + "'";
    return false;
  }
  namespace pl = plausible;
  if (!roi_px.empty() && (roi_px.size() != 4 || roi_px[2] <= 0 || roi_px[3] <= 0)) {
    *error = "roi_px: expected [x, y, w, h] with w, h > 0";
    return false;
  }
  for (size_t i = 0; i < roi_px.size(); ++i) {
    if (!CheckRange("roi_px: element " + std::to_string(i), roi_px[i], pl::kPixelCoordinatePx,
                    error)) {
      return false;
    }
  }
  if (!fov_circle_px.empty() && (fov_circle_px.size() != 3 || !(fov_circle_px[2] > 0))) {
    *error = "fov_circle_px: expected [cx, cy, r] with r > 0";
    return false;
  }
  for (size_t i = 0; i < fov_circle_px.size(); ++i) {
    if (!CheckRange("fov_circle_px: element " + std::to_string(i), fov_circle_px[i],
                    pl::kPixelCoordinatePx, error)) {
      return false;
    }
  }
  if (!(min_blob_area_px > 0) || !(max_blob_area_px > min_blob_area_px)) {
    *error = "blob area: expected 0 < min_blob_area_px < max_blob_area_px";
    return false;
  }
  // Blob areas and the margin are bounded by the largest image.
  const PlausibleRange area{0, pl::kImageSizePx.hi * pl::kImageSizePx.hi, "px^2"};
  const PlausibleRange margin{0, pl::kImageSizePx.hi, "px"};
  if (!CheckRange("min_blob_area_px", min_blob_area_px, area, error) ||
      !CheckRange("max_blob_area_px", max_blob_area_px, area, error) ||
      !CheckRange("fov_margin_px", fov_margin_px, margin, error)) {
    return false;
  }
  return true;
}

void ReadFieldOfViewOptions(YamlMap& m, DetectionOptions* o) {
  m.Get("roi_px", &o->roi_px);
  m.Get("fov_circle_px", &o->fov_circle_px);
  m.Get("auto_fov_mask", &o->auto_fov_mask);
  m.GetNonNegative("fov_margin_px", &o->fov_margin_px);
}

void ReadDetectionOptions(YamlMap& m, DetectionOptions* o) {
  m.GetEnum("polarity", {"dark", "bright", "auto"}, &o->polarity);
  ReadFieldOfViewOptions(m, o);
  m.GetPositive("min_blob_area_px", &o->min_blob_area_px);
  m.GetPositive("max_blob_area_px", &o->max_blob_area_px);
  m.Get("refine", &o->refine);
}

Status LoadDetectionOptions(const std::string& path, DetectionOptions* options) {
  YamlMap m = YamlMap::Load(path);
  CARMBA_RETURN_IF_ERROR(m.status());
  ReadDetectionOptions(m, options);
  CARMBA_RETURN_IF_ERROR(m.Finish());
  std::string err;
  if (!options->Check(&err)) return Status::Error(path + ": " + err);
  return Status::Ok();
}

// Sub-pixel centre of a blob around `c` on the float image `f` (see the header, step 4). Only
// pixels with `valid` != 0 (the field of view) are used. `nn_px` is the distance to the nearest
// other grid point: the window, the centroid disc and the background ring scale with it and with
// the blob's own measured radius, so that they hold for any circle size up to nearly touching
// circles. `disc_px`: the largest centroid disc wanted when the blob's tails allow (noise).
//   size:       the blob's half-contrast area in a window of half-size 0.5 nn_px (for circles
//               that do not overlap it holds the blob and background only), the background level
//               being the median of the window's 2 px border band (between the blob and its
//               neighbours; robust to a field-of-view edge or a plate edge), gives its radius
//               r_half. The centroid disc is rho = r_half + t with the blur's tails
//               t = 0.5 r_half + 2 px, but the disc within disc_px (noise) as long as the tails
//               stay >= 1 px, the background ring rho .. rho + 3 px; when the ring would
//               reach the neighbours' blobs (their half-contrast edge at nn_px - r_half, minus
//               their tails), t and the ring width shrink to fit the gap (at least 1 and 2 px).
//   background: a plane I = a + b (x - cx) + c (y - cy) fitted to the ring, refitted once without
//               the pixels more than 3 robust sigmas off (a neighbouring blob, an edge).
//   weights:    dark (X-ray): the flat-field contrast 1 - I / plane, i.e. the attenuation, which
//               does not depend on the local brightness (vignetting, heel effect, plate
//               thickness would otherwise pull the centre towards the brighter side); bright:
//               I - plane. Minus a floor of the peak (15 % on the plate, 5 % for markers:
//               detect_steps.h kPlateCentroidFloor), clipped at zero.
//   core:       the centroid of the contrast above 25 % of the peak, with the contrast interpolated
//               bilinearly between the pixel centres and sampled 4 x 4 times per pixel (the
//               pixels' own clipped values lock the centroid to the pixel grid: an S-curve of
//               up to +-0.05 px over the pixel for a 4.5 px disc, noise-free, against +-0.013 px
//               interpolated; tests/detect/grid_detector_test.cc RefineCentroidPhase).
//               Background structure inside the disc that the ring's plane does not follow (an
//               anatomical edge across the sphere: a few % of the level) pulls the whole-blob
//               centroid through the wide, low-contrast tails; the core, many times the
//               background's error in contrast, hardly moves. It is also the less noisy of the
//               two (about half the whole-blob centroid's variance on 4.5-7 px discs).
//   centre:     (1 - t) whole + t core. The shift rule: t goes from 0 to 1 as the two part from
//               0.03 to 0.06 px (`shift_px`: their distance at the end; a large one flags a
//               centre still unreliable). With a noise model (`noise` given) t is at least the
//               share that minimises the centre's expected squared error from the pixel noise
//               (both centroids' covariances and their correlation, propagated as for the
//               covariance below) and the two centroids' phase errors (kPhaseErrorWholePx,
//               kPhaseErrorCorePx): on a smooth, nearly noise-free background the whole-blob
//               centroid is kept (its phase error is the smaller, ~0.003 px against ~0.008 px),
//               on noisy images the centre moves most of the way to the core.
// Iterated until the centre moves less than 1e-3 px.
namespace {
// The core centroid (RefineCentroid "core"): contrast above this fraction of the peak, sampled
// kCoreSubsamples x kCoreSubsamples times per pixel.
constexpr double kCoreFloor = 0.25;
constexpr int kCoreSubsamples = 4;
// The centre moves from the whole-blob centroid to the core centroid as their distance goes from
// kBlendFromPx to kBlendToPx (on smooth backgrounds the distance is ~0.01 px, 99 % below
// ~0.06 px with the pixel noise of the recall scenes: tests/detect/edge_accuracy_test.cc).
constexpr double kBlendFromPx = 0.03, kBlendToPx = 0.06;
// The centroids' sub-pixel phase errors (RMS per axis over the blob's position on the pixel grid,
// noise-free, discs of 4.5-8 px: tests/detect/grid_detector_test.cc
// CentroidPhaseErrorOverThePixel): whole blob (5 % floor) 0.002-0.004 px, interpolated core
// 0.006-0.009 px.
constexpr double kPhaseErrorWholePx = 0.003, kPhaseErrorCorePx = 0.008;
}  // namespace

namespace {

// A pixel of the disc or the ring around a blob centre.
struct CentroidPixel {
  int ex, ey;   // offset from the rounded centre
  float value;  // grey level (disc: then contrast)
};

// The scan geometry around a blob: the disc's radius rho, the ring's width, the half-size of
// the pixel box scanned.
struct CentroidWindow {
  double r_half = 0, rho = -1, ring_width = 3;
  int rw = 0;
};

// The blob's half-maximum radius from the window of half-size w around (cx, cy), and from it the
// disc and ring: the tails and ring fit between the blob (edge r_half) and its neighbours (edge
// nn_px - r_half), the disc no larger than needed (the centroid's noise grows with its area):
// within disc_px while the tails stay >= 1 px. False when there is no blob.
bool SizeCentroidWindow(const cv::Mat& f,
                        const cv::Mat& valid,
                        bool dark,
                        double nn_px,
                        double disc_px,
                        int cx,
                        int cy,
                        int w,
                        CentroidWindow* win) {
  if (cx < 0 || cy < 0 || cx >= f.cols || cy >= f.rows) return false;
  std::vector<float> vals, band;
  vals.reserve((2 * w + 1) * (2 * w + 1));
  band.reserve(16 * w + 8);
  float extreme = dark ? 1e30f : -1e30f;
  for (int y = std::max(0, cy - w); y <= std::min(f.rows - 1, cy + w); ++y) {
    const float* fr = f.ptr<float>(y);
    const uint8_t* vr = valid.ptr<uint8_t>(y);
    const bool edge_row = std::abs(y - cy) >= w - 1;
    for (int x = std::max(0, cx - w); x <= std::min(f.cols - 1, cx + w); ++x) {
      if (!vr[x]) continue;
      vals.push_back(fr[x]);
      if (edge_row || std::abs(x - cx) >= w - 1) band.push_back(fr[x]);
      extreme = dark ? std::min(extreme, fr[x]) : std::max(extreme, fr[x]);
    }
  }
  if (vals.size() < 9) return false;
  std::vector<float>& bg = band.size() >= 8 ? band : vals;
  std::nth_element(bg.begin(), bg.begin() + bg.size() / 2, bg.end());
  const float median = bg[bg.size() / 2];
  const float half = 0.5f * (median + extreme);
  int area = 0;
  for (float v : vals) area += dark ? v < half : v > half;
  if (area == 0 || !(dark ? median > extreme : median < extreme)) return false;
  const double r_half = std::sqrt(area / M_PI);
  win->r_half = r_half;
  const double gap = nn_px - 2.0 * r_half;
  double tail = std::max(1.0, std::min(0.5 * r_half + 2.0, disc_px - r_half));
  if (2.0 * tail + win->ring_width > gap) {
    win->ring_width = std::clamp(gap - 2.0, 2.0, 3.0);
    tail = std::max(1.0, 0.5 * (gap - win->ring_width));
  }
  win->rho = r_half + tail;
  win->rw = static_cast<int>(std::ceil(win->rho + win->ring_width));
  return win->rho >= 2.0;
}

// The disc (within rho of c) and ring pixels around the rounded centre (cx, cy); false when one
// is invalid (the disc or the ring reaches the field-of-view rim).
bool CollectDiscAndRing(const cv::Mat& f, const cv::Mat& valid, cv::Point2d c, int cx, int cy,
                        const CentroidWindow& win, std::vector<CentroidPixel>* disc,
                        std::vector<CentroidPixel>* ring) {
  const int rw = win.rw;
  const double ring_in2 = win.rho * win.rho,
               ring_out2 = (win.rho + win.ring_width) * (win.rho + win.ring_width);
  ring->clear();
  disc->clear();
  for (int y = cy - rw; y <= cy + rw; ++y) {
    const float* fr = f.ptr<float>(y);
    const uint8_t* vr = valid.ptr<uint8_t>(y);
    const double dy = y - c.y;
    for (int x = cx - rw; x <= cx + rw; ++x) {
      const double dx = x - c.x, d2 = dx * dx + dy * dy;
      if (d2 > ring_out2) continue;
      if (!vr[x]) return false;
      (d2 < ring_in2 ? *disc : *ring).push_back({x - cx, y - cy, fr[x]});
    }
  }
  return true;
}

double PlaneAt(const cv::Vec3d& plane, const CentroidPixel& q) {
  return plane[0] + plane[1] * q.ex + plane[2] * q.ey;
}

// The background plane on the ring, robustly refitted once when a ring pixel is off by more than
// 3 robust sigmas (1.4826 MAD, at least 1e-3 of the background level); the ring's robust sigma
// and normal matrix. False when the ring is too small or degenerate.
bool FitRingPlane(const std::vector<CentroidPixel>& ring, cv::Vec3d* plane, double* ring_sigma,
                  cv::Matx33d* ring_AtA) {
  *plane = cv::Vec3d(0, 0, 0);
  *ring_sigma = 0;
  double cut = 1e300;
  std::vector<float> res;
  for (int pass = 0; pass < 2; ++pass) {
    double s1 = 0, sx = 0, sy = 0, sxx = 0, sxy = 0, syy = 0, sv = 0, sxv = 0, syv = 0;
    for (const CentroidPixel& q : ring) {
      if (pass == 1 && std::fabs(q.value - PlaneAt(*plane, q)) > cut) continue;
      const double x = q.ex, y = q.ey, v = q.value;
      s1 += 1, sx += x, sy += y, sxx += x * x, sxy += x * y, syy += y * y;
      sv += v, sxv += x * v, syv += y * v;
    }
    const cv::Matx33d AtA(s1, sx, sy, sx, sxx, sxy, sy, sxy, syy);
    const cv::Vec3d Atb(sv, sxv, syv);
    if (s1 < 8 || !cv::solve(AtA, Atb, *plane, cv::DECOMP_CHOLESKY)) return false;
    *ring_AtA = AtA;
    if (pass == 1) break;
    res.clear();
    for (const CentroidPixel& q : ring)
      res.push_back(static_cast<float>(std::fabs(q.value - PlaneAt(*plane, q))));
    const float largest = *std::max_element(res.begin(), res.end());
    std::nth_element(res.begin(), res.begin() + res.size() / 2, res.end());
    *ring_sigma = 1.4826 * res[res.size() / 2];
    cut = std::max(3.0 * 1.4826 * res[res.size() / 2], 1e-3 * std::fabs((*plane)[0]));
    if (largest <= cut) break;  // nothing to drop: the refit would be the same plane
  }
  return true;
}

// The whole-blob and core centroids of the disc's contrast and the blend of the two that is the
// centre (see the header above RefineCentroid).
struct CentroidEstimate {
  double peak = 0, floor = 0, core_floor = 0;
  double sw = 0, hw = 0;           // weight sums of the whole blob and of the core
  // The core centroid's derivative with respect to each disc pixel's contrast (disc order),
  // times hw.
  std::vector<cv::Vec2d> core_gradient;
  cv::Point2d full, core, centre;
  double shift = 0, toward_core = 0;
  // The centre at the core's share t: (1 - t) full + t core.
  void BlendTowardCore(double t) {
    toward_core = t;
    centre = full + t * (core - full);
  }
};

// A linear function of the disc's pixels (a centroid): per pixel its
// derivative times the pixel's noise sigma relative to the ring's (g, on the window's grid of
// `side` x `side`), and its derivative with respect to the ring's background plane (G).
struct PixelSensitivity {
  std::vector<cv::Vec2d> g;
  int side = 0;
  cv::Matx23d G = cv::Matx23d::zeros();

  explicit PixelSensitivity(int s) : g(static_cast<size_t>(s) * s, cv::Vec2d(0, 0)), side(s) {}
  // Pixel `at` with derivative `a` with respect to its weight, dw/dI sqrt(var I) `scale` and
  // dw/dplane `dw_dp`.
  void Add(size_t at, const cv::Vec2d& a, double scale, const cv::Vec3d& dw_dp) {
    g[at] = a * scale;
    for (int j = 0; j < 3; ++j) G(0, j) += a[0] * dw_dp[j], G(1, j) += a[1] * dw_dp[j];
  }
};

// The whole-blob and the core centroid as linear functions of the disc's pixels.
struct DiscSensitivity {
  PixelSensitivity full, core;
};

// The covariances of the whole-blob and the core centroid and between them (cross = Cov(full,
// core)), per unit ring variance: the pixels', sum_ij g_i h_j^T rho(i - j) with the noise's
// correlation rho(dx, dy) = rho1^(dx^2 + dy^2), |d| <= 3 (g, h: PixelSensitivity::g, a_i dw/dI
// sqrt(var I_i / sigma^2)), and the ring plane's, Cov_p = (A^T A)^-1 per unit variance (the ring
// fit; `ring_inv`) scaled by the noise's correlation factor. Any combination of the two
// centroids follows from these three.
struct CentroidCovariances {
  cv::Matx22d full, core, cross;
  // Of (1 - t) full + t core.
  cv::Matx22d Blend(double t) const {
    return (1 - t) * (1 - t) * full + t * t * core + t * (1 - t) * (cross + cross.t());
  }
  // Of core - full.
  cv::Matx22d Difference() const { return full + core - cross - cross.t(); }
};

CentroidCovariances JointCovariances(const DiscSensitivity& ds,
                                     double rho1,
                                     double correlation_factor,
                                     const cv::Matx33d& ring_inv) {
  double rho[4];
  for (int k = 0; k < 4; ++k) rho[k] = std::pow(rho1, k * k);
  const int side = ds.full.side;
  const std::vector<cv::Vec2d>&f = ds.full.g, &c = ds.core.g;
  CentroidCovariances out{cv::Matx22d::zeros(), cv::Matx22d::zeros(), cv::Matx22d::zeros()};
  for (int y = 0; y < side; ++y) {
    for (int x = 0; x < side; ++x) {
      const size_t i = static_cast<size_t>(y * side + x);
      if (f[i] == cv::Vec2d(0, 0) && c[i] == cv::Vec2d(0, 0)) continue;
      // The correlated sums of the pixel's neighbours' sensitivities.
      cv::Vec2d fj_sum(0, 0), cj_sum(0, 0);
      for (int dy = -3; dy <= 3; ++dy) {
        if (y + dy < 0 || y + dy >= side) continue;
        for (int dx = -3; dx <= 3; ++dx) {
          if (x + dx < 0 || x + dx >= side) continue;
          const size_t j = static_cast<size_t>((y + dy) * side + x + dx);
          const double r = rho[std::abs(dx)] * rho[std::abs(dy)];
          fj_sum += r * f[j], cj_sum += r * c[j];
        }
      }
      out.full += f[i] * fj_sum.t();
      out.core += c[i] * cj_sum.t();
      out.cross += f[i] * cj_sum.t();
    }
  }
  const double F = correlation_factor;
  const cv::Matx23d &Gf = ds.full.G, &Gc = ds.core.G;
  out.full += F * Gf * ring_inv * Gf.t();
  out.core += F * Gc * ring_inv * Gc.t();
  out.cross += F * Gf * ring_inv * Gc.t();
  return out;
}

// c = sum w_i x_i / S, dc/dw_i = (x_i - c) / S (over w_i > floor for the whole blob; for the
// core the sub-samples' weights, each a bilinear combination of four pixels: InterpolatedCore). w_i
// depends on the pixel I_i and on the ring's plane p = (a, b, c): dark: w = 1 - I / bg, dw/dI = -1
// / bg, dw/dp = I / bg^2 [1, ex, ey], var I_i = sigma^2 I_i / bg_i (quanta); bright: dw/dI = 1,
// dw/dp = -[1, ex, ey], var I_i = sigma^2.
DiscSensitivity Sensitivities(const std::vector<CentroidPixel>& disc,
                              const CentroidEstimate& e,
                              const cv::Vec3d& plane,
                              bool dark,
                              int cx,
                              int cy,
                              int rw) {
  const int side = 2 * rw + 1;
  DiscSensitivity out{PixelSensitivity(side), PixelSensitivity(side)};
  for (size_t i = 0; i < disc.size(); ++i) {
    const CentroidPixel& q = disc[i];
    const bool in_full = q.value - e.floor > 0;
    const cv::Vec2d& core_gradient = e.core_gradient[i];
    if (!in_full && core_gradient == cv::Vec2d(0, 0)) continue;
    const double x = q.ex + cx, y = q.ey + cy;
    const double bg = PlaneAt(plane, q);
    const double I = dark ? bg * (1.0 - q.value) : q.value + bg;
    const double var_I = dark ? std::max(0.0, I / bg) : 1.0;
    const double scale = (dark ? -1.0 / bg : 1.0) * std::sqrt(var_I);
    const double s_p = dark ? I / (bg * bg) : -1.0;
    const cv::Vec3d dw_dp(s_p, s_p * q.ex, s_p * q.ey);
    const size_t at = static_cast<size_t>((q.ey + rw) * side + (q.ex + rw));
    if (in_full) out.full.Add(at, cv::Vec2d(x - e.full.x, y - e.full.y) / e.sw, scale, dw_dp);
    if (core_gradient != cv::Vec2d(0, 0)) out.core.Add(at, core_gradient / e.hw, scale, dw_dp);
  }
  return out;
}

// The noise-optimal share of the core in the centre, (1 - t) c_full + t c_core: the t that
// minimises the expected squared error from the pixel noise (covariances Vf of c_full and Vd of
// d = c_core - c_full: JointCovariances, per unit pixel variance, times sigma2) and the two
// centroids' sub-pixel phase errors (kPhaseErrorWholePx, kPhaseErrorCorePx per axis, taken as
// independent):
//   E|c_full + t d - c|^2 = tr Vf + 2 t tr C + t^2 tr Vd + 2 (1 - t)^2 pf^2 + 2 t^2 pc^2,
//   t = (2 pf^2 - tr C) / (tr Vd + 2 pf^2 + 2 pc^2),  C = Cov(c_full, d).
double NoiseOptimalCoreShare(const CentroidCovariances& unit, double sigma2) {
  const double vd = cv::trace(unit.Difference()) * sigma2;
  const double c = (cv::trace(unit.cross) - cv::trace(unit.full)) * sigma2;  // tr Cov(full, d)
  const double pf2 = kPhaseErrorWholePx * kPhaseErrorWholePx;
  const double pc2 = kPhaseErrorCorePx * kPhaseErrorCorePx;
  return std::clamp((2 * pf2 - c) / (vd + 2 * pf2 + 2 * pc2), 0.0, 1.0);
}

// The pixel variance the covariance uses: the ring's, at least the noise model's floors.
double PixelVariance(const CentroidNoise& noise, double ring_sigma, const cv::Vec3d& plane) {
  const double sigma =
      std::max(ring_sigma,
               std::sqrt(std::max(noise.floor_variance_per_grey * std::max(0.0, plane[0]),
                                  noise.floor_variance_gray)));
  return sigma * sigma;
}

// The centre's covariance (detect_steps.h CentroidNoise) from the centroids' covariances per unit
// pixel variance (JointCovariances) times sigma2: of the centre used, (1 - t) c_full + t c_core
// (t held), and of the core-to-whole shift c_core - c_full, with the part of the shift beyond it
// (ShiftBeyondNoise).
void CentroidCovariance(const CentroidCovariances& unit,
                        const CentroidEstimate& e,
                        const cv::Vec3d& plane,
                        double sigma2,
                        CentroidNoise* noise) {
  noise->shift_beyond_noise_px = ShiftBeyondNoise(e.shift, unit.Difference() * sigma2);
  noise->covariance_px2 = unit.Blend(e.toward_core) * sigma2;
  noise->sigma_gray = std::sqrt(sigma2);
  noise->peak_contrast = e.peak;
  noise->background = plane[0];
}

// The core centroid (offsets from the rounded centre) of the disc's contrast above `threshold`,
// the contrast interpolated bilinearly between the pixel centres (0 beyond the disc) and sampled
// kCoreSubsamples x kCoreSubsamples times per pixel; `weight` the sum of the sub-samples' weights
// (contrast - threshold) over kCoreSubsamples^2, `gradient` per disc pixel d(core)/d(contrast) x
// weight. False when no sub-sample is above the threshold.
bool InterpolatedCore(const std::vector<CentroidPixel>& disc,
                      double threshold,
                      cv::Point2d* core,
                      double* weight,
                      std::vector<cv::Vec2d>* gradient) {
  int R = 0;
  for (const CentroidPixel& q : disc) R = std::max({R, std::abs(q.ex), std::abs(q.ey)});
  const int side = 2 * R + 3;  // a margin of one pixel of zeros
  std::vector<int> index(static_cast<size_t>(side) * side, -1);
  const auto cell = [&](int ex, int ey) {
    return static_cast<size_t>((ey + R + 1) * side + (ex + R + 1));
  };
  for (size_t i = 0; i < disc.size(); ++i)
    index[cell(disc[i].ex, disc[i].ey)] = static_cast<int>(i);
  const auto value = [&](int ex, int ey) {
    const int i = index[cell(ex, ey)];
    return i < 0 ? 0.0 : static_cast<double>(disc[i].value);
  };
  // Each sub-sample (u, v) above the threshold with its weight, visited twice: the centroid,
  // then its gradient. The sub-samples of the pixels -R..R lie at the fractions (k + 0.5) / n of
  // the cells between neighbouring pixel centres (x0 .. x0 + 1); a cell whose four corners are
  // all at or below the threshold has none above it.
  constexpr int n = kCoreSubsamples;
  const auto for_each_sample = [&](const auto& visit) {
    for (int y0 = -R - 1; y0 <= R; ++y0) {
      for (int x0 = -R - 1; x0 <= R; ++x0) {
        const double c00 = value(x0, y0), c10 = value(x0 + 1, y0);
        const double c01 = value(x0, y0 + 1), c11 = value(x0 + 1, y0 + 1);
        if (std::max({c00, c10, c01, c11}) <= threshold) continue;
        for (int j = 0; j < n; ++j) {
          const double fy = (j + 0.5) / n;
          for (int i = 0; i < n; ++i) {
            const double fx = (i + 0.5) / n;
            const double beta[4] = {(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy};
            const double c = beta[0] * c00 + beta[1] * c10 + beta[2] * c01 + beta[3] * c11;
            if (c > threshold) visit(x0 + fx, y0 + fy, c - threshold, x0, y0, beta);
          }
        }
      }
    }
  };
  double w0 = 0, wx = 0, wy = 0;
  for_each_sample([&](double u, double v, double w, int, int, const double*) {
    w0 += w, wx += w * u, wy += w * v;
  });
  if (!(w0 > 0)) return false;
  *core = cv::Point2d(wx / w0, wy / w0);
  const double per_pixel = 1.0 / (n * n);
  *weight = w0 * per_pixel;
  gradient->assign(disc.size(), cv::Vec2d(0, 0));
  for_each_sample([&](double u, double v, double, int x0, int y0, const double* beta) {
    const cv::Vec2d d(u - core->x, v - core->y);
    const int corner[4][2] = {{x0, y0}, {x0 + 1, y0}, {x0, y0 + 1}, {x0 + 1, y0 + 1}};
    for (int k = 0; k < 4; ++k) {
      const int i = index[cell(corner[k][0], corner[k][1])];
      if (i >= 0) (*gradient)[i] += d * (beta[k] * per_pixel);
    }
  });
  return true;
}

// The disc's pixels as contrast against the plane, and the centroids; false without contrast.
bool DiscCentroids(std::vector<CentroidPixel>* disc,
                   const cv::Vec3d& plane,
                   bool dark,
                   int cx,
                   int cy,
                   double floor,
                   CentroidEstimate* e) {
  for (CentroidPixel& q : *disc) {
    const double bg = PlaneAt(plane, q);
    q.value = static_cast<float>(dark ? 1.0 - q.value / bg : q.value - bg);
    e->peak = std::max(e->peak, static_cast<double>(q.value));
  }
  if (!(e->peak > 0)) return false;
  e->floor = floor * e->peak, e->core_floor = kCoreFloor * e->peak;
  double sx = 0, sy = 0;
  for (const CentroidPixel& q : *disc) {
    const double w = q.value - e->floor;
    if (w <= 0) continue;
    e->sw += w, sx += w * (q.ex + cx), sy += w * (q.ey + cy);
  }
  cv::Point2d core;
  if (!(e->sw > 0) || !InterpolatedCore(*disc, e->core_floor, &core, &e->hw, &e->core_gradient))
    return false;
  e->full = cv::Point2d(sx / e->sw, sy / e->sw);
  e->core = core + cv::Point2d(cx, cy);
  e->shift = cv::norm(e->core - e->full);
  e->BlendTowardCore(std::clamp((e->shift - kBlendFromPx) / (kBlendToPx - kBlendFromPx), 0.0, 1.0));
  return true;
}

// CentroidNoise::ring_arcs and ring_arc_contrast for the ring about the centre `c` (ring offsets
// from (cx, cy)), and the pixels in the arcs.
struct RingArcs {
  int arcs = 0;
  int pixels = 0;  // in the arcs counted
  double contrast = 0;
};

RingArcs FindRingArcs(const std::vector<CentroidPixel>& ring,
                      const cv::Vec3d& plane,
                      double ring_sigma,
                      bool dark,
                      cv::Point2d c,
                      int cx,
                      int cy) {
  constexpr double kOutlierSigmas = 2.5, kArcGapRad = M_PI / 6;
  constexpr int kMinArcPixels = 3;
  RingArcs out;
  std::vector<double> angles;
  double contrast = 0;
  for (const CentroidPixel& q : ring) {
    const double bg = PlaneAt(plane, q), r = q.value - bg;
    if ((dark ? -r : r) > kOutlierSigmas * ring_sigma) {
      angles.push_back(std::atan2(q.ey + cy - c.y, q.ex + cx - c.x));
      contrast += dark ? -r / bg : r;  // as the disc's contrast (DiscCentroids)
    }
  }
  if (angles.size() < kMinArcPixels) return out;
  out.contrast = contrast / angles.size();
  std::sort(angles.begin(), angles.end());
  // Start after the largest gap (the circle's wrap-around included), so no arc is cut in two.
  const size_t n = angles.size();
  size_t start = 0;
  double widest = angles[0] + 2 * M_PI - angles[n - 1];
  for (size_t i = 1; i < n; ++i) {
    if (angles[i] - angles[i - 1] > widest) widest = angles[i] - angles[i - 1], start = i;
  }
  int in_arc = 1;
  for (size_t k = 1; k <= n; ++k) {
    const double prev = angles[(start + k - 1) % n], cur = angles[(start + k) % n];
    const double gap = std::remainder(cur - prev, 2 * M_PI);
    if (k == n || std::fabs(gap) > kArcGapRad) {
      if (in_arc >= kMinArcPixels) ++out.arcs, out.pixels += in_arc;
      in_arc = 1;
    } else {
      ++in_arc;
    }
  }
  return out;
}

}  // namespace

double ShiftBeyondNoise(double shift_px, const cv::Matx22d& shift_covariance_px2) {
  const double noise2 =
      kShiftNoiseQuantile * (shift_covariance_px2(0, 0) + shift_covariance_px2(1, 1));
  return std::sqrt(std::max(0.0, shift_px * shift_px - noise2));
}

bool RefineCentroid(const cv::Mat& f,
                    const cv::Mat& valid,
                    bool dark,
                    double nn_px,
                    double disc_px,
                    double floor,
                    cv::Point2d* c,
                    double* r_half_px,
                    CentroidNoise* noise,
                    double* shift_px) {
  const int w = std::max(3, static_cast<int>(std::ceil(0.5 * nn_px)));
  CentroidWindow win;
  win.rw = w;
  std::vector<CentroidPixel> ring, disc;
  for (int it = 0; it < 8; ++it) {
    const int cx = static_cast<int>(std::lround(c->x)), cy = static_cast<int>(std::lround(c->y));
    if (win.rho < 0) {
      if (!SizeCentroidWindow(f, valid, dark, nn_px, disc_px, cx, cy, w, &win)) {
        if (win.r_half > 0) *r_half_px = win.r_half;
        return false;
      }
      *r_half_px = win.r_half;
    }
    const int rw = win.rw;
    if (cx - rw < 0 || cy - rw < 0 || cx + rw >= f.cols || cy + rw >= f.rows) return false;
    if (!CollectDiscAndRing(f, valid, *c, cx, cy, win, &disc, &ring)) return false;
    cv::Vec3d plane;
    double ring_sigma = 0;
    cv::Matx33d ring_AtA;
    if (!FitRingPlane(ring, &plane, &ring_sigma, &ring_AtA)) return false;
    if (dark && !(plane[0] > 0)) return false;
    CentroidEstimate e;
    if (!DiscCentroids(&disc, plane, dark, cx, cy, floor, &e)) return false;
    if (shift_px) *shift_px = e.shift;
    if (noise) {
      // With a noise model the centre moves towards the less noisy core as far as its noise
      // and phase error make it the better estimate, or further by the shift rule.
      const CentroidCovariances unit =
          JointCovariances(Sensitivities(disc, e, plane, dark, cx, cy, rw), noise->rho1,
                           noise->correlation_factor, ring_AtA.inv(cv::DECOMP_CHOLESKY));
      const double sigma2 = PixelVariance(*noise, ring_sigma, plane);
      e.BlendTowardCore(std::max(e.toward_core, NoiseOptimalCoreShare(unit, sigma2)));
      CentroidCovariance(unit, e, plane, sigma2, noise);
      const double bg = plane[0] + plane[1] * (e.centre.x - cx) + plane[2] * (e.centre.y - cy);
      noise->log_background_gradient =
          bg > 0 ? cv::Vec2d(plane[1] / bg, plane[2] / bg) : cv::Vec2d(0, 0);
      const RingArcs arcs = FindRingArcs(ring, plane, noise->sigma_gray, dark, *c, cx, cy);
      noise->ring_arcs = arcs.arcs;
      noise->ring_arc_contrast = arcs.contrast;
      noise->ring_arc_width_px = arcs.arcs > 0 ? arcs.pixels / (arcs.arcs * win.ring_width) : 0.0;
    }
    const double move = std::hypot(e.centre.x - c->x, e.centre.y - c->y);
    *c = e.centre;
    if (move < 1e-3) break;
  }
  return true;
}

namespace {

// The radius (px from the field-of-view centre `c`) out to which an image intensifier's field is
// fully exposed: the median grey level of 1-px annuli follows the interior's trend (a line
// fitted to the annuli 45..25 px inside `r`, which carries the vignetting) to within 3 %; beyond
// it the rim falls off. `r` when no fall-off is seen or the field is too small to tell.
double FullyExposedRadius(const cv::Mat& f, cv::Point2d c, double r) {
  constexpr int kDepth = 45, kFit = 20;
  if (r < 2 * kDepth) return r;
  std::vector<std::vector<float>> bins(kDepth + 1);
  const double r_in = r - kDepth;
  const int y0 = std::max(0, static_cast<int>(c.y - r)),
            y1 = std::min(f.rows - 1, static_cast<int>(c.y + r) + 1);
  for (int y = y0; y <= y1; y += 2) {  // every second row: ~300+ pixels per annulus still
    const float* fr = f.ptr<float>(y);
    const double dy2 = (y - c.y) * (y - c.y);
    if (dy2 > r * r) continue;
    // The row's pixels in the annulus: |x - cx| in [w_in, w_out].
    const double w_out = std::sqrt(r * r - dy2),
                 w_in = dy2 < r_in * r_in ? std::sqrt(r_in * r_in - dy2) : 0;
    for (int side = -1; side <= 1; side += 2) {
      const double a = c.x + side * w_in, b = c.x + side * w_out;
      const int xa = std::max(0, static_cast<int>(std::floor(std::min(a, b))));
      const int xb = std::min(f.cols - 1, static_cast<int>(std::ceil(std::max(a, b))));
      for (int x = xa; x <= xb; ++x) {
        if (side < 0 ? x > c.x - w_in : x <= c.x + w_in) continue;  // the other side's interval
        const double d2 = (x - c.x) * (x - c.x) + dy2;
        if (d2 < r_in * r_in || d2 > r * r) continue;
        const int k = static_cast<int>(std::sqrt(d2) - r_in);
        if (k >= 0 && k <= kDepth) bins[k].push_back(fr[x]);
      }
    }
  }
  std::vector<double> med(kDepth + 1, 0.0);
  for (int k = 0; k <= kDepth; ++k) {
    if (bins[k].size() < 16) return r;
    std::nth_element(bins[k].begin(), bins[k].begin() + bins[k].size() / 2, bins[k].end());
    med[k] = bins[k][bins[k].size() / 2];
  }
  // Line through the interior annuli (least squares).
  double sk = 0, sm = 0, skk = 0, skm = 0;
  for (int k = 0; k <= kFit; ++k) sk += k, sm += med[k], skk += k * k, skm += k * med[k];
  const double n = kFit + 1, slope = (n * skm - sk * sm) / (n * skk - sk * sk);
  const double icept = (sm - slope * sk) / n;
  if (!(icept > 0)) return r;
  for (int k = kFit + 1; k <= kDepth; ++k) {
    if (med[k] < 0.97 * (icept + slope * k)) return r_in + k;
  }
  return r;
}

// True if every pixel within `radius` of `pt` is inside the image and set in `mask` (the
// distance from `pt` to the mask's border, outside the image included, exceeds `radius`).
bool ClearOfMaskBorder(const cv::Mat& mask, cv::Point2d pt, double radius) {
  const int x0 = static_cast<int>(std::floor(pt.x - radius)),
            x1 = static_cast<int>(std::ceil(pt.x + radius));
  const int y0 = static_cast<int>(std::floor(pt.y - radius)),
            y1 = static_cast<int>(std::ceil(pt.y + radius));
  const double r2 = radius * radius;
  for (int y = y0; y <= y1; ++y) {
    const double dy2 = (y - pt.y) * (y - pt.y);
    if (dy2 > r2) continue;
    const uint8_t* mr = (y >= 0 && y < mask.rows) ? mask.ptr<uint8_t>(y) : nullptr;
    for (int x = x0; x <= x1; ++x) {
      if ((x - pt.x) * (x - pt.x) + dy2 > r2) continue;
      if (!mr || x < 0 || x >= mask.cols || !mr[x]) return false;
    }
  }
  return true;
}

// Plate position of lattice node (row r, col c) in units of the spacing; r and c may lie outside
// the grid (the lattice's continuation).
cv::Point2f LatticeNode(const GridSpec& g, int r, int c) {
  if (g.pattern == GridPattern::kAsymmetricCircles) {
    return cv::Point2f(static_cast<float>(2 * c + ((r % 2) + 2) % 2), static_cast<float>(r));
  }
  return cv::Point2f(static_cast<float>(c), static_cast<float>(r));
}

// How far the lattice of a found grid continues among the detected blobs: rows x cols of the
// lattice (>= the grid's). Grows the lattice by one row or column at a time on each side: its
// nodes predicted by a homography fitted to the 3 nearest rows / columns found so far (local:
// lens distortion), a node found when a blob of about the grid's blob size lies within 0.25 x
// the pitch; a new line counts when at least 2 of its nodes and half of those in the field of
// view are found. Stray blobs (noise, other markers) rarely sit on lattice nodes, let alone on
// half a line of them.
cv::Size LatticeExtent(const GridSpec& g,
                       const std::vector<cv::Point2d>& pts,
                       const std::vector<int>& ids,
                       const std::vector<cv::KeyPoint>& blobs,
                       const cv::Mat& mask,
                       double pitch_px) {
  cv::Size extent(g.cols, g.rows);
  // A continuation needs at least 2 blobs beyond the grid's.
  if (static_cast<int>(blobs.size()) < g.NumPoints() + 2 || ids.empty()) return extent;
  const double tol = 0.25 * pitch_px;
  auto nearest = [&blobs](cv::Point2d q, double* dist) {
    int best = -1;
    double bd = 1e300;
    for (int k = 0; k < static_cast<int>(blobs.size()); ++k) {
      const double d = cv::norm(cv::Point2d(blobs[k].pt) - q);
      if (d < bd) bd = d, best = k;
    }
    *dist = bd;
    return best;
  };
  std::vector<float> sizes;
  struct Node {
    int r, c;
    cv::Point2f uv;
  };
  std::vector<Node> nodes;
  for (int id : ids) {
    nodes.push_back({id / g.cols, id % g.cols, cv::Point2f(pts[id])});
    double d;
    const int k = nearest(pts[id], &d);
    if (k >= 0 && d < tol) sizes.push_back(blobs[k].size);
  }
  float size = 0;
  if (!sizes.empty()) {
    std::nth_element(sizes.begin(), sizes.begin() + sizes.size() / 2, sizes.end());
    size = sizes[sizes.size() / 2];
  }
  int rmin = 0, rmax = g.rows - 1, cmin = 0, cmax = g.cols - 1;
  for (int round = 0; round < 64; ++round) {
    bool grew = false;
    for (int side = 0; side < 4; ++side) {
      // side 0 / 1: a new row above / below; 2 / 3: a new column left / right.
      const bool row = side < 2;
      const int line = side == 0   ? rmin - 1
                       : side == 1 ? rmax + 1
                       : side == 2 ? cmin - 1
                                   : cmax + 1;
      std::vector<cv::Point2f> plate, image;
      for (const Node& n : nodes) {
        if (std::abs((row ? n.r : n.c) - line) <= 3) {
          plate.push_back(LatticeNode(g, n.r, n.c));
          image.push_back(n.uv);
        }
      }
      if (plate.size() < 4) continue;
      const cv::Mat H = cv::findHomography(plate, image, 0);
      if (H.empty()) continue;
      std::vector<cv::Point2f> pred_plate;
      const int lo = row ? cmin : rmin, hi = row ? cmax : rmax;
      for (int k = lo; k <= hi; ++k)
        pred_plate.push_back(row ? LatticeNode(g, line, k) : LatticeNode(g, k, line));
      std::vector<cv::Point2f> pred;
      cv::perspectiveTransform(pred_plate, pred, H);
      int counted = 0;
      std::vector<Node> found;
      for (size_t i = 0; i < pred.size(); ++i) {
        const cv::Point2d q(pred[i]);
        if (!ClearOfMaskBorder(mask, q, 0.2 * pitch_px)) continue;
        ++counted;
        double d;
        const int k = nearest(q, &d);
        if (k < 0 || d > tol) continue;
        if (size > 0 && (blobs[k].size < 0.5f * size || blobs[k].size > 2.0f * size)) continue;
        const int other = lo + static_cast<int>(i);
        found.push_back({row ? line : other, row ? other : line, blobs[k].pt});
      }
      if (found.size() < 2 || 2 * static_cast<int>(found.size()) < counted) continue;
      nodes.insert(nodes.end(), found.begin(), found.end());
      if (side == 0) rmin = line;
      if (side == 1) rmax = line;
      if (side == 2) cmin = line;
      if (side == 3) cmax = line;
      grew = true;
    }
    if (!grew) break;
  }
  return cv::Size(cmax - cmin + 1, rmax - rmin + 1);
}

// A grid returned by cv::findCirclesGrid is taken only when its points are distinct (no two
// closer than half the median distance of row neighbours: OpenCV's clustering finder can repeat
// a column when a blob is missing) and lie on a lattice (a homography from the plate explains
// each to within 30 % of that distance, as the final check does). Otherwise the next finder, or
// the next search image, is tried.
bool PlausibleGrid(const std::vector<cv::Point2f>& pts, const GridSpec& g) {
  std::vector<double> steps;
  for (int r = 0; r < g.rows; ++r) {
    for (int c = 0; c + 1 < g.cols; ++c)
      steps.push_back(cv::norm(pts[r * g.cols + c + 1] - pts[r * g.cols + c]));
  }
  if (steps.empty()) return true;
  std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
  const double step = steps[steps.size() / 2];
  for (size_t i = 0; i < pts.size(); ++i) {
    for (size_t j = i + 1; j < pts.size(); ++j) {
      if (cv::norm(pts[i] - pts[j]) < 0.5 * step) return false;
    }
  }
  std::vector<cv::Point2f> plate;
  for (int id = 0; id < g.NumPoints(); ++id)
    plate.push_back(LatticeNode(g, id / g.cols, id % g.cols));
  const cv::Mat H = cv::findHomography(plate, pts, 0);
  if (H.empty()) return false;
  std::vector<cv::Point2f> mapped;
  cv::perspectiveTransform(plate, mapped, H);
  for (size_t i = 0; i < pts.size(); ++i) {
    if (cv::norm(mapped[i] - pts[i]) > 0.3 * step) return false;
  }
  return true;
}

}  // namespace

// The 8-bit search image for dark blobs with the slowly varying brightness divided out: 255 x
// the ratio of the (lightly blurred) image to its local background, the morphological closing of
// the image (its upper envelope over dark features narrower than ~2.4 blob diameters), computed
// on a half-resolution grid and smoothed. Image-intensifier fall-off, heel effect, glare and
// anatomy larger than the blobs become a flat level of 255; a sphere's level is its contrast,
// wherever it lies, so one set of thresholds finds spheres on bright and on dark parts of the
// field. Outside `mask`: 255.
cv::Mat FlatFieldedSearchImage(const cv::Mat& f, const cv::Mat& mask, double blob_diameter_px) {
  cv::Mat half, background;
  cv::resize(f, half, cv::Size((f.cols + 1) / 2, (f.rows + 1) / 2), 0, 0, cv::INTER_AREA);
  const int k = 2 * static_cast<int>(std::ceil(0.6 * std::max(blob_diameter_px, 2.0))) + 1;
  const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(k, k));
  cv::morphologyEx(half, background, cv::MORPH_CLOSE, kernel, cv::Point(-1, -1), 1,
                   cv::BORDER_REPLICATE);
  cv::blur(background, background, cv::Size(k, k), cv::Point(-1, -1), cv::BORDER_REPLICATE);
  cv::resize(background, background, f.size(), 0, 0, cv::INTER_LINEAR);
  cv::Mat blurred;
  cv::GaussianBlur(f, blurred, cv::Size(5, 5), 1.0);
  cv::Mat out(f.size(), CV_8U);
  for (int y = 0; y < f.rows; ++y) {
    const float* b = blurred.ptr<float>(y);
    const float* g = background.ptr<float>(y);
    const uint8_t* m = mask.ptr<uint8_t>(y);
    uint8_t* o = out.ptr<uint8_t>(y);
    for (int x = 0; x < f.cols; ++x) {
      const float ratio = m[x] && g[x] > 0 ? b[x] / g[x] : 1.0f;
      o[x] = cv::saturate_cast<uint8_t>(255.0f * ratio);
    }
  }
  return out;
}

namespace {

// A SimpleBlobDetector that drops blobs touching the field-of-view border (the vignetted rim next
// to the masked-out area looks like a chain of dark blobs). findCirclesGrid calls detect() once
// per attempt on the same image: the blobs are found once and reused.
class MaskedBlobDetector : public cv::Feature2D {
 public:
  MaskedBlobDetector(cv::Ptr<cv::SimpleBlobDetector> inner, cv::Mat mask)
      : inner_(std::move(inner)), mask_(std::move(mask)) {}
  void detect(cv::InputArray image,
              std::vector<cv::KeyPoint>& keypoints,
              cv::InputArray mask = cv::noArray()) override {
    const cv::Mat m = image.getMat();
    if (!(cached_ && m.data == data_ && m.size() == size_ && mask.empty())) {
      std::vector<cv::KeyPoint> all;
      inner_->detect(image, all, mask);
      kept_.clear();
      for (const auto& k : all) {
        if (ClearOfMaskBorder(mask_, k.pt, 0.5 * k.size)) kept_.push_back(k);
      }
      cached_ = mask.empty();
      data_ = m.data;
      size_ = m.size();
    }
    keypoints = kept_;
  }
  int last_count() const { return static_cast<int>(kept_.size()); }
  const std::vector<cv::KeyPoint>& last_keypoints() const { return kept_; }

 private:
  cv::Ptr<cv::SimpleBlobDetector> inner_;
  cv::Mat mask_;
  std::vector<cv::KeyPoint> kept_;
  bool cached_ = false;
  const uchar* data_ = nullptr;
  cv::Size size_;
};

// ---- DetectGrid's steps (grid_detector.h, "Pipeline per image"). Each returns false with the
// reason in `reason` when the view cannot be used.

}  // namespace

cv::Mat GreyImage(const cv::Mat& image) {
  cv::Mat grey;
  if (image.channels() == 3) {
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  } else if (image.channels() == 4) {
    cv::cvtColor(image, grey, cv::COLOR_BGRA2GRAY);
  } else {
    grey = image;
  }
  return grey;
}

// Step 1a: the (cropped) image as float grey levels; `offset` is the crop's corner.
bool ToFloatGrey(const cv::Mat& image, const DetectionOptions& o, cv::Mat* f, cv::Point* offset,
                 std::string* reason) {
  if (image.empty()) return *reason = "empty image", false;
  GreyImage(image).convertTo(*f, CV_32F);
  *offset = cv::Point(0, 0);
  if (!o.roi_px.empty()) {
    cv::Rect roi(o.roi_px[0], o.roi_px[1], o.roi_px[2], o.roi_px[3]);
    if ((roi & cv::Rect(0, 0, f->cols, f->rows)) != roi)
      return *reason = "roi_px outside the image", false;
    *f = (*f)(roi).clone();
    *offset = roi.tl();
  }
  double lo, hi;
  cv::minMaxLoc(*f, &lo, &hi);
  if (!(hi > lo)) return *reason = "image has no contrast", false;
  return true;
}

namespace {


// The largest component above `level` (fraction of the range lo..hi) and its convex hull, when
// it covers 20-90 % of the image (a dark border exists).
bool FieldHull(const cv::Mat& f, double lo, double hi, double level, std::vector<cv::Point>* hull) {
  const cv::Mat bright = f > (lo + level * (hi - lo));
  const double inside = cv::countNonZero(bright) / static_cast<double>(f.total());
  if (!(inside < 0.9 && inside > 0.2)) return false;
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(bright, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
  if (contours.empty()) return false;
  size_t best = 0;
  for (size_t i = 1; i < contours.size(); ++i) {
    if (cv::contourArea(contours[i]) > cv::contourArea(contours[best])) best = i;
  }
  cv::convexHull(contours[best], *hull);
  return true;
}

}  // namespace

// Step 2: region of interest and field of view (header).
FieldOfView FindFieldOfView(const cv::Mat& f, const DetectionOptions& o, cv::Point offset) {
  FieldOfView fov;
  fov.mask = cv::Mat(f.size(), CV_8U, cv::Scalar(255));
  if (!o.fov_circle_px.empty()) {
    fov.have_circle = true;
    fov.centre = cv::Point2d(o.fov_circle_px[0] - offset.x, o.fov_circle_px[1] - offset.y);
    fov.radius = o.fov_circle_px[2];
    fov.mask.setTo(0);
    cv::circle(fov.mask,
               fov.centre,
               static_cast<int>(fov.radius - o.fov_margin_px),
               cv::Scalar(255),
               cv::FILLED);
  } else if (o.auto_fov_mask) {
    // The intensifier's field: the largest component above 15 % of the range, its convex hull
    // and the hull's enclosing circle, when a sizeable dark border exists. Dark anatomy at the
    // rim can fall below 15 % and cut into that region (a chord instead of the rim, the hull
    // then covering less than 97 % of its enclosing circle): when an unexposed border exists
    // (at least 10 % of the image within 2 % of the range of the darkest level) and the hull
    // above 5 % of the range is more than 3 % larger (a rim band 1 px wide is ~0.8 %), the 5 %
    // hull is the field.
    double lo, hi;
    cv::minMaxLoc(f, &lo, &hi);
    std::vector<cv::Point> hull, hull_low;
    bool have_hull = FieldHull(f, lo, hi, 0.15, &hull);
    cv::Point2f c;
    float rad = 0;
    if (have_hull) cv::minEnclosingCircle(hull, c, rad);
    const bool cut = !have_hull || cv::contourArea(hull) < 0.97 * M_PI * rad * rad;
    if (cut) {
      const double border =
          1.0 - cv::countNonZero(f > (lo + 0.02 * (hi - lo))) / static_cast<double>(f.total());
      if (border >= 0.1 && FieldHull(f, lo, hi, 0.05, &hull_low) &&
          (!have_hull || cv::contourArea(hull_low) > 1.03 * cv::contourArea(hull))) {
        hull = hull_low;
        have_hull = true;
        cv::minEnclosingCircle(hull, c, rad);
      }
    }
    if (have_hull) {
      // An intensifier field clipped by the image edge: the enclosing circle still bounds it;
      // intersect with the hull so corners outside the field stay masked.
      fov.mask.setTo(0);
      cv::fillConvexPoly(fov.mask, hull, cv::Scalar(255));
      cv::Mat circle_mask(f.size(), CV_8U, cv::Scalar(0));
      cv::circle(circle_mask, c, static_cast<int>(rad - o.fov_margin_px), cv::Scalar(255),
                 cv::FILLED);
      cv::bitwise_and(fov.mask, circle_mask, fov.mask);
      fov.have_circle = true;
      fov.centre = c;
      fov.radius = rad;
    }
  }
  // Sub-pixel refinement uses only the fully exposed field (not the intensifier's fall-off rim,
  // whose steep gradient no local background plane follows); a blob whose window reaches the rim
  // is dropped.
  fov.refine_valid = fov.mask;
  if (fov.have_circle) {
    const double exposed = FullyExposedRadius(f, fov.centre, fov.radius);
    fov.refine_valid = cv::Mat(f.size(), CV_8U, cv::Scalar(0));
    cv::circle(fov.refine_valid, fov.centre,
               static_cast<int>(std::min(exposed, fov.radius - o.fov_margin_px)), cv::Scalar(255),
               cv::FILLED);
    cv::bitwise_and(fov.refine_valid, fov.mask, fov.refine_valid);
  }
  return fov;
}

namespace {

struct WorkingImage {
  cv::Mat work;    // CV_8U, 1..99 % of the field stretched to 0..255
  cv::Mat search;  // `work` lightly blurred, for the blob search
  double p35 = 0, p65 = 0;  // the field's 35th / 65th percentiles on the working scale
};

// Step 1b: the 8-bit working image stretched over the 1..99 % range inside the mask. The outside
// is left as it is: blobs there or on the rim are dropped by their distance to the mask border.
bool MakeWorkingImage(const cv::Mat& f, const cv::Mat& mask, WorkingImage* w, std::string* reason) {
  // (Every second pixel of every second row: percentiles to well under the stretch's needs.)
  std::vector<float> vals;
  vals.reserve(f.total() / 4 + 1);
  const int step = f.total() >= 40000 ? 2 : 1;
  for (int y = 0; y < f.rows; y += step) {
    const float* fr = f.ptr<float>(y);
    const uint8_t* mr = mask.ptr<uint8_t>(y);
    for (int x = 0; x < f.cols; x += step) {
      if (mr[x]) vals.push_back(fr[x]);
    }
  }
  if (vals.size() * step * step < 100) {
    return *reason = "field of view / region of interest is (almost) empty", false;
  }
  // Percentiles by nested selection: each nth_element works only on the part of the array that
  // the previous one left on the percentile's side.
  const size_t n_vals = vals.size();
  auto index = [n_vals](double q) { return std::min(n_vals - 1, static_cast<size_t>(q * n_vals)); };
  const size_t k01 = index(0.01), k35 = index(0.35), k65 = index(0.65), k99 = index(0.99);
  std::nth_element(vals.begin(), vals.begin() + k35, vals.end());
  const double p35 = vals[k35];  // (read before the next selections move it)
  std::nth_element(vals.begin(), vals.begin() + k01, vals.begin() + k35);
  const double p01 = vals[k01];
  std::nth_element(vals.begin() + k35 + 1, vals.begin() + k65, vals.end());
  const double p65 = vals[k65];
  std::nth_element(vals.begin() + k65 + 1, vals.begin() + k99, vals.end());
  const double p99 = vals[k99];
  if (!(p99 > p01)) return *reason = "no contrast inside the field of view", false;
  // The 35th / 65th percentiles on the working scale bound the blob search's thresholds: a dark
  // blob is darker than most of the field (its levels lie below the 35th percentile), a bright
  // one brighter. Thresholds beyond only cut the background into noise contours.
  w->p35 = 255.0 * (p35 - p01) / (p99 - p01);
  w->p65 = 255.0 * (p65 - p01) / (p99 - p01);
  f.convertTo(w->work, CV_8U, 255.0 / (p99 - p01), -255.0 * p01 / (p99 - p01));
  // A light blur for the blob search only (noise speckles otherwise form small blobs at
  // thresholds near the background level); centres are refined on the unblurred image.
  cv::GaussianBlur(w->work, w->search, cv::Size(5, 5), 1.0);
  return true;
}

struct GridCandidate {
  std::vector<cv::Point2f> centres;  // row-major, OpenCV's ordering
  std::vector<cv::KeyPoint> blobs;   // the blobs of the search that found the grid (or, when none
                                     // did, of the search with the most blobs)
  bool dark = true;
};

// Step 3 (circles): the blob search and OpenCV's grid finders (header). Fills det->num_blobs and
// det->polarity.
bool FindCircleGrid(const cv::Mat& f, const WorkingImage& w, const cv::Mat& mask,
                    const GridSpec& grid, const DetectionOptions& o, GridDetection* det,
                    GridCandidate* out) {
  // Searches: (polarity, flat-fielded). The flat-fielded search runs only when the plain one of
  // that polarity fails (see FlatFieldedSearchImage).
  std::vector<std::pair<bool, bool>> tries;
  if (o.polarity != "bright") tries.push_back({true, false}), tries.push_back({true, true});
  if (o.polarity != "dark") tries.push_back({false, false});
  const cv::Size size(grid.cols, grid.rows);
  int most_blobs = 0;
  std::vector<cv::KeyPoint> plain_dark_blobs;
  for (const auto& [d, flat] : tries) {
    cv::SimpleBlobDetector::Params p;
    p.blobColor = d ? 0 : 255;
    p.filterByArea = true;
    p.minArea = static_cast<float>(o.min_blob_area_px);
    p.maxArea = static_cast<float>(o.max_blob_area_px);
    p.filterByConvexity = true;
    p.minConvexity = 0.8f;
    p.filterByInertia = true;
    p.minInertiaRatio = 0.3f;
    // 10 .. 245 in steps of 20, trimmed at the field's 35th (dark) / 65th (bright) percentile but
    // keeping at least 4 levels. On the flat-fielded image the levels are contrasts: up to 235
    // (8 % below the local background; the field's noise stays above).
    p.minThreshold = d ? 10.0f : static_cast<float>(std::clamp(w.p65, 10.0, 165.0));
    p.maxThreshold = d ? static_cast<float>(std::clamp(w.p35 + 1.0, 90.0, 245.0)) : 245.0f;
    if (flat) p.maxThreshold = 236.0f;
    p.thresholdStep = 20;
    p.minDistBetweenBlobs = 3;
    cv::Mat search = w.search;
    if (flat) {
      // The blob size from the plain search's blobs (their median diameter), else a guess.
      std::vector<float> sizes;
      for (const auto& k : plain_dark_blobs) sizes.push_back(k.size);
      double diameter_px = 0.04 * std::min(f.cols, f.rows);
      if (sizes.size() >= 3) {
        std::nth_element(sizes.begin(), sizes.begin() + sizes.size() / 2, sizes.end());
        diameter_px = sizes[sizes.size() / 2];
      }
      search = FlatFieldedSearchImage(f, mask, diameter_px);
    }
    auto detector = cv::makePtr<MaskedBlobDetector>(cv::SimpleBlobDetector::create(p), mask);
    const int flags = grid.pattern == GridPattern::kAsymmetricCircles ? cv::CALIB_CB_ASYMMETRIC_GRID
                                                                      : cv::CALIB_CB_SYMMETRIC_GRID;
    // OpenCV's symmetric grid finder depends on the order of the pattern size: try the
    // transposed size too (then transpose the ordering back), with and without clustering.
    // Clustering first: it is the cheaper finder (k-means on the blob positions instead of
    // OpenCV's graph search) and succeeds among stray noise blobs where the other often fails.
    std::vector<cv::Point2f> found;
    bool ok = false, ran = false;
    for (int attempt = 0; attempt < 4 && !ok; ++attempt) {
      const bool transposed = attempt % 2 == 1;
      const bool clustering = attempt < 2;
      if (transposed && (grid.rows == grid.cols || grid.pattern != GridPattern::kCircles)) continue;
      if (clustering && grid.pattern != GridPattern::kCircles) continue;
      if (ran && detector->last_count() < grid.NumPoints()) break;
      ran = true;
      const cv::Size try_size = transposed ? cv::Size(grid.rows, grid.cols) : size;
      GridSpec try_grid = grid;
      try_grid.rows = try_size.height;
      try_grid.cols = try_size.width;
      std::vector<cv::Point2f> f2;
      ok = cv::findCirclesGrid(search, try_size, f2,
                               flags | (clustering ? cv::CALIB_CB_CLUSTERING : 0), detector) &&
           static_cast<int>(f2.size()) == grid.NumPoints() && PlausibleGrid(f2, try_grid);
      if (detector->last_count() > most_blobs) out->blobs = detector->last_keypoints();
      most_blobs = std::max(most_blobs, detector->last_count());
      if (!ok) continue;
      if (transposed) {
        // f2[r' * rows + c'] is plate point (row c', col r').
        found.assign(f2.size(), cv::Point2f());
        for (int rp = 0; rp < grid.cols; ++rp) {
          for (int cp = 0; cp < grid.rows; ++cp)
            found[cp * grid.cols + rp] = f2[rp * grid.rows + cp];
        }
      } else {
        found = f2;
      }
    }
    if (d && !flat) plain_dark_blobs = detector->last_keypoints();
    if (ok) {
      out->centres = found;
      out->blobs = detector->last_keypoints();
      out->dark = d;
      det->polarity = d ? "dark" : "bright";
      det->num_blobs = most_blobs;
      return true;
    }
  }
  det->num_blobs = most_blobs;
  if (most_blobs < grid.NumPoints()) {
    det->reason = "too few blobs: " + std::to_string(most_blobs) + " found, " +
                  std::to_string(grid.NumPoints()) +
                  " needed (grid partly outside the field of view, wrong polarity or size?)";
  } else {
    det->reason = std::to_string(most_blobs) + " blobs but no " + std::to_string(grid.rows) +
                  " x " + std::to_string(grid.cols) +
                  " grid ordering among them (ambiguous ordering, extra blobs or grid partly "
                  "outside the field of view)";
  }
  return false;
}

// Step 3 (chessboard): OpenCV's corners, refined by cornerSubPix on the working image.
bool FindChessboard(const cv::Mat& work,
                    const GridSpec& grid,
                    GridCandidate* out,
                    std::string* reason) {
  std::vector<cv::Point2f> found;
  if (!cv::findChessboardCorners(work, cv::Size(grid.cols, grid.rows), found,
                                 cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE) ||
      static_cast<int>(found.size()) != grid.NumPoints()) {
    *reason = "no " + std::to_string(grid.rows) + " x " + std::to_string(grid.cols) +
              " chessboard (inner corners) found";
    return false;
  }
  cv::cornerSubPix(work, found, cv::Size(5, 5), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 40, 0.001));
  out->centres = found;
  return true;
}

// The smallest distance between row neighbours (half of it for acircles: the lattice step).
double GridPitchPx(const GridSpec& grid, const std::vector<cv::Point2d>& pts) {
  double pitch = 1e30;
  for (int r = 0; r < grid.rows; ++r) {
    for (int c = 0; c + 1 < grid.cols; ++c) {
      pitch = std::min(pitch, cv::norm(pts[r * grid.cols + c + 1] - pts[r * grid.cols + c]));
    }
  }
  return grid.pattern == GridPattern::kAsymmetricCircles ? 0.5 * pitch : pitch;
}

// A refined centre whose core and whole-blob centroids (RefineCentroid's shift_px) are further
// apart than this is dropped as unreliable (background structure across the sphere).
constexpr double kUnreliableShiftPx = 0.15;

// Step 4: sub-pixel centres of circles on the float image (RefineCentroid). `refined_ok[i]` is
// false where the refinement failed, was pulled off the blob or is unreliable (`shift_px[i]` >
// kUnreliableShiftPx: background structure across the sphere).
void RefineCentres(const cv::Mat& f, const cv::Mat& refine_valid, const GridSpec& grid,
                   const GridCandidate& cand, std::vector<cv::Point2d>* pts,
                   std::vector<bool>* refined_ok, std::vector<double>* shift_px) {
  const double pitch =
      GridPitchPx(grid, std::vector<cv::Point2d>(cand.centres.begin(), cand.centres.end()));
  for (size_t i = 0; i < pts->size(); ++i) {
    // The distance to the nearest other grid point bounds the blob's window and ring.
    double nn = 1e30;
    for (size_t j = 0; j < pts->size(); ++j) {
      if (j != i) nn = std::min(nn, cv::norm((*pts)[j] - (*pts)[i]));
    }
    cv::Point2d q = (*pts)[i];
    // The blob finder's centre is good to a fraction of a pixel: a refined centre that moved by
    // more than half the blob's radius (the blob finder's, else the measured one; at least
    // 1.5 px) was pulled off the blob (a strong background edge in its ring) and is dropped
    // rather than kept wrong.
    double r_half = 0, blob_r = 0, blob_d = 0.3 * pitch;
    for (const cv::KeyPoint& k : cand.blobs) {
      const double dk = cv::norm(cv::Point2d(k.pt) - (*pts)[i]);
      if (dk < blob_d) blob_d = dk, blob_r = 0.5 * k.size;
    }
    // The disc cap as before the large-circle fix (disc + ring within ceil(0.35 pitch)): small
    // circles keep their results (same noise), large ones go beyond it with 1 px tails.
    if (RefineCentroid(f,
                       refine_valid,
                       cand.dark,
                       nn,
                       std::max(3.0, std::ceil(0.35 * pitch)) - 3.0,
                       kPlateCentroidFloor,
                       &q,
                       &r_half,
                       nullptr,
                       &(*shift_px)[i]) &&
        cv::norm(q - (*pts)[i]) <
            std::min(0.3 * pitch, std::max(1.5, 0.5 * (blob_r > 0 ? blob_r : r_half)))) {
      (*pts)[i] = q;
      // Core and whole-blob centroids this far apart: the core's centre is still off by up to
      // ~0.1-0.2 px (edge_accuracy_test.cc), many times the noise; dropped (calibration weighs
      // every point with one pixel sigma).
      if ((*shift_px)[i] > kUnreliableShiftPx) (*refined_ok)[i] = false;
    } else {
      (*refined_ok)[i] = false;  // no blob there (OpenCV fills a missing blob from the grid model)
      (*shift_px)[i] = 0;
    }
  }
}

// Step 4 (end): the points kept. Points whose blob touches the field-of-view border are dropped
// (their centre is pulled by the rim); the view keeps the others if they are at least half the
// grid and lie on a grid: a homography from the plate (returned in `H`) explains them to within
// 30 % of the pitch (lens distortion over a plate stays below that; a wrong blob does not).
bool KeepPointsOnGrid(const GridSpec& grid, const std::vector<cv::Point2d>& pts,
                      const std::vector<bool>& refined_ok, const cv::Mat& mask, double pitch_px,
                      std::vector<int>* kept, cv::Mat* H, std::string* reason) {
  const bool circles = grid.pattern != GridPattern::kChessboard;
  for (int id = 0; id < grid.NumPoints(); ++id) {
    const int x = static_cast<int>(std::lround(pts[id].x)),
              y = static_cast<int>(std::lround(pts[id].y));
    if (x < 0 || y < 0 || x >= mask.cols || y >= mask.rows) continue;
    if (circles && !ClearOfMaskBorder(mask, pts[id], 0.2 * pitch_px)) continue;
    if (!circles && !mask.at<uint8_t>(y, x)) continue;
    if (!refined_ok[id]) continue;
    kept->push_back(id);
  }
  if (static_cast<int>(kept->size()) < std::max(4, grid.NumPoints() / 2)) {
    *reason = "grid partly outside the field of view (" + std::to_string(kept->size()) + " of " +
              std::to_string(grid.NumPoints()) + " points clear of its border)";
    return false;
  }
  std::vector<cv::Point2f> plate_xy, image_xy;
  for (int id : *kept) {
    const Eigen::Vector3d P = grid.PointInPlate(id);
    plate_xy.emplace_back(P.x(), P.y());
    image_xy.emplace_back(pts[id]);
  }
  *H = cv::findHomography(plate_xy, image_xy, 0);
  if (H->empty()) return *reason = "ambiguous grid ordering (no homography from the plate)", false;
  std::vector<cv::Point2f> mapped;
  cv::perspectiveTransform(plate_xy, mapped, *H);
  double worst = 0;
  for (size_t i = 0; i < mapped.size(); ++i)
    worst = std::max(worst, cv::norm(mapped[i] - image_xy[i]));
  if (worst > 0.3 * pitch_px) {
    *reason = "ambiguous grid ordering: a point is " + std::to_string(worst) +
              " px off the fitted grid (a wrong blob?)";
    return false;
  }
  return true;
}

// Step 6: a plate larger than the requested pattern. OpenCV picks some sub-window of it, a
// different one in different views, so point ids would not be consistent across views.
bool PlateNotLarger(const GridSpec& grid, const std::vector<cv::Point2d>& pts,
                    const std::vector<int>& kept, const std::vector<cv::KeyPoint>& blobs,
                    const cv::Mat& mask, double pitch_px, std::string* reason) {
  const cv::Size plate = LatticeExtent(grid, pts, kept, blobs, mask, pitch_px);
  if (plate.width > grid.cols || plate.height > grid.rows) {
    *reason = "ambiguous: more grid points than " + std::to_string(grid.rows) + "x" +
              std::to_string(grid.cols) + " (the plate has at least " +
              std::to_string(std::max(plate.height, grid.rows)) + "x" +
              std::to_string(std::max(plate.width, grid.cols)) +
              "; give its full --rows and --cols)";
    return false;
  }
  return true;
}

// Step 5: right-handed ordering in the image for symmetric patterns: the plate's x and y axes map
// to image directions with a positive cross product (Jacobian of H at the grid's first kept
// point); otherwise the columns are reversed.
void MakeRightHanded(const GridSpec& grid, const cv::Mat& H, std::vector<cv::Point2d>* pts,
                     std::vector<int>* kept) {
  if (grid.pattern == GridPattern::kAsymmetricCircles) return;
  const Eigen::Vector3d P0 = grid.PointInPlate((*kept)[0]);
  const double h[9] = {H.at<double>(0, 0), H.at<double>(0, 1), H.at<double>(0, 2),
                       H.at<double>(1, 0), H.at<double>(1, 1), H.at<double>(1, 2),
                       H.at<double>(2, 0), H.at<double>(2, 1), H.at<double>(2, 2)};
  const double w = h[6] * P0.x() + h[7] * P0.y() + h[8];
  const double u = (h[0] * P0.x() + h[1] * P0.y() + h[2]) / w;
  const double v = (h[3] * P0.x() + h[4] * P0.y() + h[5]) / w;
  const double du_dx = (h[0] - u * h[6]) / w, du_dy = (h[1] - u * h[7]) / w;
  const double dv_dx = (h[3] - v * h[6]) / w, dv_dy = (h[4] - v * h[7]) / w;
  if (du_dx * dv_dy - du_dy * dv_dx >= 0) return;
  std::vector<cv::Point2d> flipped(pts->size());
  for (int r = 0; r < grid.rows; ++r) {
    for (int c = 0; c < grid.cols; ++c)
      flipped[r * grid.cols + c] = (*pts)[r * grid.cols + (grid.cols - 1 - c)];
  }
  *pts = flipped;
  for (int& id : *kept) id = (id / grid.cols) * grid.cols + (grid.cols - 1 - id % grid.cols);
  std::sort(kept->begin(), kept->end());
}

// The blobs and grid points not among `kept`, and why (RejectedBlob in the header).
void ListRejected(const GridSpec& grid,
                  const GridCandidate& cand,
                  const std::vector<cv::Point2d>& pts,
                  const std::vector<bool>& refined_ok,
                  const std::vector<double>& shift_px,
                  const std::vector<int>& kept,
                  double pitch_px,
                  cv::Point offset,
                  std::vector<RejectedBlob>* rejected) {
  const cv::Point2d off(offset.x, offset.y);
  std::vector<bool> is_kept(grid.NumPoints(), false), has_blob(grid.NumPoints(), false);
  for (int id : kept) is_kept[id] = true;
  auto why_dropped = [&refined_ok, &shift_px](int id) -> std::string {
    if (refined_ok[id]) return "on the field-of-view border";
    if (shift_px[id] > kUnreliableShiftPx) {
      return std::string(kUnreliableCentre) + " (core " + Fixed(shift_px[id], 2) + " px off)";
    }
    return "no blob / refinement failed";
  };
  for (const cv::KeyPoint& k : cand.blobs) {
    int nearest = -1;
    double best = 0.3 * pitch_px;
    for (int id = 0; id < grid.NumPoints(); ++id) {
      const double dk = cv::norm(cv::Point2d(cand.centres[id]) - cv::Point2d(k.pt));
      if (dk < best) best = dk, nearest = id;
    }
    if (nearest >= 0) has_blob[nearest] = true;
    if (nearest >= 0 && is_kept[nearest]) continue;
    rejected->push_back(
        {cv::Point2d(k.pt) + off, k.size, nearest < 0 ? "not on the grid" : why_dropped(nearest)});
  }
  for (int id = 0; id < grid.NumPoints(); ++id) {
    if (!is_kept[id] && !has_blob[id]) rejected->push_back({pts[id] + off, 0.0, why_dropped(id)});
  }
}

}  // namespace

GridDetection DetectGrid(const cv::Mat& image, const GridSpec& grid, const DetectionOptions& o) {
  GridDetection det;
  if (!o.Check(&det.reason) || !grid.Check(&det.reason)) return det;
  // 1, 2: grey levels, field of view, working image.
  cv::Mat f;
  cv::Point offset;
  if (!ToFloatGrey(image, o, &f, &offset, &det.reason)) return det;
  const FieldOfView fov = FindFieldOfView(f, o, offset);
  WorkingImage work;
  if (!MakeWorkingImage(f, fov.mask, &work, &det.reason)) return det;
  // 3: the grid among the blobs (or the chessboard's corners).
  const bool circles = grid.pattern != GridPattern::kChessboard;
  GridCandidate cand;
  if (circles ? !FindCircleGrid(f, work, fov.mask, grid, o, &det, &cand)
              : !FindChessboard(work.work, grid, &cand, &det.reason)) {
    for (const cv::KeyPoint& k : cand.blobs) {
      det.rejected.push_back(
          {cv::Point2d(k.pt.x + offset.x, k.pt.y + offset.y), k.size, "no grid"});
    }
    return det;
  }
  // 4: sub-pixel centres, the points kept.
  std::vector<cv::Point2d> pts(cand.centres.begin(), cand.centres.end());
  std::vector<bool> refined_ok(pts.size(), true);
  std::vector<double> shift(pts.size(), 0.0);
  if (circles && o.refine)
    RefineCentres(f, fov.refine_valid, grid, cand, &pts, &refined_ok, &shift);
  const double pitch_px = GridPitchPx(grid, pts);
  std::vector<int> kept;
  cv::Mat H;
  const bool kept_ok =
      KeepPointsOnGrid(grid, pts, refined_ok, fov.mask, pitch_px, &kept, &H, &det.reason);
  if (circles)
    ListRejected(grid, cand, pts, refined_ok, shift, kept, pitch_px, offset, &det.rejected);
  if (!kept_ok) return det;
  // 6: not a sub-window of a larger plate.
  if (circles && !PlateNotLarger(grid, pts, kept, cand.blobs, fov.mask, pitch_px, &det.reason)) {
    return det;
  }
  // 5: ids, right-handed.
  MakeRightHanded(grid, H, &pts, &kept);
  for (int id : kept) {
    det.view.point_ids.push_back(id);
    det.view.uv_px.emplace_back(pts[id].x + offset.x, pts[id].y + offset.y);
    det.background_shift_px.push_back(shift[id]);
  }
  det.found = true;
  return det;
}

StatusOr<ObservationSet> DetectGridInFiles(const std::vector<std::string>& files,
                                           const GridSpec& grid,
                                           const DetectionOptions& options,
                                           std::vector<std::string>* skipped,
                                           double* seconds_per_image,
                                           std::vector<GridDetection>* detections,
                                           const ProgressFn& progress) {
  std::string err;
  if (!options.Check(&err)) return Status::Error("detection options: " + err);
  if (!grid.Check(&err)) return Status::Error(err);
  ObservationSet obs;
  obs.grid = grid;
  double total = 0;
  int num_views = 0;
  for (const auto& path : files) {
    auto named = ReadImageViews(path);
    if (!named.ok()) return named.status();
    for (const NamedImage& view : *named) {
      const std::string& file = view.name;
      const cv::Mat* img = &view.image;
      ++num_views;
      if (obs.width == 0) {
        obs.width = img->cols;
        obs.height = img->rows;
      } else if (img->cols != obs.width || img->rows != obs.height) {
        return Status::Error(file + ": image size " + std::to_string(img->cols) + "x" +
                             std::to_string(img->rows) + " differs from the first image's " +
                             std::to_string(obs.width) + "x" + std::to_string(obs.height));
      }
      const auto t0 = std::chrono::steady_clock::now();
      GridDetection d = DetectGrid(*img, grid, options);
      total += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      d.view.image = file;
      if (detections) detections->push_back(d);
      if (!d.found) {
        skipped->push_back(file + ": " + d.reason);
        continue;
      }
      obs.views.push_back(d.view);
    }
    if (progress) progress(path);
  }
  if (seconds_per_image && num_views > 0) *seconds_per_image = total / num_views;
  return obs;
}

}  // namespace carmba
