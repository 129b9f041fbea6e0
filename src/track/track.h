// `carmba track`: beads (small metal spheres implanted in bones) tracked through the frames of a
// calibrated multi-camera X-ray system (XMALab's marker-based XROMM workflow), with no CT model.
//
// Stages (Track()), each a function below:
//   1. Beads in each image: the marker detector (detect/marker_blobs.h) with 2x2 covariances; the
//      expected diameter is --marker-diameter-mm at each camera's magnification at the point
//      nearest to all optical axes (the cameras' common field).
//   2. Matching per frame (MatchFrame): every pair of blobs of the first two cameras whose rays
//      meet within `epipolar_px` (the pair's reprojection, both pixels) is a candidate bead,
//      triangulated with its 3x3 covariance from the pixels' (TriangulateHeld). A blob with
//      several candidates is ambiguous: which one is real is left to stage 3.
//   3. Identity and rigid bodies (FindBodies): candidates of the first frame against those of
//      each later frame as a compatibility graph (two correspondences agree when the distance
//      between their beads is the same in both frames within `rigid_tolerance_mm`); its largest
//      cliques, one blob used once, are the rigid bodies (>= 3 beads). A candidate in no body
//      (a wrong epipolar pairing, a bead seen moving alone) gets no id. Every bead has one id in
//      all frames; body membership must hold in every frame pair.
//      A bead missed in one camera joins with its single pixel (AddSingleCameraBeads).
//   4. One bundle adjustment over all frames in the engine (ba/problem.h rigs): the beads in
//      each body's frame (the lab frame at the first frame) and each body's pose per later frame,
//      lab_from_body, are the unknowns; the cameras are held (intrinsics with a camera.json
//      covariance free within it, as a prior; the cameras' poses always held); the first frame's
//      poses are held at the identity (the gauge). Its covariance gives each bead's 3x3 and each
//      pose's 6x6.
//   5. Checks without ground truth (TrackChecks): per frame independent triangulations, the
//      distances within each body compared between frames against their predicted sigmas.
#pragma once

#include <Eigen/Dense>
#include <array>
#include <map>
#include <string>
#include <vector>

#include "camera/camera_model.h"
#include "detect/marker_blobs.h"
#include "geometry/pose.h"
#include "util/status.h"

