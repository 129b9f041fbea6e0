// X-ray image rendering of analytic phantoms through the carmba camera model.
//
// MODEL (per detector pixel, in this order)
//  1. Rays. Each pixel is split into S x S sub-pixels (supersampling); sub-pixel (i, j) of pixel
//     (u, v) sits at (u - 1/2 + (i + 1/2)/S, v - 1/2 + (j + 1/2)/S) (pixel (0,0) is the centre of
//     the top-left pixel). Its ray leaves the source (the camera origin) along (x, y, 1), where
//     (x, y) = UnprojectToNormalized(intrinsics, sub-pixel): the image is therefore rendered WITH
//     the camera's distortion, exactly as camera_model.h projects.
//  2. Beer-Lambert: transmission T = exp(-sum_k mu_k L_k), L_k the exact length of the ray inside
//     solid k (sphere chords, box slabs; see sim/phantom.h for embedded spheres).
//  3. Circular field of view (image intensifier): sub-pixels outside the circle get
//     `outside_fov_gray`; the pixel is the mean over its sub-pixels (an anti-aliased edge).
//     Inside, the expected grey level is
//         E = white_level * mean(T) * (1 - vignetting * (r / R)^vignetting_power)
//             * (1 + heel * ((u - u_c) cos(a) + (v - v_c) sin(a)) / R) * background_gain(u, v)
//             * clamp((R - r) / fov_edge_px, 0, 1)          (the last factor only if edge > 0)
//     with r the distance of the pixel centre to the FOV centre (u_c, v_c), R the FOV radius and
//     a = heel_direction_deg: the image intensifier's fall-off towards the rim (vignetting,
//     quadratic by default) and the anode heel effect, a linear gradient of +-heel across the
//     field, brightest in direction a (image x right, y down, degrees).
//  4. Quantum noise: N ~ Poisson(E / white_level * photons_per_pixel), grey = N * white_level /
//     photons_per_pixel (skipped when photons_per_pixel == 0).
//  5. Veiling glare: light scattered inside the intensifier's output optics. Inside the field of
//     view the grey level becomes (1 - g) I + g * (I * coverage) (x) G, with g = glare_fraction,
//     G a normalised Gaussian of sigma glare_sigma_px and coverage the pixel's fraction inside
//     the FOV: a fraction g of the light is spread over the field, lifting the dark parts and
//     lowering the contrast of small objects by about g. (Large sigmas are blurred on a
//     reduced grid; the glare is smooth at that scale.)
//  6. Detector blur: Gaussian, sigma `blur_sigma_px` (applied after the quanta are detected, as
//     in an image intensifier's phosphor and optics; it also smooths the noise).
//  7. Read noise: additive Gaussian, sigma `read_noise_gray`.
// The result is a CV_32F image of grey levels; ToOutputImage() rounds and saturates to 8 or 16
// bits. Metal (large mu) appears DARK on a bright background, as in fluoroscopy displays.
//
// Deterministic: the noise comes from carmba::Rng (std::mt19937_64, util/random.h) seeded with
// `seed`.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "camera/camera.h"
#include "camera/carm_geometry.h"
#include "sim/phantom.h"
#include "util/status.h"

namespace carmba::sim {

struct RenderOptions {
  int supersampling = 3;          // S: S x S rays per pixel (1..16)
  double white_level = 220.0;     // grey level of an unattenuated ray at the FOV centre (<= 1e6)
  double photons_per_pixel = 0;   // detected quanta per pixel of an unattenuated ray; 0 = no noise
  double read_noise_gray = 0.0;   // additive Gaussian noise sigma (grey levels)
  double blur_sigma_px = 0.0;     // detector blur sigma (px), 0..50; 0 = none
  bool circular_fov = true;       // image-intensifier circle; false = the whole detector
  double fov_radius_px = 0.0;     // 0 = min(width, height) / 2
  double fov_center_u_px = -1.0;  // < 0 = image centre ((width - 1) / 2)
  double fov_center_v_px = -1.0;  // < 0 = image centre ((height - 1) / 2)
  double outside_fov_gray = 0.0;  // grey level outside the field of view
  double vignetting = 0.0;        // relative intensity loss at the FOV edge, in [0, 1)
  double vignetting_power = 2.0;  // profile exponent p of the loss (r / R)^p, in [0.5, 16]
  double heel = 0.0;              // heel-effect gradient: +-heel at the FOV rim, in [0, 0.5]
  double heel_direction_deg = 0;  // image direction of the brighter side (0 = +x, 90 = +y)
  double glare_fraction = 0.0;    // veiling glare g, fraction of the light spread, in [0, 0.9]
  double glare_sigma_px = 50.0;   // spread of the glare (Gaussian sigma, px), in [1, 1000]
  double fov_edge_px = 0.0;  // width of the linear fall-off to 0 inside the FOV edge; 0 = sharp
  cv::Mat background_gain;   // optional CV_32F, image-sized, multiplicative, values in (0, 1]
  uint64_t seed = 1;

