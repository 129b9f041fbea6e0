// Spherical metal markers in a CT volume: segmentation, sub-voxel centres, covariance. Made to
// work in real anatomy with default settings (bone, teeth, air next to the markers).
//
// 1. Threshold: voxels with HU >= threshold_hu are candidate cores (default 1500 HU: below any
//    metal marker's peak, above soft tissue; dense bone and teeth pass and are sorted out by
//    3.-6.). More than max_core_fraction of all voxels above it is refused as a wrong threshold.
// 2. 3-D connected components of the core voxels (26-connectivity, union-find; no ITK).
// 3. Seeds. A component smaller than min_volume_fraction x the nominal sphere volume pi d^3 / 6,
//    or touching the volume's border, is rejected. One up to max_volume_fraction x nominal is one
//    seed (its core centroid). A larger one (a marker touching bone or teeth above the threshold,
//    or bone alone) is seeded at its local maxima, strongest first, at least d/2 apart (at most
//    max_seeds_per_component), each skipped within d of a marker already accepted.
// 4. Centre: the intensity-weighted centroid c = sum_i w_i p_i / W, W = sum_i w_i,
//    w_i = HU_i - b, over the region of interest of voxels whose box (voxel extent along the
//    volume axes) comes within R_roi = max(d/2, r_core) + roi_margin_mm of the current centre,
//    where r_core is the radius of a sphere of the core's volume. b is the local background: the
//    median HU of a shell of voxels beyond the ROI (0.5 .. 0.5 + shell_mm mm outside it); sigma_b,
//    the local noise, is 1.4826 x the shell's median absolute deviation. Started at the seed, the
//    ROI is re-centred and the centroid recomputed `iterations` times. Because every voxel is a
//    box average of the object (partial volume), the weighted centroid is the object's centre up
//    to the sampling (aliasing) error below -- when its surroundings are uniform. The thesis's
//    bounding-box centre of the core voxels is computed too (for the report).
// 5. Covariance of the centroid (3x3, mm^2, patient frame) = noise term + background term +
//    sampling term, in the volume's axis frame, rotated to patient coordinates:
//    - noise: sigma_b^2 sum_i (p_i - c)(p_i - c)^T / W^2 (independent voxel noise); sigma_b is
//      raised to the RMS of the background's odd part when that is larger: each voxel of the
//      ROI's rim and the shell (beyond R + the largest voxel extent) against the trilinear value
//      at its reflection through the centre, (v - v') / sqrt(2). Only the odd part of a
//      structured background (metal streaks, a neighbour's artefacts, an edge) moves the
//      centroid; white noise gives about sigma_b (odd_background_hu);
//    - background: sigma_b^2 / N_shell g g^T, g = sum_i (p_i - c) / W (error of b);
//    - sampling: along each volume axis a, the centroid error of a ball of the nominal diameter
//      box-filtered over the voxel extent (pixel spacing, or the slice thickness along k) and
//      sampled at the spacing is a periodic function of the ball's sub-voxel phase (separable:
//      it depends only on the 1-D projection of the ball, pi (R^2 - x^2)). Treating the phase
//      as uniform, its variance is computed numerically over 64 phases. This is the error over
//      "where the marker happens to sit in the voxel grid"; it dominates with thick slices.
// 6. Partial-volume ball fit and validation. A seed whose peak is below b + f_min (min_metal_hu
//    - b), f_min the least largest-voxel fraction of the nominal ball over sub-voxel positions,
//    is not metal. Otherwise the model v_i = b' + (M - b') f_i(c) (f_i the fraction of voxel i
//    inside the ball of the nominal diameter centred at c, exact along the slice axis and
//    sub-sampled in-plane) is fitted by robust (Cauchy) Gauss-Newton over the voxels within
//    d/2 + the largest voxel extent, from the peak voxel, the seed and the centroid (each
//    re-fitted once around its result, kept within d/2 per pass and within d/2 + half a voxel
//    diagonal of the peak; the lowest mean robust cost wins). Bone or air beside the marker are
//    outliers to it. A candidate is a marker when the fit converged, its M >= min_metal_hu
//    (metal, not bone; partial volume removed), the voxels most inside the ball (f >= 0.75 x the
//    largest f) agree with the fit within 25 % of their contrast in at least min_inner_fraction
//    of cases (ball-shaped), and the fitted centre is within d/2 + half a voxel extent of the seed.
//    Fit covariance: s^2 H^-1 over (c, M, b') with H = sum_i w_i J_i J_i^T, s^2 the larger of
//    the robust residual variance and the mean square residual of the voxels the surface cuts
//    (0 < f < 1: bone or air mixed into them shows there), plus the sampling term of 5.
// 7. Contamination. chi2 = (c_centroid - c_fit)^T (C_centroid + C_fit)^-1 (c_centroid - c_fit).
//    Above contamination_chi2 (default 11.34, 1 % of uncontaminated markers) the surroundings pull
//    the centroid: the centre is the fit's, with the fit's covariance. Otherwise the centre is
//    the centroid, its covariance multiplied by max(1, chi2 / 3) (the Birge ratio of the two
//    estimates' disagreement). When the centroid has no mass (W <= 0: the surroundings outweigh
//    the marker) the fit is used.
//    Neither model includes correlated noise (beyond the odd-part RMS of 5.), the
//    scanner's point-spread function (the fit's partial-volume model is the simulator's box
//    model), or marker diameters different from the nominal one.
// 8. Saturated metal (real scanners). A scanner stores HU up to a maximum (3071 for most: 12-bit
//    stored values); metal above it is clipped, so its voxels hold that maximum, the box model of
//    6. does not hold, and blooming, streaks and a holder touching the marker distort the
//    partial-volume rim. The clip is read from the data: the volume's largest value, when at
//    least kMinClippedVoxels voxels hold it and it is >= threshold_hu (clip_hu > 0 sets it, < 0
//    disables). A seed whose peak is at the clip is measured by two independent estimators:
//    - surface fit: from the most interior clipped voxel within 1.5 R of the seed (farthest from
//      any voxel below the clip: the ball is thicker than a post or tail), 400 rays (a Fibonacci
//      sphere) each find where the trilinear HU falls below the half level L = b + (clip - b) / 2
//      (b the median of a shell 1.5 R + 1 .. 1.5 R + 2.5 mm out, R the nominal radius), then again
//      below the ray's own half level, between the clip and the median 1 .. 2 mm beyond that first
//      edge (a holder on one side, air on the other would move a common level's crossing
//      unequally); an axis-aligned spheroid (centre, in-plane and along-slice radii: the scanner's
//      blur differs in and across the slices) is fitted to these edge points by Tukey-weighted
//      Gauss-Newton (4.685 x the MAD of the radial residuals, the scale frozen after 3 iterations;
//      steps at most 0.5 mm, radii kept within 0.3 .. 2.5 R), the rays re-cast from the new centre
//      4 times. Rays that run into a post, a pin or the holder, or stop early in a streak, are
//      outliers. Covariance: s^2 H^-1 of the centre, s^2 the weighted residual variance, multiplied
//      by n_inliers / n_eff, plus the sampling term of 5. at the fitted radii (the edge is
//      interpolated between voxels), n_eff = the inliers' share of the spheroid's area / voxel
//      area^(2/3) (neighbouring rays see the same voxels). Slices further apart than they are thick
//      (gaps: the odd or even half of a series) hide where an edge falls between them: there the
//      sampling term is at least the surface fit's own error on noise-free clipped balls of the
//      fitted radius in a volume sampled alike (8 sub-voxel positions, metal 2, 4 and 8 x (clip -
//      b) above b, the mean), and the covariance is widened to cover a delete-one-sector jackknife
//      of the fit (the edge points in 12 sectors of directions around an icosahedron's vertices,
//      one along the slice axis; each left out in turn and the spheroid re-fitted): a real
//      sphere is not a spheroid (helical scanning distorts metal), and sparse slices see a
//      lopsided piece of its shape, an error correlated over a sector that independent rays do
//      not show (the real CT's odd and even halves: NEES per dof 6.88 without it, 1.97 with).
//      The widening keeps the covariance where the jackknife is within it and raises it to the
//      jackknife's variance along the directions where it is not. The diameter need only be
//      roughly known: the radii must be within 0.6
//      .. 1.6 x R. Not a ball (a pin, a wire): radii in a ratio beyond 1.3 (the axial radius moved
//      toward the in-plane one by up to half the slice step's excess over the pixel: sparse slices
//      move the edge across them by that much), less than half the rays ending within 20 % of the
//      spheroid, or less than min_inner_fraction of the voxels inside the spheroid shrunk by half a
//      voxel reaching L. A clip less than 500 HU above b is refused;
//    - clipped centroid: the centroid of the occupancy u = clamp((v - b) / (clip - b), 0, 1)
//      (a clipped voxel counts as fully inside, whatever metal HU the scanner lost) over the
//      voxels within the fitted spheroid grown by 0.5 mm around its own iterate (its radii, not
//      its centre, from the surface fit), started at the same clipped voxel; covariance: the
//      shell's noise (MAD / (clip - b)) propagated + the sampling term of 5. at the fitted radius.
//    The centre is the surface fit's, its covariance widened by max(1, chi2 / 3) (chi2 between
//    the two estimators, 3 dof): the Birge ratio says how far the estimate can be trusted when
//    streaks or a holder move one estimator more than its covariance allows. Both estimates and
//    their own covariances are kept (surface_*, centroid_*).
// Sheared (gantry-tilted) volumes: the centroid's ROI distances and covariance axis frame treat
// the volume axes as orthogonal (an approximation of the order of the shear angle); the
// centroid, a weighted mean of voxel indices mapped through the affine voxel-to-patient map, is
// unaffected; the ball fit works in patient coordinates with sheared voxels.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "ct/ct_volume.h"
#include "util/status.h"

