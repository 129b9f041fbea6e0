// Scoring marker detection and correspondence on rendered scenes against the simulator's truth
// (tests/detect/marker_views_test.cc, marker_recall_test.cc).
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "camera/camera_model.h"
#include "detect/marker_views.h"
#include "sim/xray_scene.h"

namespace carmba {

// The scene's markers as CT fiducials (exact positions, 0.1 mm sigma).
inline std::vector<Marker> SceneMarkers(const sim::XrayScene& s) {
  std::vector<Marker> out;
  for (const auto& sp : s.phantom.spheres) {
    Marker m;
    m.id = sp.id;
    m.p_in_object = sp.center_mm;
    m.covariance = 0.01 * Eigen::Matrix3d::Identity();
    out.push_back(m);
  }
  return out;
}

// Per view of a rendered scene: which markers are visible and separated (the truth), and how the
// pipeline labelled them.
struct Tally {
  // correct: labelled with the blob of this marker (within half a diameter of its centre and
  // nearer to it than to any other marker or bead); wrong: labelled with another blob.
  // off_centre: of the correct, those more than 0.5 px off and beyond their own covariance at
  // chi2(2) 1e-4 (Mahalanobis^2 18.4): the centre errors' tail the covariance does not hold.
  int expected = 0, correct = 0, wrong = 0, off_centre = 0;
  int spurious_labelled = 0, overlap_labelled = 0;
  int outside_labelled = 0, overlapping_pairs = 0, outside = 0, crossed_by_wire = 0;
  // Views not labelled although 4 or more of their markers were expected (visible, in the field,
  // apart from every other marker, bead and the wire): markers enough to identify the view.
  int views_lost_identifiable = 0;
  // The expected markers not labelled, by why: the detector's rejection reason ("merged", "low
  // contrast", ...), "no blob found there", "a blob, not paired" or "view skipped".
  std::map<std::string, int> missed;
  // The labelled expected markers' centre errors against their covariance (NEES, 2 dof):
  // how many, the sum of their Mahalanobis^2, and how many lie beyond chi2(2) at 1e-3 (13.8).
  int nees_n = 0, nees_beyond_1e3 = 0;
  double nees_sum = 0;
  // The same over the centres whose covariance the detector widened for their core-to-whole
  // shift (MarkerBlob::shift_beyond_noise_px above MarkerBlobOptions::unreliable_shift_px).
  int nees_widened_n = 0;
  double nees_widened_sum = 0;
  // Their errors along the direction from the view's markers' mean centre (px): a blur or a
  // background that moves every centre in or out shows as a mean that is not 0.
  double radial_sum = 0, radial_sum2 = 0;

