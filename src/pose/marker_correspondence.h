// Automatic correspondence: which blob of an X-ray view is which CT marker, from the markers'
// CT centres (the object frame) and the calibrated camera.
//
// Hypothesise and verify (LabelMarkerBlobs):
//   * predicted pose (optional, e.g. from an already labelled view and the DICOM angles' nominal
//     relative geometry, detect/marker_views.h): project all markers, pair each with the nearest
//     blob within `predict_gate_px` (greedy by distance, one blob per marker), refine the pose on
//     the pairs, re-pair within `gate_px`; the same from a first pairing within `gate_px`. The
//     wide one is taken if it is accepted (below) and, when the tight one holds 3 or more
//     markers (an accurate prediction), pairs the same (a pair only the wide gate made, e.g. a
//     bead beside a hidden marker, bends a pose of few pairs to itself); else the tight one if
//     accepted; else the prediction moved across the view by the image offset most markers agree
//     on (a vote over the offsets from each marker's projection to the blobs within
//     predict_gate_px: a nominal geometry off by a few mm moves the whole layout, and a greedy
//     wide pairing can take other blobs for it), paired within gate_px, if accepted; else the
//     full search runs.
//   * full search: marker triples (compact and well-shaped, disjoint first) x every ordered
//     triple of blobs within the magnification bound (px_per_mm below) ->
//     P3P (OpenCV's AP3P on undistorted rays) -> up to 4 poses -> a quick check that another
//     marker projects within the gate of some blob -> project all markers -> gated greedy pairing
//     -> pose refined on the pairs (Gauss-Newton, full camera model) and re-paired -> score.
//     A triple of markers all found in the best labelling was searched exhaustively (every
//     labelling that pairs those three markers with blobs has been seen), and the search stops.
//   * A labelling is accepted when it pairs >= min_markers markers, and >= min_fraction of the
//     markers its pose predicts visible and separable (in the image and the view's field of view,
//     farther than separation_px from every other marker and from every candidate the detector
//     rejected as metal: a bead or a wire on a marker hides it; and farther than gate_px from
//     every blob-sized shadow it found too faint to measure: a marker behind dense anatomy;
//     ViewContext), with RMS (per coordinate) <= accept_rms_px, and (when
//     px_per_mm is known) its pose puts the markers' centroid at a magnification fx / z within
//     the scale tolerance of px_per_mm: among thousands of hypotheses, a 4-marker labelling of a
//     foreign layout fits to a few tenths of a px by chance, but at a wrong depth. A labelling of
//     exactly 4 pairs, with none to spare for the off-pose check below, must also have each pair
//     where the other three put it (the same test as OffPoseBlob's). The best
//     labels the most markers, then has the smallest RMS (MSAC score, sum of min(d^2, gate^2)
//     over markers in the image, keeps the best variant of one labelling).
//   * the search over triples stops once d disjoint triples are done with d >= m - best + 1 (m
//     markers, best = markers in the best labelling): a labelling at least as complete misses at
//     most m - best markers, so one of the triples was complete in it and found it. The first pass
//     tries the disjoint triples and at least 8 in all; when they cannot give that guarantee
//     (nothing accepted, or a best labelling too incomplete: many markers hidden or merged),
//     every other triple is tried, up to 50000 P3P solves in all (any labelling of 3 or more
//     markers contains a complete triple).
//   * ambiguity: an accepted labelling that contradicts the best (a blob given two different
//     markers, or a marker two different blobs), labels as many markers and has an RMS within
//     ambiguity_margin_px of the best leaves only the pairs all such labellings share (e.g. 7 of
//     8 markers, one marker's blob contested); when those are too few for min_markers and
//     min_fraction it is an error naming both: the layout is (nearly) symmetric as seen by this
//     view, and a guess could be wrong. The margin is in px, not relative to the blobs' noise:
//     the true labelling's RMS includes the shadows' offsets and the calibration's error, and a
//     wrong 4-marker labelling can fit better than it (0.022 px against the true 0.101 px on
//     a randomised scene with a bead among 4 visible markers). Before that error: when the
//     best accepted labelling of fewer markers fits 6 times better than both contested ones and
//     no labelling of as many markers contests it, it is taken (the contested ones are chance
//     fits that took spurious beads: 0.75 px against 0.02 px on a randomised scene).
//   * rival: the best labelling of 4 pairs has none to spare to tell a pulled centre from a
//     chance fit. When another labelling of 4 pairs, contradicting it, within
//     ambiguity_margin_px and 6 times its RMS, was refused only because one of its pairs lies
//     off where the other three put it, by no more than an edge or a bead in line can pull a
//     centre (a quarter of separation_px, about 0.3 of a diameter; 1.5 px when unknown), the
//     view is ambiguous too: the true labelling may be the refused one (randomised scene 2011).
// Blobs left unpaired are not labelled (spurious beads, other metal).
#pragma once

#include <Eigen/Core>

#include <optional>
#include <string>
#include <vector>