namespace carmba {

struct MarkerDetectionOptions {
  double threshold_hu = 1500;        // candidate threshold, HU (the thesis kept > 1000 HU)
  double diameter_mm = 2.0;          // nominal marker diameter
  int expected_count = 0;            // markers expected; 0: any number >= 1
  double min_volume_fraction = 0.1;  // accepted core volume, x nominal sphere volume
  double max_volume_fraction = 3.0;
  double roi_margin_mm = 0.3;        // ROI beyond the marker radius (after the first pass)
  double shell_mm = 1.5;             // thickness of the background shell
  int iterations = 3;                // re-centrings of the ROI
  // Refuse when more than this fraction of all voxels is above the threshold (wrong threshold).
  double max_core_fraction = 0.01;
  // A marker's fitted ball HU (partial volume removed) is at least this: metal, not bone.
  double min_metal_hu = 2500;
  // Of the voxels most inside the fitted ball (fraction >= 0.75 x the largest), at least this
  // share must be within 25 % of their fitted contrast (ball-shaped, not a hot bone ridge).
  double min_inner_fraction = 0.8;
  // Centroid and fit disagreeing by more than this chi-square (3 dof; 11.34: 1 % false alarms)
  // means contamination: the fit's centre is used.
  double contamination_chi2 = 11.34;
  // Local maxima tried in a component larger than max_volume_fraction x nominal.
  int max_seeds_per_component = 200;
  // The scanner's clip (8.): 0 reads it from the data, > 0 sets it (HU), < 0: no clip.
  double clip_hu = 0;