  void Add(const Tally& o) {
    expected += o.expected, correct += o.correct, wrong += o.wrong, off_centre += o.off_centre;
    spurious_labelled += o.spurious_labelled, overlap_labelled += o.overlap_labelled;
    outside_labelled += o.outside_labelled, overlapping_pairs += o.overlapping_pairs;
    outside += o.outside, crossed_by_wire += o.crossed_by_wire;
    views_lost_identifiable += o.views_lost_identifiable;
    for (const auto& [why, n] : o.missed) missed[why] += n;
    nees_n += o.nees_n, nees_beyond_1e3 += o.nees_beyond_1e3, nees_sum += o.nees_sum;
    nees_widened_n += o.nees_widened_n, nees_widened_sum += o.nees_widened_sum;
    radial_sum += o.radial_sum, radial_sum2 += o.radial_sum2;
  }
  // The mean radial error (px) and its standard error, over the nees_n labelled centres.
  double MeanRadialPx() const { return nees_n ? radial_sum / nees_n : 0.0; }
  double MeanRadialSePx() const {
    if (nees_n < 2) return 0.0;
    const double m = MeanRadialPx();
    return std::sqrt(std::max(0.0, radial_sum2 / nees_n - m * m) / (nees_n - 1));
  }
  // Mean NEES per dof of the labelled centres (1 when the covariances are honest).
  double NeesPerDof() const { return nees_n ? nees_sum / (2.0 * nees_n) : 0.0; }
};

inline Tally Score(const sim::XrayScene& scene,
                   const nlohmann::json& truth,
                   const std::vector<ObjectView>& views) {
  Tally t;
  const double fov_r = scene.render.fov_radius_px, cu = 255.5, cv_ = 255.5;
  const double d_px =
      scene.markers.sphere_diameter_mm * scene.camera.params[kFx] / scene.views[0].carm.sod_mm;
  EXPECT_EQ(views.size(), truth["views"].size());
  for (size_t v = 0; v < views.size() && v < truth["views"].size(); ++v) {
    const auto& tv = truth["views"][v];
    std::vector<Eigen::Vector2d> c;
    for (const auto& p : tv["centers_px"]) c.emplace_back(p[0].get<double>(), p[1].get<double>());
    std::vector<Eigen::Vector2d> clutter;
    if (tv.contains("clutter_centers_px")) {
      for (const auto& p : tv["clutter_centers_px"])
        clutter.emplace_back(p[0].get<double>(), p[1].get<double>());
    }
    const ObjectView& ov = views[v];
    // The clutter's wires (thin boxes) projected, as polylines of 200 points.
    std::vector<Eigen::Vector2d> wire_px;
    const Rigid3 cam_from_object = scene.CamFromObject(static_cast<int>(v));
    const Camera view_camera = scene.ViewCamera(static_cast<int>(v));
    for (const auto& box : scene.clutter.boxes) {
      int axis = 0;
      box.half_size_mm.maxCoeff(&axis);
      for (int i = 0; i <= 200; ++i) {
        Eigen::Vector3d p_box = Eigen::Vector3d::Zero();
        p_box[axis] = box.half_size_mm[axis] * (2.0 * i / 200 - 1);
        const Eigen::Vector3d p_cam = cam_from_object * (box.phantom_from_box * p_box);
        Eigen::Vector2d uv;
        if (ProjectCamPoint(view_camera.params.data(), p_cam.data(), uv.data()))
          wire_px.push_back(uv);
      }
    }
    Eigen::Vector2d mean_centre = Eigen::Vector2d::Zero();
    for (const auto& ck : c) mean_centre += ck / static_cast<double>(c.size());
    int view_expected = 0;
    for (size_t k = 0; k < c.size(); ++k) {
      const int id = scene.phantom.spheres[k].id;
      // Overlapping: another marker's or a bead's centre within 1.25 diameters (the blob finder's
      // merge_distance), so that the two shadows touch or merge: must not be labelled. Close:
      // 1.25-1.5 diameters: labelled or not, but if labelled then at its centre.
      double nearest = 1e9;
      for (size_t j = 0; j < c.size(); ++j) {
        if (j != k) nearest = std::min(nearest, (c[j] - c[k]).norm() / d_px);
      }
      for (const auto& s : clutter) nearest = std::min(nearest, (s - c[k]).norm() / d_px);
      // A wire across the marker's shadow (within its radius + 2 px): like a close pair.
      bool crossed = false;
      for (const auto& w : wire_px) crossed |= (w - c[k]).norm() < 0.5 * d_px + 2.0;
      t.crossed_by_wire += crossed;
      const bool overlapped = nearest < 1.25, close = nearest < 1.5 || crossed;
      const bool inside =
          std::hypot(c[k].x() - cu, c[k].y() - cv_) + d_px < fov_r - scene.render.fov_edge_px - 10;
      const bool outside = std::hypot(c[k].x() - cu, c[k].y() - cv_) - d_px > fov_r;
      t.outside += outside;
      t.overlapping_pairs += overlapped;
      // The blob labelled with this id, if any.
      int labelled_blob = -1;
      for (size_t b = 0; b < ov.detection.blobs.size() && ov.labelled; ++b) {
        if (ov.marker_id_of_blob[b] == id) labelled_blob = static_cast<int>(b);
      }
      if (overlapped) {
        t.overlap_labelled += labelled_blob >= 0;
        if (labelled_blob >= 0) {
          const cv::Point2d q = ov.detection.blobs[labelled_blob].uv_px;
          const cv::Matx22d& C = ov.detection.blobs[labelled_blob].covariance_px2;
          std::cout << "  " << ov.name << ": marker " << id
                    << " labelled although another marker or bead is " << nearest
                    << " diameters away (" << std::hypot(q.x - c[k].x(), q.y - c[k].y())
                    << " px from its centre; sigma " << std::sqrt(0.5 * (C(0, 0) + C(1, 1)))
                    << " px)\n";
        }
        continue;
      }
      if (outside) {
        t.outside_labelled += labelled_blob >= 0;
        continue;
      }
      if (!inside) continue;            // on the rim: not counted either way
      if (close && labelled_blob < 0) continue;  // a close pair or a wire across: may be left out
      ++t.expected;
      ++view_expected;
      if (labelled_blob < 0) {
        std::string why = "no blob found there";
        for (size_t b = 0; b < ov.detection.blobs.size(); ++b) {
          const cv::Point2d q = ov.detection.blobs[b].uv_px;
          if (std::hypot(q.x - c[k].x(), q.y - c[k].y()) < 0.5 * d_px) why = "a blob, not paired";
        }
        // A blob left out after the labelling (off the pose, overlapping) is also a rejection.
        std::string rejected;
        for (const auto& r : ov.detection.rejected) {
          if (std::hypot(r.uv_px.x - c[k].x(), r.uv_px.y - c[k].y()) < 0.5 * d_px) rejected = r.why;
        }
        if (!rejected.empty()) why = "rejected: " + rejected;
        // Counted by the reason's name, without its figures ("off the pose: 0.70 px ...").
        ++t.missed[!ov.labelled        ? "view skipped"
                   : !rejected.empty() ? rejected.substr(0, rejected.find(':'))
                                       : why];
        std::cout << "  " << ov.name << ": marker " << id << " not labelled ("
                  << (ov.labelled ? why : "view skipped: " + ov.skipped) << ")\n";
        continue;
      }
      const cv::Point2d q = ov.detection.blobs[labelled_blob].uv_px;
      const double err = std::hypot(q.x - c[k].x(), q.y - c[k].y());
      // The right marker: the blob lies within the marker's shadow (half a diameter of its
      // centre) and nearer to it than to any other marker or bead. Otherwise the label is wrong.
      bool this_marker = err < 0.5 * d_px;
      for (size_t j = 0; j < c.size(); ++j) {
        if (j != k) this_marker &= std::hypot(q.x - c[j].x(), q.y - c[j].y()) > err;
      }
      for (const auto& s : clutter) this_marker &= std::hypot(q.x - s.x(), q.y - s.y()) > err;
      // At its centre: within 0.5 px, or further but within its own covariance (a centre next to
      // an edge or a wire, widened by the detector): Mahalanobis^2 < 18.4 (chi2, 2 dof, 1e-4).
      const cv::Matx22d& C = ov.detection.blobs[labelled_blob].covariance_px2;
      const Eigen::Vector2d e(q.x - c[k].x(), q.y - c[k].y());
      const double det = C(0, 0) * C(1, 1) - C(0, 1) * C(1, 0);
      const double m2 =
          det > 0
              ? (C(1, 1) * e.x() * e.x() - 2 * C(0, 1) * e.x() * e.y() + C(0, 0) * e.y() * e.y()) /
                    det
              : 1e9;
      ++t.nees_n;
      t.nees_sum += m2;
      if (ov.detection.blobs[labelled_blob].shift_beyond_noise_px >
          MarkerBlobOptions().unreliable_shift_px) {
        ++t.nees_widened_n;
        t.nees_widened_sum += m2;
      }
      const Eigen::Vector2d out = c[k] - mean_centre;
      const double radial = out.norm() > 1 ? e.dot(out.normalized()) : 0.0;
      t.radial_sum += radial;
      t.radial_sum2 += radial * radial;
      t.nees_beyond_1e3 += m2 > 13.8;
      const bool at_centre = err < 0.5 || m2 < 18.4;
      if (this_marker) ++t.correct;
      if (this_marker && at_centre) continue;
      ++(this_marker ? t.off_centre : t.wrong);
      const MarkerBlob& mb = ov.detection.blobs[labelled_blob];
      std::cout << "  " << ov.name << ": marker " << id << " labelled " << err << " px away"
                << (this_marker ? ", off its covariance" : ": a wrong label")
                << " (nearest other marker or bead " << nearest << " diameters; sigma "
                << std::sqrt(std::max(mb.covariance_px2(0, 0), mb.covariance_px2(1, 1)))
                << " px, core-to-whole shift " << mb.background_shift_px << " px)\n";
    }
    t.views_lost_identifiable += !ov.labelled && view_expected >= 4;
    for (size_t b = 0; b < ov.detection.blobs.size() && ov.labelled; ++b) {
      if (ov.marker_id_of_blob[b] < 0) continue;
      const cv::Point2d q = ov.detection.blobs[b].uv_px;
      for (const auto& s : clutter)
        t.spurious_labelled += std::hypot(q.x - s.x(), q.y - s.y()) < 0.5 * d_px;
    }
  }
  return t;
}

}  // namespace carmba