namespace carmba {

// A calibrated camera of the tracking system: pinhole intrinsics (OPENCV5 order; the XMALab
// text has no distortion: its images are undistorted) and cam_from_lab (x_cam = R x_lab + t).
struct TrackCamera {
  std::string name;
  int width = 0, height = 0;
  std::array<double, kNumIntrinsics> intrinsics{};
  Pose6 cam_from_lab = Pose6::Zero();
  // camera.json's covariance of some intrinsics (IntrinsicIndex order as listed; empty: none). The
  // bundle adjustment then frees those intrinsics within it (a prior), the others held.
  std::vector<int> covariance_indices;
  Eigen::MatrixXd covariance;
  Eigen::Vector3d CentreInLab() const;   // the source (focal spot) in the lab frame
  Eigen::Vector3d AxisInLab() const;     // the optical axis (unit), source towards the detector
};

// The XMALab / Autoscoper calibration text: "image size" W,H; "camera matrix" (3 rows);
// "rotation" (3 rows, x_cam = R x_lab + t); "translation" (3 rows). Errors name path:line.
StatusOr<TrackCamera> ReadXmaCalibration(const std::string& path, const std::string& name);

// carmba's camera.json (intrinsics with distortion) and a pose file {"cam_from_lab": {"rvec":
// [rad x3], "t_mm": [mm x3]}} (x_cam = R(rvec) x_lab + t). Errors name the file and key.
StatusOr<TrackCamera> ReadCameraJsonWithPose(const std::string& camera_json,
                                             const std::string& pose_json,
                                             const std::string& name);
// `spec` as --cameras gives it: FILE (the XMALab text) or CAMERA_JSON+POSE_JSON.
StatusOr<TrackCamera> ReadTrackCamera(const std::string& name, const std::string& spec);

// The frame number of an image file: the last run of digits in its name before the extension
// ("xr_cam01_UND.0099.tif" -> 99). Error when the name has none.
StatusOr<int> FrameNumberOfFile(const std::string& path);

struct TrackFrame {
  int number = 0;
  std::vector<std::string> image_per_camera;  // parallel to the cameras; "" = not imaged
};
// Pairs the cameras' images by frame number; frames imaged by fewer than two cameras are left
// out (listed in `unpaired`). Error: a frame number given twice for one camera, no frame seen by
// two cameras.
StatusOr<std::vector<TrackFrame>> PairFrames(const std::vector<std::vector<std::string>>& images,
                                             std::vector<std::string>* unpaired);

struct TrackOptions {
  double marker_diameter_mm = 1.0;
  double diameter_tolerance = 0.35;  // of the expected diameter in px
  double epipolar_px = 2.0;          // rays of one bead meet within this (px, per image)
  double rigid_tolerance_mm = 0.3;   // a body's distances agree between frames within this
  int min_body_beads = 3;
  // The detector's options; the diameter fields are set from marker_diameter_mm. Beads are metal
  // (tantalum): they attenuate by far more than bone edges and skin discs, min_contrast 0.15.
  MarkerBlobOptions blobs = BeadBlobOptions();
  static MarkerBlobOptions BeadBlobOptions() {
    MarkerBlobOptions o;
    o.min_contrast = 0.15;
    return o;
  }
  bool Check(std::string* error) const;
};

// One image's detection.
struct TrackImage {
  int frame = 0, camera = 0;
  std::string path;
  MarkerBlobDetection detection;
  int split_pairs = 0;  // "merged" blobs separated into two by FitBlobPair
};

// Stage 1's second step: every blob the detector rejected as "merged" is fitted as a pair of
// touching blobs (detect/blob_pair_fit.h); the two centres join the blobs, a failed fit stays
// rejected with its reason.
void SplitMergedPairs(const cv::Mat& image, const MarkerBlobOptions& blobs, TrackImage* ti);

// A bead triangulated from its pixels with the cameras held.
struct HeldPoint {
  Eigen::Vector3d p_lab = Eigen::Vector3d::Zero();
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // from the pixels' covariances, mm^2
};

struct TrackObservation {
  int camera = 0;
  int blob = 0;             // index into that image's detection.blobs
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();
  Eigen::Matrix2d covariance_px2 = Eigen::Matrix2d::Identity();
};

// A candidate bead of one frame: one blob per camera that sees it.
struct TrackCandidate {
  std::vector<TrackObservation> observations;
  HeldPoint point;
  double epipolar_px = 0;  // largest reprojection error of its pixels at the triangulated point
};

struct TrackBead {
  int id = 0;
  int body = 0;
  // Per frame index: the candidate index in that frame (-1: not found in that frame).
  std::vector<int> candidate;
};

struct TrackBody {
  int id = 0;
  std::vector<int> beads;               // indices into TrackResult::beads
  // Per frame index: lab_from_body (body frame = lab frame at the first frame), its 6x6
  // covariance ([rx, ry, rz] rad, [tx, ty, tz] mm), reprojection RMS; `found` false when the body
  // could not be identified in that frame.
  std::vector<Pose6> lab_from_body;
  std::vector<Matrix6> covariance;
  std::vector<char> found;
};

// Inter-bead distances within a body, per frame from the independent per-frame triangulations.
struct BodyDistance {
  int body = 0, bead_a = 0, bead_b = 0;  // bead ids
  std::vector<double> distance_mm;       // per frame (NaN: not in that frame)
  std::vector<double> sigma_mm;
  double spread_mm = 0;                  // max - min over the frames
  double max_change_sigmas = 0;          // largest |d_f - d_g| / sigma over frame pairs
};

struct TrackChecks {
  // The detector's pixel covariances times this squared (the bundle adjustment's per-group
  // variance component of the detected blobs, 1 when it could not be estimated) are the pixel
  // noise the distance checks below use: the data's own estimate of the noise, not the stated one.
  double pixel_sigma_scale = 1;
  double max_change_sigmas_stated = 0;   // the same check at the detector's stated covariances
  int min_beads_per_frame = 0;           // triangulated from >= 2 cameras, with an id
  double rms_px = 0;                     // the bundle adjustment's, per coordinate
  double max_change_sigmas = 0;          // over all body distances
  double max_spread_mm = 0;
  // What the noise alone gives: the expected largest spread over the same distances and frames
  // with each distance drawn from N(d, sigma_f) (seeded Monte Carlo, kSpreadDraws draws). A spread
  // target below it is out of reach on these data.
  double predicted_max_spread_mm = 0;
  double rms_spread_mm = 0;              // RMS over the distances of (d_f - mean d)
  double distance_chi2 = 0;              // sum over distances and frames of ((d_f - mean)/sigma)^2
  int distance_dof = 0;
  double distance_chi2_p = 1;            // its upper tail
};

struct TrackResult {
  std::vector<TrackCamera> cameras;
  std::vector<TrackFrame> frames;
  std::vector<std::string> unpaired;
  std::vector<TrackImage> images;                      // frame-major, camera-minor
  std::vector<std::vector<TrackCandidate>> candidates; // per frame
  std::vector<TrackBead> beads;
  std::vector<TrackBody> bodies;
  std::vector<Eigen::Vector3d> bead_in_body;           // per bead, the BA's estimate (mm)
  std::vector<Eigen::Matrix3d> bead_covariance;        // in the body frame
  // Per frame and bead: lab position from the BA and its covariance (poses and beads jointly),
  // its reprojection RMS and number of cameras (0: not observed in that frame).
  std::vector<std::vector<Eigen::Vector3d>> bead_lab;
  std::vector<std::vector<Eigen::Matrix3d>> bead_lab_covariance;
  std::vector<std::vector<double>> bead_rms_px;
  std::vector<std::vector<int>> bead_num_views;
  std::vector<BodyDistance> distances;
  TrackChecks checks;
  double ba_chi2 = 0;
  int ba_dof = 0;
  double ba_sigma0 = 0;
  std::vector<std::string> warnings;
  double time_detect_s = 0, time_match_s = 0, time_ba_s = 0;
};

// Reads each image, detects its beads, matches, identifies, solves and checks.
StatusOr<TrackResult> Track(const std::vector<TrackCamera>& cameras,
                            const std::vector<TrackFrame>& frames,
                            const TrackOptions& options);

// Stages 2-5 on detections already made (`images`, any order; Track() reads and detects them).
StatusOr<TrackResult> TrackDetections(const std::vector<TrackCamera>& cameras,
                                      const std::vector<TrackFrame>& frames,
                                      std::vector<TrackImage> images,
                                      const TrackOptions& options);

// The stages, for tests and the benchmark. `images` are frame-major, camera-minor.
std::vector<TrackCandidate> MatchFrame(const std::vector<TrackCamera>& cameras,
                                       const std::vector<const MarkerBlobDetection*>& images,
                                       const TrackOptions& options);
StatusOr<HeldPoint> TriangulateHeld(const std::vector<TrackCamera>& cameras,
                                    const std::vector<TrackObservation>& observations);
// Stage 3 on the result's candidates: fills beads and bodies (poses from the candidates).
void FindBodies(const TrackOptions& options, TrackResult* result);
// Stage 3b: a bead of an identified body that no epipolar candidate gave in a frame, but whose
// predicted position (the body's pose) falls within epipolar_px of an unused blob in exactly one
// camera, gets that single observation (the bundle adjustment uses it; the per-frame distance
// checks do not, having no triangulation of it).
void AddSingleCameraBeads(const TrackOptions& options, TrackResult* result);
// Stage 4: the bundle adjustment (fills the bodies' poses and covariances and the beads).
Status SolveTrack(TrackResult* result);
// Stage 5.
void CheckTrack(TrackResult* result);

}  // namespace carmba