#include "camera/camera.h"
#include "geometry/pose.h"
#include "util/status.h"

namespace carmba {

struct CorrespondenceOptions {
  double gate_px = 3.0;            // pairing distance (px)
  double predict_gate_px = 40.0;   // pairing distance around a predicted pose (px)
  double accept_rms_px = 1.0;      // an accepted labelling's RMS per coordinate (px)
  int min_markers = 4;             // markers a labelling must pair
  // ... and at least this fraction of all markers (chance alignments of 4-5 markers within the
  // gate are common among thousands of hypotheses, and a wrong pose can put the other markers
  // outside the image; the true labelling pairs all markers but the hidden ones). A view seeing
  // fewer (e.g. 5 of 9 markers at 0.6) is skipped as unlabelled.
  double min_fraction = 0.6;
  // Of the markers it can see: those whose projection at the labelling's pose lies in the image
  // (and the view's field of view) and farther than `separation_px` from every other marker's and
  // every obstruction (ViewContext; closer ones merge into one blob, which the detector
  // rejects). 0: every marker in the image counts, and obstructions within gate_px. carmba pose
  // sets it to the detector's merge distance in px.
  double separation_px = 0;
  double ambiguity_margin_px = 0.5;
  int max_blobs = 40;              // more candidate blobs is an error (the search is cubic)
  // Nominal magnification at the object (px per mm; focal length / source-to-object distance);
  // 0 = unknown. When known, a blob triple is tried for a marker triple only if no blob pair is
  // longer than px_per_mm (1 + scale_tolerance) x its marker pair (a projection only shortens).
  double px_per_mm = 0;
  double scale_tolerance = 0.3;

  bool Check(std::string* error) const;
};

// What the view shows besides the blob centres, for counting the markers a labelling must pair
// (see min_fraction): the detector's circular field of view, and the centres of the candidates it
// rejected as metal (merged, elongated, too large, at the field's border, refinement failed), on
// which a marker's own blob cannot be seen. Empty: the whole image, nothing hidden.
// Also each blob's centre sigma (px, in blob order; empty: unknown) for the check below.
struct ViewContext {
  Eigen::Vector2d fov_centre = Eigen::Vector2d::Zero();
  double fov_radius = 0;                      // px; 0 = no circular field
  std::vector<Eigen::Vector2d> obstructions;  // px
  // Blob-sized shadows the detector found too faint to measure (px): a marker predicted within
  // gate_px of one is seen, not missing (a marker behind dense anatomy), and is not counted
  // among the markers a labelling must pair. The tight gate keeps the many faint blobs of
  // anatomy from excusing a foreign layout's missing markers.
  std::vector<Eigen::Vector2d> faint_blobs;
  std::vector<double> blob_sigma_px;
};

// A labelled blob that the other pairs' pose does not predict: its centre is not the marker's
// (two shadows in line, a bead behind the marker; an edge across it). With 5 or more pairs, each
// pair is left out in turn and the pose refined on the others; the blob is dropped when it lies
// more than kOffPoseFloorPx from the marker's prediction and its Mahalanobis distance squared
// exceeds kOffPoseChi2, with the covariance s^2 (J H^-1 J^T + I) + sigma_blob^2 I (s^2: the
// others' squared residuals over their redundancy 2 n - 6, at least the blobs' median sigma
// squared; J H^-1 J^T: the prediction through the refined pose). The worst such blob goes first,
// then the check runs again on the rest, as long as more than min_markers pairs remain.
constexpr double kOffPoseFloorPx = 0.5;
constexpr double kOffPoseChi2 = 25;  // 5 sigma
struct OffPoseBlob {
  int blob = 0;
  int marker = 0;  // index into the markers
  double distance_px = 0;
};

struct MarkerLabelling {
  std::vector<int> marker_of_blob;  // index into the markers, -1 = not labelled
  Pose6 cam_from_object = Pose6::Zero();
  int num_labelled = 0;
  double rms_px = 0;                 // of the pairs, per coordinate
  double score_px2 = 0;              // MSAC score
  std::string method;                // "predicted" or "search"
  int hypotheses = 0;                // P3P solves
  // The best labelling that contradicts this one (for the report); num_labelled 0 when none.
  int second_num_labelled = 0;
  double second_rms_px = 0;
  std::vector<OffPoseBlob> off_pose;  // dropped from the labelling (see OffPoseBlob)
};

// Labels `blobs_uv` (px) with the `markers` (object frame, mm) seen by `camera`. Errors (one line):
// fewer blobs than min_markers; too many blobs; no accepted labelling (with the best one found:
// how many markers and RMS); an ambiguous labelling.
StatusOr<MarkerLabelling> LabelMarkerBlobs(const Camera& camera,
                                           const std::vector<Eigen::Vector3d>& markers,
                                           const std::vector<Eigen::Vector2d>& blobs_uv,
                                           const CorrespondenceOptions& options,
                                           const std::optional<Pose6>& predicted = std::nullopt,
                                           const ViewContext& context = {});

}  // namespace carmba