  bool Check(std::string* error) const;
};

struct DetectedMarker {
  int id = 0;                          // 1-based; detection order until labelled
  Eigen::Vector3d centre_mm;           // weighted centroid, patient coordinates
  Eigen::Matrix3d covariance_mm2;      // of centre_mm, patient coordinates
  Eigen::Vector3d bbox_centre_mm;      // centre of the core's bounding box (thesis method)
  Eigen::Vector3d core_centroid_mm;    // unweighted centroid of the core voxels
  Eigen::Vector3d centre_index;        // weighted centroid in continuous voxel indices (i, j, k)
  Eigen::Vector3d peak_index = Eigen::Vector3d::Zero();  // the voxel of peak_hu
  double volume_mm3 = 0;               // core volume (voxels >= threshold x voxel volume)
  double peak_hu = 0;                  // maximum HU in the core
  double background_hu = 0;            // b
  double noise_hu = 0;                 // sigma_b (after the odd-part check of 5.)
  double odd_background_hu = 0;        // RMS of the background's odd part (0: too few voxels)
  double weight_volume_mm3 = 0;        // W x voxel volume / (peak - b): partial-volume volume
  int core_voxels = 0;
  int roi_voxels = 0;
  Eigen::Matrix3d covariance_noise_mm2;     // the noise + background part (+ the jackknife, 8.)
  Eigen::Matrix3d covariance_sampling_mm2;  // the sampling part
  // Robust partial-volume ball fit (see 6.).
  bool fit_ok = false;
  Eigen::Vector3d fit_centre_mm = Eigen::Vector3d::Zero();
  Eigen::Matrix3d fit_covariance_mm2 = Eigen::Matrix3d::Zero();
  double fit_metal_hu = 0, fit_background_hu = 0, fit_scale_hu = 0, fit_outlier_mass = 0;
  double fit_inner_fraction = 0;
  double fit_metal_sigma_hu = 0;  // standard deviation of fit_metal_hu
  int fit_voxels = 0;
  double contamination_chi2 = 0;  // (centroid - fit)^T (C_centroid + C_fit)^-1 (centroid - fit)
  bool contaminated = false;      // contamination_chi2 > threshold: centre_mm is the fit's
  Eigen::Vector3d centroid_mm = Eigen::Vector3d::Zero();  // the weighted centroid
  bool merged = false;            // seeded from a local maximum of a larger component
  double peak_needed_hu = 0;      // the least peak of a min_metal_hu ball over background_hu
  // Saturated metal (8.): measured by the surface fit and the clipped centroid.
  bool saturated = false;
  Eigen::Vector3d surface_centre_mm = Eigen::Vector3d::Zero();
  Eigen::Matrix3d surface_covariance_mm2 = Eigen::Matrix3d::Zero();
  Eigen::Vector2d surface_radii_mm = Eigen::Vector2d::Zero();  // in-plane, along the slices
  int surface_rays = 0, surface_inliers = 0;
  double surface_rms_mm = 0;  // weighted RMS of the inliers' radial residuals
  Eigen::Matrix3d centroid_covariance_mm2 = Eigen::Matrix3d::Zero();  // of centroid_mm
};

struct RejectedComponent {
  Eigen::Vector3d centroid_mm;
  double volume_mm3 = 0;
  double peak_hu = 0;
  int voxels = 0;
  std::string reason;
};

struct MarkerDetection {
  std::vector<DetectedMarker> markers;      // in detection order (by first voxel index)
  std::vector<RejectedComponent> rejected;  // components that failed the size/border filter
  int core_voxels = 0;                      // voxels >= threshold
  double clip_hu = 0;                       // the scanner's clip (8.); 0: none found
  int clipped_voxels = 0;                   // voxels at the clip
};

// Voxels that must hold the volume's largest value for it to be taken as the scanner's clip.
inline constexpr int kMinClippedVoxels = 8;

// Runs steps 1-7. Errors: no marker found, a count different from options.expected_count (the
// message lists what was found and rejected), or too many voxels above the threshold.
StatusOr<MarkerDetection> DetectMarkers(const CtVolume& volume,
                                        const MarkerDetectionOptions& options);

// Whether `volume` samples with gaps: slices further apart than they are thick (the odd or even
// half of a series; thin slices reconstructed at a larger increment). Saturated markers' centre
// covariances then also cover the sector jackknife of 8.
bool SlicesHaveGaps(const CtVolume& volume);

// The sampling-error variance (mm^2) of the centroid along one axis for a ball of radius
// `radius_mm`, box-filtered over `extent_mm` and sampled every `spacing_mm`, over uniformly
// distributed sub-voxel phases (see 5. above).
double SamplingVarianceMm2(double radius_mm, double spacing_mm, double extent_mm);

}  // namespace carmba
