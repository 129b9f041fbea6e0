#include "sim/xray_render.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>

#include "camera/camera_model.h"
#include "util/image_codecs.h"
#include "util/plausible.h"
#include "util/random.h"

namespace carmba::sim {

bool RenderOptions::Check(std::string* error) const {
  if (supersampling < 1 || supersampling > 16) {
    return *error = "supersampling must be in 1..16", false;
  }
  const double v[] = {white_level,
                      photons_per_pixel,
                      read_noise_gray,
                      blur_sigma_px,
                      fov_radius_px,
                      fov_center_u_px,
                      fov_center_v_px,
                      outside_fov_gray,
                      vignetting,
                      vignetting_power,
                      heel,
                      heel_direction_deg,
                      glare_fraction,
                      glare_sigma_px,
                      fov_edge_px};
  for (double x : v) {
    if (!std::isfinite(x)) return *error = "render options: non-finite value", false;
  }
  if (!(white_level > 0)) return *error = "white_level must be positive", false;
  if (!CheckRange("photons_per_pixel", photons_per_pixel, plausible::kPhotonsPerPixel, error) ||
      !CheckRange("read_noise_gray", read_noise_gray, plausible::kGreyLevel, error) ||
      !CheckRange("outside_fov_gray", outside_fov_gray, plausible::kGreyLevel, error)) {
    return false;
  }
  if (!(blur_sigma_px >= 0 && blur_sigma_px <= 50)) {
    return *error = "blur_sigma_px must be in [0, 50] px", false;
  }
  if (!(white_level <= 1e6)) return *error = "white_level must be <= 1e6 grey levels", false;
  if (fov_radius_px < 0) return *error = "fov_radius_px must be >= 0", false;
  if (outside_fov_gray < 0) return *error = "outside_fov_gray must be >= 0", false;
  if (!(vignetting >= 0 && vignetting < 1)) return *error = "vignetting must be in [0, 1)", false;
  if (!(vignetting_power >= 0.5 && vignetting_power <= 16)) {
    return *error = "vignetting_power must be in [0.5, 16]", false;
  }
  if (!(heel >= 0 && heel <= 0.5)) return *error = "heel must be in [0, 0.5]", false;
  if (!(glare_fraction >= 0 && glare_fraction <= 0.9)) {
    return *error = "glare fraction must be in [0, 0.9]", false;
  }
  if (!(glare_sigma_px >= 1 && glare_sigma_px <= 1000)) {
    return *error = "glare sigma_px must be in [1, 1000] px", false;
  }
  if (fov_edge_px < 0) return *error = "fov edge must be >= 0", false;
  if (!background_gain.empty() && background_gain.type() != CV_32F) {
    return *error = "background_gain must be CV_32F", false;
  }
  return true;
}

FovCircle FovOf(const Camera& camera, const RenderOptions& o) {
  FovCircle f;
  f.circular = o.circular_fov;
  f.u = o.fov_center_u_px >= 0 ? o.fov_center_u_px : 0.5 * (camera.width - 1);
  f.v = o.fov_center_v_px >= 0 ? o.fov_center_v_px : 0.5 * (camera.height - 1);
  f.r = o.fov_radius_px > 0 ? o.fov_radius_px : 0.5 * std::min(camera.width, camera.height);
  return f;
}

namespace {

// UnprojectToNormalized (same Gauss-Newton, same 1e-10 px stop) started from `seed_xy`, the
// solution of a nearby pixel: a sub-pixel's neighbour is a fraction of a pixel away, so one or two
// steps converge instead of the ~5 from the undistorted guess. Falls back to the full routine.
bool UnprojectNear(const double* in, const double* uv, const double* seed_xy, double* xy) {
  return UnprojectToNormalizedFrom(in, uv, seed_xy, 8, xy) || UnprojectToNormalized(in, uv, xy);
}

}  // namespace

StatusOr<std::shared_ptr<const RayGrid>> RayGrid::Build(const Camera& camera,
                                                        const RenderOptions& options) {
  CARMBA_RETURN_IF_ERROR(camera.Check());
  std::string error;
  if (!options.Check(&error)) return Status::Error(error);
  auto grid = std::make_shared<RayGrid>();
  const FovCircle fov = FovOf(camera, options);
  const int S = options.supersampling;
  grid->width_ = camera.width;
  grid->height_ = camera.height;
  grid->ss_ = S;
  grid->params_ = camera.params;
  grid->circular_ = fov.circular;
  grid->fov_r_ = fov.r;
  grid->fov_u_ = fov.u;
  grid->fov_v_ = fov.v;
  const size_t n = static_cast<size_t>(camera.width) * camera.height * S * S;
  constexpr size_t kMaxSubPixels = size_t{1} << 26;  // 64 M rays: 768 MB of ray grid
  if (n > kMaxSubPixels) {
    return Status::Error("image " + std::to_string(camera.width) + "x" +
                         std::to_string(camera.height) + " with supersampling " +
                         std::to_string(S) + " needs " + std::to_string(n) +
                         " rays, more than 2^26: reduce the supersampling or the image size");
  }
  grid->xy_.assign(2 * n, 0.0f);
  grid->inside_.assign(n, 0);
  grid->r2_.assign(static_cast<size_t>(camera.width) * camera.height, 0.0f);
  const double r2_max = fov.r * fov.r;
  for (int v = 0; v < camera.height; ++v) {
    double seed[2] = {0, 0};  // the previous sub-pixel's ray (same row of pixels)
    bool have_seed = false;
    for (int u = 0; u < camera.width; ++u) {
      const double du = u - fov.u, dv = v - fov.v;
      grid->r2_[static_cast<size_t>(v) * camera.width + u] =
          static_cast<float>((du * du + dv * dv) / r2_max);
      for (int j = 0; j < S; ++j) {
        for (int i = 0; i < S; ++i) {
          const double uv[2] = {u - 0.5 + (i + 0.5) / S, v - 0.5 + (j + 0.5) / S};
          const size_t k = grid->Index(u, v, j * S + i);
          if (fov.circular) {
            const double eu = uv[0] - fov.u, ev = uv[1] - fov.v;
            if (eu * eu + ev * ev > r2_max) continue;
          }
          double xy[2];
          const bool ok = have_seed ? UnprojectNear(camera.params.data(), uv, seed, xy)
                                    : UnprojectToNormalized(camera.params.data(), uv, xy);
          if (ok) seed[0] = xy[0], seed[1] = xy[1], have_seed = true;
          if (!ok) {
            return Status::Error("the distortion cannot be inverted at pixel (" +
                                 std::to_string(uv[0]) + ", " + std::to_string(uv[1]) +
                                 ") inside the field of view; reduce the distortion or the FOV");
          }
          grid->inside_[k] = 1;
          grid->xy_[2 * k] = static_cast<float>(xy[0]);
          grid->xy_[2 * k + 1] = static_cast<float>(xy[1]);
        }
      }
    }
  }
  return std::shared_ptr<const RayGrid>(grid);
}

bool RayGrid::Matches(const Camera& camera, const RenderOptions& options) const {
  const FovCircle fov = FovOf(camera, options);
  return width_ == camera.width && height_ == camera.height && ss_ == options.supersampling &&
         params_ == camera.params && circular_ == fov.circular && fov_r_ == fov.r &&
         fov_u_ == fov.u && fov_v_ == fov.v;
}

double SphereImageRadius(const Camera& camera,
                         const Eigen::Vector3d& c,
                         double radius_mm,
                         const Eigen::Vector2d& uv_center) {
  const double dist = c.norm();
  if (!(dist > radius_mm)) return std::numeric_limits<double>::infinity();
  const Eigen::Vector3d axis = c / dist;
  const Eigen::Vector3d e1 = axis.unitOrthogonal();
  const Eigen::Vector3d e2 = axis.cross(e1);
  const double sa = radius_mm / dist, ca = std::sqrt(1.0 - sa * sa);
  double r_max = 0.0;
  constexpr int kSamples = 32;
  for (int k = 0; k < kSamples; ++k) {
    const double phi = 2.0 * M_PI * k / kSamples;
    const Eigen::Vector3d d = axis * ca + (e1 * std::cos(phi) + e2 * std::sin(phi)) * sa;
    double uv[2];
    if (!ProjectCamPoint(camera.params.data(), d.data(), uv)) {
      return std::numeric_limits<double>::infinity();
    }
    r_max = std::max(r_max, std::hypot(uv[0] - uv_center.x(), uv[1] - uv_center.y()));
  }
  return r_max;
}

StatusOr<std::vector<Eigen::Vector2d>> ProjectSphereCenters(const Camera& camera,
                                                            const PlacedPhantom& placed) {
  std::vector<Eigen::Vector2d> out;
  for (const auto& s : placed.phantom->spheres) {
    const Eigen::Vector3d p = placed.cam_from_phantom * s.center_mm;
    double uv[2];
    if (!ProjectCamPoint(camera.params.data(), p.data(), uv)) {
      return Status::Error("sphere " + std::to_string(s.id) + " is not in front of the source");
    }
    out.emplace_back(uv[0], uv[1]);
  }
  return out;
}

namespace {

// A sphere and a box in the camera frame, ready for ray tests.
struct CamSphere {
  Eigen::Vector3d c;
  double c2, r2, mu;
  int host;  // global box index or -1
  double mu_host;
  int u0, u1, v0, v1;  // pixel bounding box
};
struct CamBox {
  Eigen::Matrix3d box_from_cam_R;
  Eigen::Vector3d source_in_box;
  Eigen::Vector3d h;
  double mu;
};

// Interval [t0, t1] of the ray t*d (|d| = 1) inside the box; false if it misses.
inline bool BoxInterval(const CamBox& b, const Eigen::Vector3d& d, double* t0, double* t1) {
  return RayBoxInterval(b.source_in_box, b.box_from_cam_R * d, -b.h, b.h, t0, t1);
}

constexpr int kTile = 16;

// Step 5 of the model (header): I <- (1 - g) I + g * (I * coverage) (x) G inside the FOV. The
// Gaussian is applied on a grid reduced by up to sigma / 4 (at least 4 samples per sigma), then
// interpolated back: the glare is smooth at that scale.
void AddVeilingGlare(const cv::Mat& coverage, const RenderOptions& o, cv::Mat* image) {
  const double g = o.glare_fraction;
  cv::Mat light = image->mul(coverage);
  const int factor = std::max(1, static_cast<int>(o.glare_sigma_px / 4.0));
  cv::Mat small, spread;
  if (factor > 1) {
    cv::resize(light,
               small,
               cv::Size((light.cols + factor - 1) / factor, (light.rows + factor - 1) / factor),
               0,
               0,
               cv::INTER_AREA);
  } else {
    small = light;
  }
  const double sigma = o.glare_sigma_px * small.cols / static_cast<double>(light.cols);
  cv::GaussianBlur(small, small, cv::Size(0, 0), sigma, sigma, cv::BORDER_CONSTANT);
  if (factor > 1) {
    cv::resize(small, spread, light.size(), 0, 0, cv::INTER_LINEAR);
  } else {
    spread = small;
  }
  for (int v = 0; v < image->rows; ++v) {
    float* row = image->ptr<float>(v);
    const float* cov = coverage.ptr<float>(v);
    const float* sp = spread.ptr<float>(v);
    for (int u = 0; u < image->cols; ++u) {
      if (cov[u] > 0) row[u] = static_cast<float>((1.0 - g) * row[u] + g * cov[u] * sp[u]);
    }
  }
}

}  // namespace

namespace {

// A sphere in the camera frame with the pixel box its image can reach (px).
CamSphere SphereInCamera(const Camera& camera,
                         const PlacedPhantom& placed,
                         const SpherePrimitive& s,
                         int box_base) {
  CamSphere cs;
  cs.c = placed.cam_from_phantom * s.center_mm;
  cs.c2 = cs.c.squaredNorm();
  cs.r2 = s.radius_mm * s.radius_mm;
  cs.mu = s.mu_per_mm;
  cs.host = s.host_box >= 0 ? box_base + s.host_box : -1;
  cs.mu_host = s.host_box >= 0 ? placed.phantom->boxes[s.host_box].mu_per_mm : 0.0;
  double uv[2];
  ProjectCamPoint(camera.params.data(), cs.c.data(), uv);
  const double r_px = SphereImageRadius(camera, cs.c, s.radius_mm, {uv[0], uv[1]}) + 2.0;
  if (!std::isfinite(r_px)) {
    cs.u0 = cs.v0 = 0;
    cs.u1 = camera.width - 1;
    cs.v1 = camera.height - 1;
  } else {
    cs.u0 = static_cast<int>(std::floor(uv[0] - r_px));
    cs.u1 = static_cast<int>(std::ceil(uv[0] + r_px));
    cs.v0 = static_cast<int>(std::floor(uv[1] - r_px));
    cs.v1 = static_cast<int>(std::ceil(uv[1] + r_px));
  }
  return cs;
}

// The phantoms' boxes and spheres in the camera frame; an error for a sphere not wholly in front
// of the source.
Status SolidsInCameraFrame(const Camera& camera, const std::vector<PlacedPhantom>& phantoms,
                           std::vector<CamBox>* boxes, std::vector<CamSphere>* spheres) {
  for (const auto& placed : phantoms) {
    if (!placed.phantom) return Status::Error("null phantom");
    const int box_base = static_cast<int>(boxes->size());
    for (const auto& b : placed.phantom->boxes) {
      const Rigid3 box_from_cam = (placed.cam_from_phantom * b.phantom_from_box).Inverse();
      boxes->push_back({box_from_cam.R, box_from_cam.t, b.half_size_mm, b.mu_per_mm});
    }
    for (const auto& s : placed.phantom->spheres) {
      if (!((placed.cam_from_phantom * s.center_mm).z() > s.radius_mm)) {
        return Status::Error("sphere " + std::to_string(s.id) +
                             " is not entirely in front of the source");
      }
      spheres->push_back(SphereInCamera(camera, placed, s, box_base));
    }
  }
  return Status::Ok();
}

// The line integral of mu along the unit ray d: every box's chord, the chord of each sphere of
// the tile, less the part of its host box the sphere displaces. box_t0, box_t1, box_hit are
// scratch (per box).
double LineIntegral(const Eigen::Vector3d& d,
                    const std::vector<CamBox>& boxes,
                    const std::vector<CamSphere>& spheres,
                    const std::vector<int>& tile_spheres,
                    std::vector<double>* box_t0,
                    std::vector<double>* box_t1,
                    std::vector<char>* box_hit) {
  double line_integral = 0.0;
  for (size_t b = 0; b < boxes.size(); ++b) {
    (*box_hit)[b] = BoxInterval(boxes[b], d, &(*box_t0)[b], &(*box_t1)[b]);
    if ((*box_hit)[b]) line_integral += boxes[b].mu * ((*box_t1)[b] - (*box_t0)[b]);
  }
  for (int k : tile_spheres) {
    const CamSphere& sp = spheres[k];
    const double b = d.dot(sp.c);
    const double disc = sp.r2 - (sp.c2 - b * b);
    if (disc <= 0) continue;
    const double h = std::sqrt(disc);
    line_integral += sp.mu * 2.0 * h;
    if (sp.host >= 0 && (*box_hit)[sp.host]) {
      const double overlap =
          std::min(b + h, (*box_t1)[sp.host]) - std::max(b - h, (*box_t0)[sp.host]);
      if (overlap > 0) line_integral -= sp.mu_host * overlap;
    }
  }
  return line_integral;
}

// The gain of a pixel: white level, vignetting, heel effect, the field of view's soft edge, the
// background.
struct PixelGainModel {
  PixelGainModel(const Camera& camera, const RenderOptions& o)
      : options(o), fov(FovOf(camera, o)), edge_px(fov.circular ? o.fov_edge_px : 0.0),
        heel_cu(std::cos(o.heel_direction_deg * M_PI / 180.0) / fov.r),
        heel_cv(std::sin(o.heel_direction_deg * M_PI / 180.0) / fov.r) {}