  bool Check(std::string* error) const;
};

// A phantom placed in the camera frame.
struct PlacedPhantom {
  const Phantom* phantom = nullptr;
  Rigid3 cam_from_phantom;
};

// The undistorted ray directions of every sub-pixel inside the field of view, for one camera,
// supersampling and FOV. Building it costs one UnprojectToNormalized per sub-pixel; reuse it for
// all views of a scene (RenderXray builds one itself when given none).
class RayGrid {
 public:
  // Error when the distortion cannot be inverted at some sub-pixel inside the field of view.
  static StatusOr<std::shared_ptr<const RayGrid>> Build(const Camera& camera,
                                                        const RenderOptions& options);
  int width() const { return width_; }
  int height() const { return height_; }
  int supersampling() const { return ss_; }
  bool Matches(const Camera& camera, const RenderOptions& options) const;

  // Normalised (x, y) of sub-pixel s (0 .. S*S-1) of pixel (u, v); inside() false when the
  // sub-pixel lies outside the field of view.
  bool inside(int u, int v, int s) const { return inside_[Index(u, v, s)] != 0; }
  const float* xy(int u, int v, int s) const { return &xy_[2 * Index(u, v, s)]; }
  // Vignetting-free FOV coverage is implied by inside(); r2 = (r / R)^2 of the pixel centre.
  float radius2(int u, int v) const { return r2_[static_cast<size_t>(v) * width_ + u]; }

 private:
  size_t Index(int u, int v, int s) const {
    return (static_cast<size_t>(v) * width_ + u) * ss_ * ss_ + s;
  }
  int width_ = 0, height_ = 0, ss_ = 1;
  std::array<double, kNumIntrinsics> params_{};
  bool circular_ = true;
  double fov_r_ = 0, fov_u_ = 0, fov_v_ = 0;
  std::vector<float> xy_;
  std::vector<uint8_t> inside_;
  std::vector<float> r2_;
};

// Renders the phantoms. `grid` may be null (built here) or a grid from RayGrid::Build with the
// same camera and options. Returns CV_32F grey levels, camera.height x camera.width.
StatusOr<cv::Mat> RenderXray(const Camera& camera,
                             const std::vector<PlacedPhantom>& phantoms,
                             const RenderOptions& options,
                             const RayGrid* grid = nullptr);

// Rounds and saturates a CV_32F grey image to CV_8U (bit_depth 8) or CV_16U (bit_depth 16).
cv::Mat ToOutputImage(const cv::Mat& gray, int bit_depth);

// Writes a CV_8U / CV_16U image as .png or .pgm (by extension). Error names the path.
Status WriteImage(const std::string& path, const cv::Mat& image);

// Pixel positions (u, v) of the sphere centres of a placed phantom (camera_model.h projection,
// with distortion), in the phantom's sphere order. Error if a centre is behind the source.
StatusOr<std::vector<Eigen::Vector2d>> ProjectSphereCenters(const Camera& camera,
                                                            const PlacedPhantom& placed);

// The radius (px) of the smallest circle about `uv_center` containing the silhouette of sphere
// `s` (camera frame centre/radius), sampled along its tangent cone with distortion. Used for
// field-of-view checks and render culling.
double SphereImageRadius(const Camera& camera,
                         const Eigen::Vector3d& center_in_cam_mm,
                         double radius_mm,
                         const Eigen::Vector2d& uv_center);

// The interval [t0, t1] of the ray origin + t dir (t >= 0) inside the axis-aligned box [lo, hi],
// by the slab method; false when it misses. The renderer's boxes and the anatomy's CT
// (sim/ct_anatomy.h) share it.
inline bool RayBoxInterval(const Eigen::Vector3d& origin,
                           const Eigen::Vector3d& dir,
                           const Eigen::Vector3d& lo,
                           const Eigen::Vector3d& hi,
                           double* t0,
                           double* t1) {
  double a = 0.0, b = std::numeric_limits<double>::infinity();
  for (int i = 0; i < 3; ++i) {
    const double o = origin[i];
    if (std::fabs(dir[i]) < 1e-15) {
      if (o < lo[i] || o > hi[i]) return false;
      continue;
    }
    const double inv = 1.0 / dir[i];
    double ta = (lo[i] - o) * inv, tb = (hi[i] - o) * inv;
    if (ta > tb) std::swap(ta, tb);
    a = std::max(a, ta);
    b = std::min(b, tb);
    if (a >= b) return false;
  }
  *t0 = a;
  *t1 = b;
  return true;
}

// The image intensifier's field of view as `o` gives it for `camera` (px): its centre (u, v), by
// default the image centre, and radius r, by default half the smaller side; circular false: the
// whole detector is exposed.
struct FovCircle {
  bool circular = true;
  double u = 0, v = 0, r = 0;
};
FovCircle FovOf(const Camera& camera, const RenderOptions& o);

// A multiplicative background from a real X-ray frame: a DICOM file (io/dicom_xray.h: the first
// frame, or frame N of `file.dcm#frameN`; MONOCHROME2 convention, stored values) or any image
// OpenCV reads. A square of `crop_fraction` (0 < f <= 1) of the frame's shorter side, centred at
// `crop_center` (fractions of the frame's width and height; the square is moved inside the frame
// where it would leave it), is cut out, resized to width x height, normalised by its 99th
// percentile and mapped to
//   gain = 1 - strength + strength * clamp(value, 0.02, 1).
StatusOr<cv::Mat> LoadBackgroundGain(const std::string& path,
                                     int width,
                                     int height,
                                     double strength,
                                     double crop_fraction,
                                     cv::Point2d crop_center = cv::Point2d(0.5, 0.5));

}  // namespace carmba::sim
