// The cone-beam shadow of a sphere is not centred on the projection of the sphere's centre
// (Clackdoyle & Mennessier, "Centers and centroids of the cone-beam projection of a ball", Phys.
// Med. Biol. 56, 2011). The rays from
// the source tangent to a sphere of radius r whose centre lies at distance d from the source
// form a circular cone of half-angle alpha = asin(r / d) about the source-to-centre line; that
// line makes an angle theta with the optical axis. The cone cuts the (undistorted) image plane
// in an ellipse whose major axis lies on the radial line through the centre's projection p, with
// its vertices at tan(theta -+ alpha): the ellipse's centre is
//     p (1 + tan^2(alpha) (1 + tan^2 theta) / (1 - tan^2(theta) tan^2(alpha)))
// in normalised coordinates (|p| = tan theta): further out than p, by a fraction of about
// (r / d)^2 (1 + tan^2 theta). Every level set of the shadow (chord length above some value) is
// such an ellipse of a smaller cone with an area and an offset both proportional to its tan^2,
// so an intensity centroid lies between 0.8 (a faint sphere, contrast proportional to the chord)
// and 1 (an opaque one) of the outline's offset (integrating the level sets); carmba's marker and
// grid detectors follow the outline's centre for steel spheres (measured:
// tests/ba/shadow_correction_test.cc).
//
// The engine corrects for it (SolveBundleAdjustment, BaOptions::shadow_correction): after a
// solve, each observation of a sphere of known radius (BaProblem::marker_radius_mm,
// BaPlate::sphere_radius_mm) gets the offset of its shadow's centre at the solution; when the
// largest offset exceeds kShadowCorrectionMinSigma of its observation's sigma, the offsets are
// subtracted from the observed pixels and the problem is solved again. The offsets move by a
// negligible amount between the two solves (they are second order in r / d).
#pragma once

#include <Eigen/Core>
#include <vector>

#include "ba/problem.h"

namespace carmba {
namespace ba {

struct BaResult;

// Corrections below this fraction of an observation's sigma are not applied.
constexpr double kShadowCorrectionMinSigma = 0.1;

// The image offset (px) from the projection of a sphere's centre `p_cam` (camera frame, mm) to
// the centre of its shadow's outline, through the lens model `intrinsics` (OPENCV5 order).
// Zero when the radius is 0, the centre is not in front of the source, or the source lies
// inside the sphere.
Eigen::Vector2d SphereShadowOffsetPx(const double* intrinsics, const Eigen::Vector3d& p_cam,
                                     double radius_mm);

// Offsets of every observation of `problem` at `result`'s solution (views x observations, zero
// for observations of spheres of unknown radius).
std::vector<std::vector<Eigen::Vector2d>> ShadowOffsets(const BaProblem& problem,
                                                        const BaResult& result);

// What the correction did, for result.json and the report.
struct ShadowCorrectionSummary {
  bool evaluated = false;   // some sphere radius was known
  bool applied = false;     // the largest offset exceeded kShadowCorrectionMinSigma sigma
  int num_observations = 0;
  double max_px = 0;        // largest |offset|
  double rms_px = 0;        // over the observations, per coordinate
  double max_sigma = 0;     // largest |offset| / the observation's sigma
};
// `sigma_scale` multiplies the observations' stated sigmas: the root of the a-posteriori variance
// factor when they are nominal (covariance.scale global, e.g. a calibration that estimates its
// pixel sigma from a nominal 1 px), 1 otherwise.
ShadowCorrectionSummary SummariseShadowOffsets(
    const BaProblem& problem,
    const std::vector<std::vector<Eigen::Vector2d>>& offsets,
    double sigma_scale = 1.0);

// `problem` with every observed pixel moved by minus its offset.
BaProblem WithShadowOffsetsRemoved(const BaProblem& problem,
                                   const std::vector<std::vector<Eigen::Vector2d>>& offsets);

}  // namespace ba
}  // namespace carmba
