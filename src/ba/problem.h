// The one bundle-adjustment problem description of carmba (calibration, pose and the joint
// problem are front ends that fill it), and its named state layout.
//
// WHAT is estimated (COLMAP's "config" beside its "options"; mrcal's state vector):
//   * intrinsics groups g: [fx, fy, cx, cy, k1, k2, p1, p2, k3] (camera/camera_model.h), one per
//     group ("shared" for one C-arm geometry, or one per orientation group). Each intrinsic is
//     free or held at its initial value; a group may carry a Gaussian prior (mean, covariance over
//     a subset of the names, e.g. an earlier calibration's camera.json).
//   * one pose per view, `cam_from_plate` for a plate view, `cam_from_object` for an object view:
//     [rx, ry, rz (rad), tx, ty, tz (mm)], p_in_cam = R(r) p + t.
//   * or, for object views taken together by cameras of known relative pose (a RIG: the views of
//     one frame of a calibrated biplane system), one pose per rig, `rig_from_object`, shared by
//     its views: cam_from_object = cam_from_rig (held, per view) * rig_from_object. A constant
//     rig fixes the gauge (frame 1 of `carmba track`); COLMAP's rigs. The solve, its covariance
//     and the variance components handle rigs; the derived quantities, relative poses, TRE and
//     triangulation read each view's block as its own cam_from_object and take problems without
//     rigs (TriangulatePoint and LeaveOneMarkerOut refuse them).
//   * the object's markers p_in_object (mm), tied to their CT centres by priors whitened with each
//     marker's 3x3 CT covariance (the CT frame is the object frame: the priors fix the gauge).
//   * the plate's sphere positions (mm), held at the nominal grid, or free and tied to it by a
//     manufacturing-tolerance prior of sigma_mm per coordinate.
// Residual kinds, each whitened, each with an analytic cost and an autodiff twin
// (ba/reprojection_error.h, ba/priors.h), each belonging to one independent noise SOURCE:
//   plate reprojection (kPlatePixels), marker reprojection (kObjectPixels), CT prior (kCt),
//   plate prior (kPlateManufacturing), intrinsics prior (kIntrinsicsPrior).
// A sixth source has no residual: the CONSIDERED calibration (kCalibration). A group whose
// intrinsics are held at an earlier calibration may carry that calibration's covariance
// (IntrinsicsGroup::consider_*): the estimates stay those with the intrinsics held, and the
// covariance of the free parameters gains the Schmidt "consider" term (ba/covariance.h).
//
// STATE LAYOUT: parameter blocks in a fixed order -- intrinsics groups, plate-view poses,
// object-view poses, markers (by id), plate points (by id) -- in one contiguous buffer (Ceres
// orders blocks by address in places, so one buffer makes solves reproducible to the last digit).
// Every scalar has a name used by the covariance output, the rank-deficiency message and the
// reports: `fx` (one group) or `lao30 fx` (several), `plate 3 rz`, `view lao+030 rz`,
// `marker 7 z`, `plate point 12 x`. Held parameters (fixed intrinsics, constant blocks) are not
// in the FREE state; `FreeIndex` maps the free state to (block, parameter).
#pragma once

#include <Eigen/Dense>
#include <array>
#include <string>
#include <vector>

#include "ba/smooth_intrinsics.h"
#include "camera/camera_model.h"
#include "geometry/pose.h"
#include "util/status.h"

