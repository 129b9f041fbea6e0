#include "detect/marker_blobs.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <string>
#include <tuple>

#include "detect/detect_steps.h"
#include "util/yaml_reader.h"

namespace carmba {

namespace {
// The share of a line's largest pull on a centre (the line through the disc's edge) that its
// errors have as RMS: 0.3 over the labelled centres with a line across their ring in
// tests/detect/marker_recall_test.cc's seed sets 1-4 of each anatomy (NEES per dof 0.66 there;
// 0.08 with the bound itself, 1.1 with 0.2).
constexpr double kLinePullRmsShare = 0.3;
// The share of the core-to-whole shift's excess (its part beyond the pixel noise's, less
// unreliable_shift_px) that a centre's errors have as RMS per axis. Over the labelled centres of
// tests/detect/marker_recall_test.cc's development sets (real CT 1-16, 9546 centres), the
// widened centres' NEES per dof equals the others' (the pixel noise's own) at the whole excess:
// 0.86 against 0.89 (on the XA frame 1-8, 1.28 against 0.96); a share of 0.55 left them at 1.24
// and 1.74. Before the shift's own noise was taken out, 62 % of the real-CT centres were widened,
// most for the noise of dark anatomy alone, the share that matched was 0.55, and their blob NEES
// was 0.75. Since the centre moves to the core by its noise too (grid_detector.cc, "centre"),
// the widened centres are over-covered at this share (NEES 0.72 against 0.93 on the real-CT
// development sets, 0.53 against 1.01 on the XA frame's); a share of 0.55 gave 0.54-1.40 (XA
// frame) and 1.31-2.56 (real CT) over seed sets 1-4, so it is kept.
constexpr double kShiftRmsShare = 1.0;
}  // namespace

bool MarkerBlobOptions::Check(std::string* error) const {
  if (!diameter_px.empty()) {
    if (diameter_px.size() != 2 || !(diameter_px[0] > 0) || !(diameter_px[1] >= diameter_px[0]) ||
        !(diameter_px[1] < 1000)) {
      *error = "diameter_px: expected [min, max] with 0 < min <= max < 1000";
      return false;
    }
  } else if (!(diameter_mm > 0 && diameter_mm < 100) || !(px_per_mm > 0 && px_per_mm < 1000)) {
    *error = "marker diameter: expected diameter_px [min, max], or diameter_mm (0..100) with the "
             "nominal magnification px_per_mm (0..1000)";
    return false;
  }
  if (!(diameter_tolerance >= 0 && diameter_tolerance < 1)) {
    *error = "diameter_tolerance: expected 0 <= value < 1";
    return false;
  }
  if (!(min_contrast >= 0 && min_contrast < 1)) {
    *error = "min_contrast: expected 0 <= value < 1";
    return false;
  }
  if (!(max_elongation >= 1 && max_elongation < 10) ||
      !(merge_area_ratio > 1 && merge_area_ratio < 10) ||
      !(merge_distance > 0 && merge_distance < 10)) {
    *error =
        "max_elongation (1..10), merge_area_ratio (1..10), merge_distance (0..10) out of range";
    return false;
  }
  return fov.Check(error);
}

std::pair<double, double> MarkerBlobOptions::DiameterRangePx() const {
  if (!diameter_px.empty()) return {diameter_px[0], diameter_px[1]};
  const double d = diameter_mm * px_per_mm;
  return {d * (1 - diameter_tolerance), d * (1 + diameter_tolerance)};
}

void ReadMarkerBlobOptions(YamlMap& m, MarkerBlobOptions* o) {
  m.Get("diameter_px", &o->diameter_px);
  m.GetPositive("diameter_mm", &o->diameter_mm);
  m.GetPositive("px_per_mm", &o->px_per_mm);
  m.GetNonNegative("diameter_tolerance", &o->diameter_tolerance);
  m.GetNonNegative("min_contrast", &o->min_contrast);
  m.GetPositive("max_elongation", &o->max_elongation);
  m.GetPositive("merge_area_ratio", &o->merge_area_ratio);
  m.GetPositive("merge_distance", &o->merge_distance);
  m.Get("correct_blur_pull", &o->correct_blur_pull);
  ReadFieldOfViewOptions(m, &o->fov);
}

namespace {

double RobustSigma(std::vector<float>* v) {
  if (v->size() < 16) return 0;
  const size_t h = v->size() / 2;
  std::nth_element(v->begin(), v->begin() + h, v->end());
  const float med = (*v)[h];
  for (float& x : *v) x = std::fabs(x - med);
  std::nth_element(v->begin(), v->begin() + h, v->end());
  return 1.4826 * (*v)[h];
}

// The difference of the axis extents (px) a region's pixel outline can make on its own
// (PieceRejection).
constexpr double kPixelStepExtentPx = 1.5;
// The area (in expected marker areas) above which a stretched piece can be two markers
// (NoiseStretched): a pair 0.2 diameters apart, or one marker 12 % wider than expected.
constexpr double kPairAreaRatio = 1.25;
// The axis ratio below which a stretch can be a small disc's noise (NoiseStretched): a 4 px
// marker's 11-13 pixel region reaches 1.5-1.65 on its outline's steps alone; a pair 0.7
// diameters apart, at 1.7, has 1.9 of a disc's area.
constexpr double kNoiseStretch = 1.7;

// A connected piece of a candidate's half-peak region.
struct Piece {
  double area = 0;
  cv::Point2d centre;
  double major = 0, minor = 0;  // sqrt of the second-moment eigenvalues (px)
  int touches_border = 0;
  cv::Point peak_at;  // the piece's darkest pixel (full image)
  double height = 0;  // its contrast there (above the local base after LocalHalfPeakPiece)
};

}  // namespace

double NoiseCorrelationFactor(const cv::Mat& f,
                              const cv::Mat& mask,
                              double* rho1,
                              double* sigma_pixel) {
  // Second differences along rows at lags 1 and 2: a background that changes linearly (an edge's
  // flank, anatomy, the fall-off) leaves them, where it would make first differences look
  // correlated. With the noise's correlation rho^(k^2) at lag k:
  //   var(x[i+1] - 2 x[i] + x[i-1]) = s^2 (6 - 8 rho + 2 rho^4),
  //   var(x[i+2] - 2 x[i] + x[i-2]) = s^2 (6 - 8 rho^4 + 2 rho^16).
  std::vector<float> d1, d2;
  d1.reserve(f.total() / 8);
  d2.reserve(f.total() / 8);
  // Pixels at the image's extremes are clipped (an 8-bit radiograph's white skin edges): they
  // have no noise, and where they fill much of the field they would make it look noise-free.
  double f_min = 0, f_max = 0;
  cv::minMaxLoc(f, &f_min, &f_max, nullptr, nullptr, mask);
  for (int y = 0; y < f.rows; y += 4) {
    const float* r = f.ptr<float>(y);
    const uint8_t* m = mask.ptr<uint8_t>(y);
    for (int x = 2; x + 2 < f.cols; x += 2) {
      bool usable = true;
      for (int k = -2; k <= 2 && usable; ++k)
        usable = m[x + k] && r[x + k] > f_min && r[x + k] < f_max;
      if (!usable) continue;
      d1.push_back(r[x + 1] - 2 * r[x] + r[x - 1]);
      d2.push_back(r[x + 2] - 2 * r[x] + r[x - 2]);
    }
  }
  const double s1 = RobustSigma(&d1), s2 = RobustSigma(&d2);
  if (rho1) *rho1 = 0;
  if (sigma_pixel) *sigma_pixel = s1 / std::sqrt(6.0);
  if (!(s1 > 0)) return 1.0;
  const auto lag1 = [](double r) { return 6 - 8 * r + 2 * std::pow(r, 4); };
  const auto lag2 = [](double r) { return 6 - 8 * std::pow(r, 4) + 2 * std::pow(r, 16); };
  // The ratio grows from 1 (white noise) to 16 (rho -> 1): solved for rho by bisection.
  const double ratio = std::clamp(s2 * s2 / (s1 * s1), 1.0, 15.9);
  double lo = 0, hi = 1;
  for (int it = 0; it < 50; ++it) {
    const double r = 0.5 * (lo + hi);
    (lag2(r) / lag1(r) < ratio ? lo : hi) = r;
  }
  const double rho = 0.5 * (lo + hi);
  if (rho1) *rho1 = rho;
  if (sigma_pixel) *sigma_pixel = s1 / std::sqrt(std::max(1e-6, lag1(rho)));
  double F = 0;
  for (int kx = -4; kx <= 4; ++kx) {
    for (int ky = -4; ky <= 4; ++ky) F += std::pow(rho, kx * kx + ky * ky);
  }
  return F;
}

double LargestBlurCorrectionPx(const MarkerBlobDetection& detection) {
  double largest = 0;
  for (const MarkerBlob& b : detection.blobs)
    largest = std::max(largest, std::hypot(b.blur_correction_px.x, b.blur_correction_px.y));
  return largest;
}

double BlurVarianceFromNoiseCorrelation(double rho1) {
  if (!(rho1 > 0)) return 0.0;
  if (rho1 >= 1) return kMaxBlurVariancePx2;
  return std::min(kMaxBlurVariancePx2, -1.0 / (4.0 * std::log(rho1)));
}

namespace {

// One connected piece above the threshold, before refinement.
struct BlobCandidate {
  cv::Point2d centre;  // the half-peak piece's centre (crop coordinates)
  double diameter = 0, peak = 0;
  std::string why;     // empty: accepted so far
  // Accepted on its own surroundings (LocalHalfPeakPiece): how far the centre of the region at
  // the component's level lies from the centre of its own region, what stands beside the marker
  // one-sidedly (a plateau's edge, a wire's end): the covariance is widened by it.
  double surroundings_shift_px = 0;
};

// The blob sizes the options allow, in px.
struct BlobSizes {
  double d_min = 0, d_max = 0, d_nom = 0, area_nom = 0, min_area = 0;
};

// The robust sigma of the contrast image in the field of view (every second pixel); 0 when the
// field of view is (almost) empty.
double ContrastNoise(const cv::Mat& contrast, const cv::Mat& mask) {
  std::vector<float> vals;
  vals.reserve(contrast.total() / 4);
  for (int y = 0; y < contrast.rows; y += 2) {
    const float* c = contrast.ptr<float>(y);
    const uint8_t* m = mask.ptr<uint8_t>(y);
    for (int x = 0; x < contrast.cols; x += 2) {
      if (m[x]) vals.push_back(c[x]);
    }
  }
  if (vals.size() < 100) return 0;
  return std::max(RobustSigma(&vals), 1.0 / 255.0);
}

// The least ring noise a centre's covariance uses (detect_steps.h CentroidNoise): half the
// quantum noise expected at the ring's level (variance proportional to the grey level, scaled
// from the image's pixel noise at its median level), and an integer image's quantisation.
void RingNoiseFloors(const cv::Mat& image,
                     const cv::Mat& f,
                     const cv::Mat& valid,
                     double sigma_pixel,
                     CentroidNoise* noise) {
  std::vector<float> levels;
  for (int y = 0; y < f.rows; y += 8) {
    for (int x = 0; x < f.cols; x += 8) {
      if (valid.at<uint8_t>(y, x)) levels.push_back(f.at<float>(y, x));
    }
  }
  double median_level = 0;
  if (!levels.empty()) {
    std::nth_element(levels.begin(), levels.begin() + levels.size() / 2, levels.end());
    median_level = levels[levels.size() / 2];
  }
  noise->floor_variance_per_grey =
      median_level > 0 ? 0.25 * sigma_pixel * sigma_pixel / median_level : 0.0;
  noise->floor_variance_gray =
      image.depth() == CV_32F || image.depth() == CV_64F ? 0.0 : 1.0 / 12.0;
}

// A region's area, centre (full image: its moments are of a window at `offset`) and axes.
void SetShape(const cv::Moments& mo, cv::Point offset, Piece* pc) {
  pc->area = mo.m00;
  pc->centre = cv::Point2d(mo.m10 / mo.m00 + offset.x, mo.m01 / mo.m00 + offset.y);
  const double a = mo.mu20 / mo.m00, b = mo.mu11 / mo.m00, c = mo.mu02 / mo.m00;
  const double disc = std::sqrt(std::max(0.0, 0.25 * (a - c) * (a - c) + b * b));
  pc->major = std::sqrt(std::max(1e-12, 0.5 * (a + c) + disc));
  pc->minor = std::sqrt(std::max(1e-12, 0.5 * (a + c) - disc));
}

// The pieces above half the component's peak, by their moments.
std::vector<Piece> HalfPeakPieces(const cv::Mat& labels,
                                  const cv::Mat& contrast,
                                  int k,
                                  const cv::Rect& box,
                                  double peak,
                                  double min_area) {
  cv::Mat half(box.size(), CV_8U, cv::Scalar(0));
  for (int y = 0; y < box.height; ++y) {
    const int* l = labels.ptr<int>(y + box.y);
    const float* c = contrast.ptr<float>(y + box.y);
    uint8_t* h = half.ptr<uint8_t>(y);
    for (int x = 0; x < box.width; ++x)
      h[x] = (l[x + box.x] == k && c[x + box.x] > 0.5 * peak) ? 255 : 0;
  }
  cv::Mat plabels;
  const int np = cv::connectedComponents(half, plabels, 8, CV_32S);
  std::vector<Piece> pieces;
  std::vector<std::pair<float, cv::Point>> peaks(np, {-1.0f, cv::Point()});
  for (int y = 0; y < box.height; ++y) {
    const int* pl = plabels.ptr<int>(y);
    const float* c = contrast.ptr<float>(y + box.y);
    for (int x = 0; x < box.width; ++x) {
      if (pl[x] > 0 && c[x + box.x] > peaks[pl[x]].first)
        peaks[pl[x]] = {c[x + box.x], cv::Point(x + box.x, y + box.y)};
    }
  }
  for (int p = 1; p < np; ++p) {
    const cv::Moments mo = cv::moments(plabels == p, true);
    if (mo.m00 < min_area) continue;
    Piece pc;
    pc.peak_at = peaks[p].second;
    pc.height = peaks[p].first;
    SetShape(mo, box.tl(), &pc);
    pieces.push_back(pc);
  }
  return pieces;
}

// The piece re-measured against its own surroundings: the pixels about its own peak above half
// way from the local base (the median contrast on a ring 1-1.6 nominal diameters from its centre)
// to that peak, connected to the peak, within a window of the largest expected diameter. A marker
// on a plateau of anatomy narrower than the flat field (a bone edge, a sinus) otherwise has a
// half-peak region that takes in the plateau: too large, "merged".
Piece LocalHalfPeakPiece(const cv::Mat& contrast, const Piece& coarse, const BlobSizes& z) {
  const cv::Point c0(static_cast<int>(std::lround(coarse.centre.x)),
                     static_cast<int>(std::lround(coarse.centre.y)));
  const int h = static_cast<int>(std::ceil(1.6 * z.d_nom)) + 1;
  const cv::Rect image(0, 0, contrast.cols, contrast.rows);
  const cv::Rect win = cv::Rect(c0.x - h, c0.y - h, 2 * h + 1, 2 * h + 1) & image;
  std::vector<float> ring;
  for (int y = win.y; y < win.y + win.height; ++y) {
    const float* c = contrast.ptr<float>(y);
    for (int x = win.x; x < win.x + win.width; ++x) {
      const double r = std::hypot(x - coarse.centre.x, y - coarse.centre.y);
      if (r >= z.d_nom && r <= 1.6 * z.d_nom) ring.push_back(c[x]);
    }
  }
  if (ring.size() < 8) return coarse;
  std::nth_element(ring.begin(), ring.begin() + ring.size() / 2, ring.end());
  const double base = std::max(0.0f, ring[ring.size() / 2]);
  const double peak = coarse.height;  // the contrast at its peak pixel (HalfPeakPieces)
  Piece pc = coarse;
  pc.height = peak - base;
  if (base <= 0 || peak <= base) return pc;
  const double level = base + 0.5 * (peak - base);
  // Only the window of the largest expected disc about the peak.
  const int hr = static_cast<int>(std::ceil(0.5 * z.d_max)) + 1;
  const cv::Rect box =
      cv::Rect(pc.peak_at.x - hr, pc.peak_at.y - hr, 2 * hr + 1, 2 * hr + 1) & image;
  cv::Mat labels;
  cv::connectedComponents(contrast(box) > level, labels, 8, CV_32S);
  const int k = labels.at<int>(pc.peak_at.y - box.y, pc.peak_at.x - box.x);
  const cv::Moments mo = cv::moments(labels == k, true);
  if (k == 0 || mo.m00 < 1) return pc;
  SetShape(mo, box.tl(), &pc);
  return pc;
}

// Whether the piece's axis ratio exceeds a single marker's. A small disc's half-peak region is a
// few pixels, and its outline's pixel steps alone give axis ratios up to about 1.4 (a 3 x 4 pixel
// region: 1.37). Its axis ratio counts only where the axes' extents (4 sigma) also differ by more
// than those steps.
bool Stretched(const Piece& pc, const MarkerBlobOptions& o) {
  return pc.major > o.max_elongation * pc.minor && 4 * (pc.major - pc.minor) > kPixelStepExtentPx;
}

// Whether a piece is stretched only as noise stretches a small disc's outline: two discs of
// diameter D with centres s apart make one region about (1 + s / D) D long and of area about
// (1 + 1.27 s / D) x one disc's, so a stretch below kNoiseStretch that the area does not show
// (an axis ratio of 1.37 at 0.95 of a marker's area: seed 1006 of the real-CT recall set 1) is
// not a second marker.
bool NoiseStretched(const Piece& pc, const BlobSizes& z) {
  return pc.major < kNoiseStretch * pc.minor && pc.area <= kPairAreaRatio * z.area_nom;
}

// Why piece i is not a single marker (merged, elongated, too large or small), or "". Another
// piece nearer than merge_distance makes it "merged" when that piece's height reaches
// `min_neighbour_height`.
std::string PieceRejection(const std::vector<Piece>& pieces,
                           size_t i,
                           const BlobSizes& z,
                           const MarkerBlobOptions& o,
                           double min_neighbour_height) {
  const Piece& pc = pieces[i];
  const double d = 2 * std::sqrt(pc.area / M_PI);
  const double elong = pc.major / pc.minor;
  const double length = 4 * pc.major;  // full extent of a uniform ellipse along its axis
  for (size_t j = 0; j < pieces.size(); ++j) {
    if (j != i && cv::norm(pieces[j].centre - pc.centre) < o.merge_distance * z.d_nom &&
        pieces[j].height >= min_neighbour_height)
      return "merged";
  }
  const bool stretched = Stretched(pc, o);
  if (stretched || pc.area > o.merge_area_ratio * z.area_nom) {
    if (length > 2.6 * z.d_max) return "elongated";
    if (4 * pc.minor > 1.3 * z.d_max && elong < 1.15) return "too large";
    if (!stretched || !NoiseStretched(pc, z)) return "merged";
  }
  if (d < z.d_min) return "too small";
  if (d > z.d_max) return "too large";
  return "";
}

// Whether piece i of `judged` (re-measured against its own surroundings, LocalHalfPeakPiece) is
// one marker there: it stands half the peak threshold above its surroundings, and so does any
// neighbour that makes it "merged" (a noise crest on a plateau does not).
bool OneMarkerOnItsOwn(const std::vector<Piece>& judged,
                       size_t i,
                       double t_peak,
                       const BlobSizes& z,
                       const MarkerBlobOptions& o) {
  const double min_height = 0.5 * t_peak;
  return judged[i].height >= min_height && PieceRejection(judged, i, z, o, min_height).empty();
}

// The candidate taken as the region `own` (a piece re-measured on its own surroundings).
void TakeOwnRegion(const Piece& own, BlobCandidate* cand) {
  cand->centre = own.centre;
  cand->diameter = 2 * std::sqrt(own.area / M_PI);
  cand->why.clear();
}

// 4. The candidates: connected components above t_low; those peaking below t_peak are listed as
// "low contrast" when blob-sized; the others split into their half-peak pieces, each judged.
std::vector<BlobCandidate> BlobCandidates(const cv::Mat& contrast, double t_low, double t_peak,
                                          const BlobSizes& z, const MarkerBlobOptions& o) {
  cv::Mat cand = contrast > t_low;
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(cand, labels, stats, centroids, 8, CV_32S);
  std::vector<BlobCandidate> cands;
  for (int k = 1; k < n; ++k) {
    const int area = stats.at<int>(k, cv::CC_STAT_AREA);
    if (area < z.min_area) continue;  // noise speckle (not listed)
    const cv::Rect box(stats.at<int>(k, cv::CC_STAT_LEFT), stats.at<int>(k, cv::CC_STAT_TOP),
                       stats.at<int>(k, cv::CC_STAT_WIDTH), stats.at<int>(k, cv::CC_STAT_HEIGHT));
    double peak = 0;
    for (int y = box.y; y < box.y + box.height; ++y) {
      const int* l = labels.ptr<int>(y);
      const float* c = contrast.ptr<float>(y);
      for (int x = box.x; x < box.x + box.width; ++x) {
        if (l[x] == k) peak = std::max(peak, static_cast<double>(c[x]));
      }
    }
    const cv::Point2d cc(centroids.at<double>(k, 0), centroids.at<double>(k, 1));
    if (peak < t_peak) {
      // Low-contrast structure: listed only when it is blob-sized (the rest is background).
      if (area >= 0.5 * z.area_nom && box.width < 4 * z.d_max && box.height < 4 * z.d_max) {
        cands.push_back({cc, 2 * std::sqrt(area / M_PI), peak, "low contrast"});
      }
      continue;
    }
    const std::vector<Piece> pieces = HalfPeakPieces(labels, contrast, k, box, peak, z.min_area);
    std::vector<Piece> local;  // made when a piece needs a second look
    for (size_t i = 0; i < pieces.size(); ++i) {
      BlobCandidate cand{pieces[i].centre,
                         2 * std::sqrt(pieces[i].area / M_PI),
                         peak,
                         PieceRejection(pieces, i, z, o, 0)};
      // A round piece too large for one marker, or beside another piece, is looked at again
      // against its own surroundings: on a plateau it is one marker. It, and a neighbouring piece,
      // count there when they stand half the peak threshold above their own surroundings (a noise
      // crest on the plateau does not; the component's peak has passed the whole threshold). A
      // small marker on anatomy's plateau stood 0.33 above it against a threshold of 0.37 (seed
      // 1006 of tests/detect/marker_recall_test.cc's real-CT set 1) and was lost as "merged". A
      // stretched piece short enough to be called merged keeps its verdict: two markers side by
      // side look alike (blob_pair_fit.h takes such pairs apart).
      if ((cand.why == "merged" || cand.why == "too large") && !Stretched(pieces[i], o)) {
        if (local.empty()) {
          for (const Piece& pc : pieces) local.push_back(LocalHalfPeakPiece(contrast, pc, z));
        }
        // Judged on its own region's size; the distances to its neighbours stay those between the
        // component-level centres (a pair of markers 1.2 diameters apart stays "merged").
        std::vector<Piece> judged = pieces;
        for (size_t j = 0; j < pieces.size(); ++j) judged[j].height = local[j].height;
        judged[i].area = local[i].area;
        judged[i].major = local[i].major;
        judged[i].minor = local[i].minor;
        if (OneMarkerOnItsOwn(judged, i, t_peak, z, o)) {
          cand.surroundings_shift_px = cv::norm(local[i].centre - cand.centre);
          TakeOwnRegion(local[i], &cand);
        }
      }
      // A piece too long for any marker pair whose darkest pixel stands on a round, marker-sized
      // region of its own (against its own surroundings, as above) is that marker, touched by a
      // wire or an edge at the component's half-peak level (26 of the 45 markers the real-CT
      // development sets lost as "no blob found there"): the pull of what touches it shows in the
      // core-to-whole shift and the ring's arcs, which widen its covariance (RefineCandidate).
      if (cand.why == "elongated") {
        std::vector<Piece> judged = pieces;
        judged[i].centre = cv::Point2d(pieces[i].peak_at);
        judged[i] = LocalHalfPeakPiece(contrast, judged[i], z);
        if (OneMarkerOnItsOwn(judged, i, t_peak, z, o)) TakeOwnRegion(judged[i], &cand);
      }
      cands.push_back(cand);
    }
  }
  return cands;
}

// Whether the disc or ring of a candidate at `centre` reaches the invalid area (the rim).
bool NearInvalidArea(const cv::Mat& valid, cv::Point2d centre, double r_nom) {
  const cv::Point ip(static_cast<int>(std::lround(centre.x)),
                     static_cast<int>(std::lround(centre.y)));
  const int rr = static_cast<int>(std::ceil(r_nom + 4));
  for (int y = ip.y - rr; y <= ip.y + rr; ++y) {
    for (int x = ip.x - rr; x <= ip.x + rr; ++x) {
      if (x < 0 || y < 0 || x >= valid.cols || y >= valid.rows || !valid.at<uint8_t>(y, x))
        return true;
    }
  }
  return false;
}

// 5, 6. The sub-pixel centre and covariance of candidate i (accepted so far) into det, or its
// rejection.
void RefineCandidate(const cv::Mat& f,
                     const cv::Mat& valid,
                     const std::vector<BlobCandidate>& cands,
                     size_t i,
                     const BlobSizes& z,
                     const CentroidNoise& noise_model,
                     const MarkerBlobOptions& o,
                     cv::Point offset,
                     MarkerBlobDetection* det) {
  const BlobCandidate& c = cands[i];
  const cv::Point2d full = c.centre + cv::Point2d(offset);
  const double r_nom = 0.5 * z.d_nom;
  double nn = 3.0 * z.d_max + 8.0;
  for (size_t j = 0; j < cands.size(); ++j) {
    if (j != i) nn = std::min(nn, cv::norm(cands[j].centre - c.centre));
  }
  cv::Point2d q = c.centre;
  double r_half = 0, shift = 0;
  CentroidNoise noise = noise_model;
  const bool refined = RefineCentroid(f,
                                      valid,
                                      /*dark=*/true,
                                      nn,
                                      1.5 * r_nom + 2.0,
                                      kMarkerCentroidFloor,
                                      &q,
                                      &r_half,
                                      &noise,
                                      &shift);
  if (!refined) {
    det->rejected.push_back(
        {full,
         c.diameter,
         NearInvalidArea(valid, c.centre, r_nom) ? "field-of-view border" : "refinement failed"});
    return;
  }
  if (cv::norm(q - c.centre) > std::max(1.5, 0.25 * z.d_nom)) {
    det->rejected.push_back({full, c.diameter, "refinement failed"});
    return;
  }
  MarkerBlob b;
  if (o.correct_blur_pull) {
    // The blur moves the blob's contrast profile by -s^2 x the log background's gradient
    // (detect_steps.h CentroidNoise::log_background_gradient): whatever the centre estimator,
    // the centre moves with it, and is moved back.
    const cv::Vec2d& g = noise.log_background_gradient;
    b.blur_correction_px = cv::Point2d(g[0], g[1]) * det->blur_variance_px2;
  }
  b.uv_px = q + cv::Point2d(offset) + b.blur_correction_px;
  b.covariance_px2 = noise.covariance_px2;
  b.background_shift_px = shift;
  b.shift_beyond_noise_px = noise.shift_beyond_noise_px;
  if (b.shift_beyond_noise_px > o.unreliable_shift_px) {
    // Next to an edge or a wire the centre's error grows with the core-to-whole shift beyond
    // what noise alone gives it: by a share of the excess (kShiftRmsShare) per axis.
    const double w = kShiftRmsShare * (b.shift_beyond_noise_px - o.unreliable_shift_px);
    b.covariance_px2(0, 0) += w * w;
    b.covariance_px2(1, 1) += w * w;
  }
  // A marker accepted on its own surroundings: what stood beside it one-sidedly at the
  // component's half-peak level (0.41 px away for a wire's end touching a marker 0.55 px off
  // centre, seed 21013 of tests/detect/marker_recall_test.cc) pulls the centroid as much.
  b.covariance_px2(0, 0) += c.surroundings_shift_px * c.surroundings_shift_px;
  b.covariance_px2(1, 1) += c.surroundings_shift_px * c.surroundings_shift_px;
  if (noise.ring_arcs >= 2 && noise.peak_contrast > 0) {
    // A line across the ring (a wire beside or over the marker) crosses the disc too: a line of
    // width W and contrast c_l over a disc of peak contrast c_p moves the centroid by up to about
    // (4 / pi) W c_l / c_p, whatever the disc's size (its share of the disc's weight, 2 r W c_l
    // against pi r^2 c_p / 2, at an offset of up to r). Neither the pixel noise nor the
    // core-to-whole shift shows it (0.71-0.73 px off, 0.05-0.09 px shift, beside a wire in
    // tests/detect/marker_recall_test.cc's real-CT scenes): widened by the RMS share of that
    // bound (kLinePullRmsShare), the bound at most r_half.
    const double ratio = std::min(1.0, noise.ring_arc_contrast / noise.peak_contrast);
    const double w =
        kLinePullRmsShare * std::min(r_half, 4.0 / M_PI * noise.ring_arc_width_px * ratio);
    b.covariance_px2(0, 0) += w * w;
    b.covariance_px2(1, 1) += w * w;
  }
  b.diameter_px = 2 * r_half;
  b.contrast = noise.peak_contrast;
  det->blobs.push_back(b);
}

}  // namespace

MarkerBlobDetection DetectMarkerBlobs(const cv::Mat& image, const MarkerBlobOptions& o) {
  MarkerBlobDetection det;
  if (!o.Check(&det.reason)) return det;
  cv::Mat f;
  cv::Point offset;
  if (!ToFloatGrey(image, o.fov, &f, &offset, &det.reason)) return det;
  const FieldOfView fov = FindFieldOfView(f, o.fov, offset);
  if (fov.have_circle) {
    det.fov_centre = fov.centre + cv::Point2d(offset);
    det.fov_radius = fov.radius;
  }
  BlobSizes z;
  std::tie(z.d_min, z.d_max) = o.DiameterRangePx();
  z.d_nom = 0.5 * (z.d_min + z.d_max);
  z.area_nom = M_PI * 0.25 * z.d_nom * z.d_nom;
  z.min_area = std::max(2.0, 0.25 * M_PI * 0.25 * z.d_min * z.d_min);

  // 3. Contrast image and its noise.
  const cv::Mat search = FlatFieldedSearchImage(f, fov.mask, std::max(z.d_max, 2.0));
  cv::Mat contrast;
  search.convertTo(contrast, CV_32F, -1.0 / 255.0, 1.0);
  contrast.setTo(0, fov.mask == 0);
  const double s = ContrastNoise(contrast, fov.mask);
  if (s == 0) return det.reason = "field of view / region of interest is (almost) empty", det;
  det.noise_contrast = s;
  double sigma_pixel = 0;
  det.correlation_factor =
      NoiseCorrelationFactor(f, fov.refine_valid, &det.noise_rho1, &sigma_pixel);
  CentroidNoise noise;
  noise.correlation_factor = det.correlation_factor;
  noise.rho1 = det.noise_rho1;
  det.blur_variance_px2 = BlurVarianceFromNoiseCorrelation(det.noise_rho1);
  RingNoiseFloors(image, f, fov.refine_valid, sigma_pixel, &noise);
  const double t_low = std::max(4.0 * s, 0.3 * o.min_contrast);
  const double t_peak = std::max(8.0 * s, o.min_contrast);
  const std::vector<BlobCandidate> cands = BlobCandidates(contrast, t_low, t_peak, z, o);
  for (size_t i = 0; i < cands.size(); ++i) {
    if (!cands[i].why.empty()) {
      det.rejected.push_back(
          {cands[i].centre + cv::Point2d(offset), cands[i].diameter, cands[i].why});
      continue;
    }
    RefineCandidate(f, fov.refine_valid, cands, i, z, noise, o, offset, &det);
  }
  det.ok = true;
  return det;
}

}  // namespace carmba