  // Pixel (u, v) with r2 its squared normalised radius.
  double operator()(int u, int v, float r2) const {
    const double fall = options.vignetting_power == 2.0
                            ? r2
                            : std::pow(static_cast<double>(r2), 0.5 * options.vignetting_power);
    double gain = options.white_level * (1.0 - options.vignetting * fall);
    if (options.heel > 0) {
      gain *= 1.0 + options.heel * ((u - fov.u) * heel_cu + (v - fov.v) * heel_cv);
    }
    if (edge_px > 0) {
      gain *= std::clamp((fov.r * (1.0 - std::sqrt(r2))) / edge_px, 0.0, 1.0);
    }
    if (!options.background_gain.empty()) {
      gain *= options.background_gain.at<float>(v, u);
    }
    return gain;
  }

  const RenderOptions& options;
  const FovCircle fov;
  const double edge_px, heel_cu, heel_cv;
};

// The expected grey levels: every sub-pixel ray of the grid through the solids, tile by tile
// (each tile tests only the spheres whose image reaches it); coverage (when not empty) the
// fraction of each pixel inside the field of view.
void RenderExpected(const Camera& camera, const RenderOptions& options, const RayGrid& grid,
                    const std::vector<CamBox>& boxes, const std::vector<CamSphere>& spheres,
                    cv::Mat* expected, cv::Mat* coverage) {
  const int W = camera.width, H = camera.height, SS = options.supersampling * options.supersampling;
  const PixelGainModel pixel_gain(camera, options);
  std::vector<double> box_t0(boxes.size()), box_t1(boxes.size());
  std::vector<char> box_hit(boxes.size());
  std::vector<int> tile_spheres;
  for (int tv = 0; tv < H; tv += kTile) {
    for (int tu = 0; tu < W; tu += kTile) {
      const int tu1 = std::min(W, tu + kTile) - 1, tv1 = std::min(H, tv + kTile) - 1;
      tile_spheres.clear();
      for (int k = 0; k < static_cast<int>(spheres.size()); ++k) {
        const CamSphere& s = spheres[k];
        if (s.u1 >= tu && s.u0 <= tu1 && s.v1 >= tv && s.v0 <= tv1) tile_spheres.push_back(k);
      }
      for (int v = tv; v <= tv1; ++v) {
        float* row = expected->ptr<float>(v);
        for (int u = tu; u <= tu1; ++u) {
          double sum = 0.0;
          int n_inside = 0;
          for (int s = 0; s < SS; ++s) {
            if (!grid.inside(u, v, s)) continue;
            ++n_inside;
            const float* xy = grid.xy(u, v, s);
            Eigen::Vector3d d(xy[0], xy[1], 1.0);
            d.normalize();
            const double mu_l =
                LineIntegral(d, boxes, spheres, tile_spheres, &box_t0, &box_t1, &box_hit);
            sum += mu_l == 0 ? 1.0 : std::exp(-mu_l);  // a ray through nothing: no exp
          }
          double value = options.outside_fov_gray * (SS - n_inside) / SS;
          if (n_inside > 0) value += pixel_gain(u, v, grid.radius2(u, v)) * sum / SS;
          row[u] = static_cast<float>(value);
          if (!coverage->empty()) coverage->at<float>(v, u) = static_cast<float>(n_inside) / SS;
        }
      }
    }
  }
}

// The detector on the expected image: quantum (Poisson) noise, veiling glare, blur, read noise.
void AddDetectorEffects(const RenderOptions& options, const cv::Mat& coverage, cv::Mat* image_ptr) {
  cv::Mat& image = *image_ptr;
  const int W = image.cols, H = image.rows;
  Rng rng(options.seed);
  if (options.photons_per_pixel > 0) {
    const double quanta_per_gray = options.photons_per_pixel / options.white_level;
    for (int v = 0; v < H; ++v) {
      float* row = image.ptr<float>(v);
      for (int u = 0; u < W; ++u) {
        const double mean = std::max(0.0, static_cast<double>(row[u])) * quanta_per_gray;
        if (mean <= 0) continue;
        std::poisson_distribution<long> poisson(mean);
        row[u] = static_cast<float>(poisson(rng) / quanta_per_gray);
      }
    }
  }
  if (options.glare_fraction > 0) AddVeilingGlare(coverage, options, &image);
  if (options.blur_sigma_px > 0) {
    cv::GaussianBlur(image, image, cv::Size(0, 0), options.blur_sigma_px, options.blur_sigma_px,
                     cv::BORDER_REFLECT);
  }
  if (options.read_noise_gray > 0) {
    std::normal_distribution<double> normal(0.0, options.read_noise_gray);
    for (int v = 0; v < H; ++v) {
      float* row = image.ptr<float>(v);
      for (int u = 0; u < W; ++u) row[u] += static_cast<float>(normal(rng));
    }
  }
}

}  // namespace

StatusOr<cv::Mat> RenderXray(const Camera& camera,
                             const std::vector<PlacedPhantom>& phantoms,
                             const RenderOptions& options,
                             const RayGrid* grid) {
  CARMBA_RETURN_IF_ERROR(camera.Check());
  std::string error;
  if (!options.Check(&error)) return Status::Error(error);
  if (!options.background_gain.empty() && (options.background_gain.cols != camera.width ||
                                           options.background_gain.rows != camera.height)) {
    return Status::Error("background_gain size differs from the image size");
  }
  std::shared_ptr<const RayGrid> own;
  if (!grid || !grid->Matches(camera, options)) {
    auto built = RayGrid::Build(camera, options);
    if (!built.ok()) return built.status();
    own = *built;
    grid = own.get();
  }
  std::vector<CamBox> boxes;
  std::vector<CamSphere> spheres;
  CARMBA_RETURN_IF_ERROR(SolidsInCameraFrame(camera, phantoms, &boxes, &spheres));
  cv::Mat expected(camera.height, camera.width, CV_32F);
  cv::Mat coverage;  // fraction of the pixel inside the FOV (for the glare)
  if (options.glare_fraction > 0) coverage.create(camera.height, camera.width, CV_32F);
  RenderExpected(camera, options, *grid, boxes, spheres, &expected, &coverage);
  cv::Mat image = expected;
  AddDetectorEffects(options, coverage, &image);
  return image;
}

cv::Mat ToOutputImage(const cv::Mat& gray, int bit_depth) {
  cv::Mat out;
  gray.convertTo(out, bit_depth == 16 ? CV_16U : CV_8U);  // rounds and saturates
  return out;
}

Status WriteImage(const std::string& path, const cv::Mat& image) {
  const auto dot = path.find_last_of('.');
  const std::string ext = dot == std::string::npos ? "" : path.substr(dot + 1);
  if (ext != "png" && ext != "pgm") {
    return Status::Error(path + ": unsupported image extension, expected .png or .pgm");
  }
  if (image.type() != CV_8U && image.type() != CV_16U) {
    return Status::Error(path + ": image must be 8- or 16-bit single channel");
  }
  try {
    if (!ImWrite(path, image)) return Status::Error(path + ": cannot write image");
  } catch (const cv::Exception& e) {
    return Status::Error(path + ": cannot write image: " + e.what());
  }
  return Status::Ok();
}

}  // namespace carmba::sim