namespace carmba {
namespace ba {

// Independent noise sources (error budget).
enum class Source {
  kPlatePixels = 0,
  kObjectPixels,
  kCt,
  kPlateManufacturing,
  kIntrinsicsPrior,
  kCalibration  // held intrinsics' calibration covariance, considered (no residual of its own)
};
constexpr int kNumSources = 6;
constexpr int kNumResidualSources = 5;  // the sources that residual blocks belong to
// "plate pixels", "object pixels", "CT localisation", "plate manufacturing", "intrinsics prior",
// "calibration (intrinsics)".
const char* SourceName(Source s);

// Observation groups for the variance-component estimate (ba/variance_components.h): the
// residual blocks by their noise MODEL, finer than the sources (object pixels picked by hand and
// marker blobs found by the detector are both kObjectPixels, with different noise models).
enum class NoiseGroup {
  kPlatePixels = 0,
  kObjectPixels,      // object-view pixels with an isotropic sigma (picked, or given)
  kDetectedBlobs,     // object-view pixels with a 2x2 covariance each (the marker detector's)
  kCt,                // CT fiducial priors
  kPlateManufacturing,
  kIntrinsicsPrior
};
constexpr int kNumNoiseGroups = 6;
// "plate pixels", "object pixels", "detected blobs", "CT fiducials", "plate manufacturing",
// "intrinsics prior".
const char* NoiseGroupName(NoiseGroup g);
// result.json's key: "plate_pixels", "object_pixels", "detected_blobs", "ct",
// "plate_manufacturing", "intrinsics_prior".
const char* NoiseGroupKey(NoiseGroup g);
// The group of a residual block of `source`; `view` for a reprojection (null for a prior).
struct BaView;
NoiseGroup GroupOf(Source source, const BaView* view);

struct IntrinsicsPrior {
  std::array<double, kNumIntrinsics> mean{};
  std::vector<int> indices;      // which intrinsics the covariance is over (IntrinsicIndex)
  Eigen::MatrixXd covariance;    // |indices| x |indices|, symmetric positive definite
};

struct IntrinsicsGroup {
  std::string name = "shared";
  int width = 0, height = 0;  // image size, px (0: unknown)
  std::array<double, kNumIntrinsics> initial{};
  std::array<bool, kNumIntrinsics> free{true, true, true, true, true, true, true, true, true};
  // > 0: a fixed aspect ratio, fy = fy_over_fx * fx. fy is then not a free parameter of its own:
  // it follows fx (held with it when fx is held); the initial values must satisfy the ratio.
  double fy_over_fx = 0;
  bool has_prior = false;
  IntrinsicsPrior prior;
  // Considered calibration uncertainty of HELD intrinsics (Schmidt's consider covariance): the
  // covariance (consider_indices x consider_indices, IntrinsicIndex order as listed) of the
  // values they are held at, e.g. camera.json's. They stay held in the solve; the free
  // parameters' covariance gains  A Sigma_c A^T  (ba/covariance.h). Every index must be held.
  std::vector<int> consider_indices;
  Eigen::MatrixXd consider_covariance;
  // Orientation-dependent intrinsics (ba/smooth_intrinsics.h): the group's block holds the
  // coefficients of `basis` (4K + 5), each view's intrinsics are A(view angles) c. Coefficient j
  // is free if its intrinsic is. Every view of the group needs angles; no prior; the plate views
  // must cover at least K orientations (K distinct angle pairs).
  bool smooth = false;
  SmoothBasis basis;
  std::vector<double> initial_coefficients;  // empty: `initial` at every angle
  int BlockSize() const { return smooth ? basis.BlockSize() : kNumIntrinsics; }
};

enum class ViewKind { kPlate, kObject };

struct BaView {
  std::string id;
  // >= 0: an object view of rig `rig` (BaProblem::rigs): its pose is cam_from_rig * the rig's
  // rig_from_object, and `initial` is unused.
  int rig = -1;
  Pose6 cam_from_rig = Pose6::Zero();
  ViewKind kind = ViewKind::kObject;
  int group = 0;                      // index into BaProblem::groups
  Pose6 initial = Pose6::Zero();      // cam_from_plate / cam_from_object, set by the front end
  std::vector<int> point_ids;         // plate point ids (plate view) or marker ids (object view)
  std::vector<Eigen::Vector2d> uv_px;
  double sigma_px = 1.0;              // pixel noise, 1 sigma per coordinate
  // C-arm angles (DICOM positioner angles, deg), needed by a smooth intrinsics group.
  bool has_angles = false;
  double primary_deg = 0, secondary_deg = 0;
  // Per-observation pixel noise (1 sigma per coordinate, isotropic), parallel to uv_px; empty =
  // sigma_px for all.
  std::vector<double> obs_sigma_px;
  // Per-observation full 2x2 pixel covariance (px^2), parallel to uv_px; empty = isotropic
  // (obs_sigma_px / sigma_px). E.g. detected marker blobs (detect/marker_blobs.h). The residual
  // is whitened by L^-1 with Sigma = L L^T (ba/reprojection_error.h). Takes precedence over
  // obs_sigma_px.
  std::vector<Eigen::Matrix2d> obs_covariance_px2;
  // An isotropic sigma standing for observation i (px): sqrt of the larger eigenvalue of its 2x2
  // covariance when it has one (the robust loss's scale and the outlier listing use it).
  double SigmaPx(size_t i) const;
  // Observation i's pixel covariance (px^2): its 2x2, else sigma^2 I.
  Eigen::Matrix2d CovariancePx2(size_t i) const;
};

struct BaMarker {
  int id = 0;
  Eigen::Vector3d p_ct = Eigen::Vector3d::Zero();        // CT centre (object frame), mm
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Identity();  // mm^2
};

struct BaPlate {
  std::vector<Eigen::Vector3d> points;  // nominal positions by point id (plate frame), mm
  bool free = false;                    // estimate them, tied to the nominal grid
  double sigma_mm = 0;                  // manufacturing tolerance, 1 sigma per coordinate
                                        // (0 with free: no prior -- a gauge freedom)
  double sphere_radius_mm = 0;          // the plate's spheres (0 = unknown: no shadow correction)
};

// The views of one rig share its pose rig_from_object (see the header comment).
struct BaRig {
  std::string id;
  Pose6 initial = Pose6::Zero();  // rig_from_object
  bool constant = false;          // held at `initial` (the gauge)
};

struct BaProblem {
  std::string name;
  std::vector<BaRig> rigs;
  std::vector<IntrinsicsGroup> groups;
  std::vector<BaView> views;
  std::vector<BaMarker> markers;
  bool markers_free = true;   // estimate the markers (else held at their CT centres)
  bool marker_priors = true;  // tie free markers to their CT centres (the CT prior)
  // Radius of the marker spheres (mm); 0 = unknown: no cone-beam shadow-centre correction for
  // object views (ba/shadow_correction.h).
  double marker_radius_mm = 0;
  BaPlate plate;

  // Consistency, before anything is built: groups and views valid, ids unique, every observation
  // names a known point or marker, >= 4 observations per view, finite values, sigmas > 0, each
  // group used, a group with object views but no plate view and no prior is an error (its
  // intrinsics would rest on the markers alone).
  Status Check() const;
};

enum class BlockKind { kIntrinsics, kPlatePose, kObjectPose, kRigPose, kMarker, kPlatePoint };

struct BlockInfo {
  BlockKind kind;
  int index = 0;           // group / view / marker or plate-point index in the problem
  int offset = 0;          // into the parameter buffer
  int size = 0;            // 9 (4K + 5 for smooth intrinsics), 6 or 3
  // "" (one group), "lao30", "plate 3", "view lao+030", "rig frame 2 radius", "marker 7", ...
  std::string label;
  bool constant = false;   // held entirely
  std::vector<int> free;   // free parameter indices within the block (empty if constant)
  int free_offset = -1;    // into the free state (-1 if constant)
  // Considered (held) parameters of an intrinsics block (IntrinsicsGroup::consider_indices) and
  // their offset in the considered vector c (-1: none).
  std::vector<int> consider;
  int consider_offset = -1;
  std::vector<std::string> parameter_names;  // when not the kind's default (smooth intrinsics)
  // The block's parameters move as  x = x0 + basis * delta,  delta over `free` (size x |free|).
  // A column selection (`selection`) unless parameters are tied (fy = r fx: the fx column has r
  // in fy's row).
  Eigen::MatrixXd basis;
  bool selection = true;
  // Parameters that move (non-zero rows of basis): `free` plus the tied ones.
  std::vector<int> Moving() const;
};

class StateLayout {
 public:
  explicit StateLayout(const BaProblem& problem);

  int buffer_size() const { return buffer_size_; }
  int num_free() const { return num_free_; }
  const std::vector<BlockInfo>& blocks() const { return blocks_; }
  const BlockInfo& block(int b) const { return blocks_[b]; }
  int group_block(int g) const { return group_block_[g]; }
  // The pose block of view v (its rig's for a rig view).
  int view_block(int v) const { return view_block_[v]; }
  int rig_block(int r) const { return rig_block_[r]; }
  int marker_block(int m) const { return marker_block_[m]; }        // m: index in problem.markers
  int plate_point_block(int p) const { return plate_point_block_[p]; }  // p: point id
  // Name of parameter `i` of block `b`, e.g. "view lao+030 rz".
  std::string ParameterName(int b, int i) const;
  // Name of free-state index `k`.
  std::string FreeName(int k) const;
  // (block, parameter) of free-state index k.
  std::pair<int, int> FreeIndex(int k) const { return free_index_[k]; }
  // The considered calibration parameters c (held intrinsics with a covariance), their number,
  // names and covariance Sigma_c (block-diagonal over the groups; 0 x 0 when none).
  int num_consider() const { return num_consider_; }
  std::string ConsiderName(int k) const;
  const Eigen::MatrixXd& consider_covariance() const { return consider_covariance_; }

 private:
  std::vector<BlockInfo> blocks_;
  std::vector<int> group_block_, view_block_, rig_block_, marker_block_, plate_point_block_;
  std::vector<std::pair<int, int>> free_index_, consider_index_;
  int buffer_size_ = 0, num_free_ = 0, num_consider_ = 0;
  Eigen::MatrixXd consider_covariance_;
};

// How the calibration's uncertainty enters the covariances: the intrinsics are estimated (some
// free), held and considered (a covariance, no free one), or held and left out.
enum class CalibrationUncertainty { kEstimated, kConsidered, kLeftOut };
CalibrationUncertainty CalibrationUncertaintyOf(const BaProblem& problem);
// One sentence saying it, for reports and messages.
const char* CalibrationUncertaintyNote(CalibrationUncertainty c);

// `view` with only the observations i where keep[i] is non-zero (ids, pixels and the
// per-observation sigmas and covariances alike).
BaView KeepObservations(const BaView& view, const std::vector<char>& keep);

// The initial state: every block's initial value in layout order.
std::vector<double> InitialState(const BaProblem& problem, const StateLayout& layout);

}  // namespace ba
}  // namespace carmba
