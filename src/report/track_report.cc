#include "report/track_report.h"

#include <ceres/rotation.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "geometry/rotation.h"
#include "report/overlays.h"
#include "util/base64.h"
#include "util/file_util.h"
#include "util/format.h"
#include "util/image_codecs.h"

namespace carmba {

namespace {

std::string G(double x) { return Fmt("%.9g", x); }

// The 6x6 covariance with the rotation rows and columns in degrees.
Matrix6 InDegrees(const Matrix6& C) {
  Matrix6 D = Matrix6::Identity();
  for (int i = 0; i < 3; ++i) D(i, i) = kRadToDeg;
  return D * C * D;
}

const char* Verdict(bool ok) { return ok ? "yes" : "**no**"; }

}  // namespace

std::string TrackPointsCsv(const TrackResult& r) {
  std::ostringstream o;
  o << "# carmba track: each bead per frame in the cameras' lab frame (mm) from the bundle "
       "adjustment over all frames, its covariance (mm^2; poses and beads jointly), the cameras "
       "that saw it and its reprojection RMS (px per coordinate)\n";
  o << "frame,point,x_mm,y_mm,z_mm,cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz,num_views,rms_px\n";
  for (size_t f = 0; f < r.frames.size(); ++f) {
    for (size_t b = 0; b < r.beads.size(); ++b) {
      if (r.bead_num_views[f][b] == 0) continue;
      const Eigen::Vector3d& x = r.bead_lab[f][b];
      const Eigen::Matrix3d& C = r.bead_lab_covariance[f][b];
      o << r.frames[f].number << ',' << r.beads[b].id << ',' << G(x[0]) << ',' << G(x[1]) << ','
        << G(x[2]) << ',' << G(C(0, 0)) << ',' << G(C(0, 1)) << ',' << G(C(0, 2)) << ','
        << G(C(1, 1)) << ',' << G(C(1, 2)) << ',' << G(C(2, 2)) << ',' << r.bead_num_views[f][b]
        << ',' << Fmt("%.4f", r.bead_rms_px[f][b]) << '\n';
    }
  }
  return o.str();
}

std::string TrackObservationsCsv(const TrackResult& r) {
  std::ostringstream o;
  o << "# carmba track: the bead pixels the bundle adjustment used (px) and their covariances "
       "(px^2, the detector's)\n";
  o << "frame,camera,point,u_px,v_px,cov_uu,cov_uv,cov_vv\n";
  for (size_t f = 0; f < r.frames.size(); ++f) {
    for (const TrackBead& bead : r.beads) {
      const int k = bead.candidate[f];
      if (k < 0) continue;
      for (const TrackObservation& ob : r.candidates[f][k].observations) {
        o << r.frames[f].number << ',' << r.cameras[ob.camera].name << ',' << bead.id << ','
          << Fmt("%.4f", ob.uv_px[0]) << ',' << Fmt("%.4f", ob.uv_px[1]) << ','
          << G(ob.covariance_px2(0, 0)) << ',' << G(ob.covariance_px2(0, 1)) << ','
          << G(ob.covariance_px2(1, 1)) << '\n';
      }
    }
  }
  return o.str();
}

nlohmann::json TrackBodiesJson(const TrackResult& r) {
  nlohmann::json j;
  j["frame_of_reference"] =
      "lab (the cameras' calibration frame); a body's frame is the lab frame at the first frame";
  j["frames"] = nlohmann::json::array();
  for (const TrackFrame& f : r.frames) j["frames"].push_back(f.number);
  j["bodies"] = nlohmann::json::array();
  for (const TrackBody& body : r.bodies) {
    nlohmann::json b;
    b["id"] = body.id;
    b["points"] = nlohmann::json::array();
    for (int bi : body.beads) {
      const Eigen::Vector3d& p = r.bead_in_body[bi];
      const Eigen::Matrix3d& C = r.bead_covariance[bi];
      b["points"].push_back({{"point", r.beads[bi].id},
                             {"p_in_body_mm", {p[0], p[1], p[2]}},
                             {"covariance_mm2", {{C(0, 0), C(0, 1), C(0, 2)},
                                                 {C(1, 0), C(1, 1), C(1, 2)},
                                                 {C(2, 0), C(2, 1), C(2, 2)}}}});
    }
    b["poses"] = nlohmann::json::array();
    for (size_t f = 0; f < r.frames.size(); ++f) {
      if (!body.found[f]) continue;
      const Pose6& p = body.lab_from_body[f];
      const Matrix6 C = InDegrees(body.covariance[f]);
      nlohmann::json cov = nlohmann::json::array();
      for (int i = 0; i < 6; ++i) {
        nlohmann::json row = nlohmann::json::array();
        for (int k = 0; k < 6; ++k) row.push_back(C(i, k));
        cov.push_back(row);
      }
      b["poses"].push_back({{"frame", r.frames[f].number},
                            {"lab_from_body_rotation_deg",
                             {p[0] * kRadToDeg, p[1] * kRadToDeg, p[2] * kRadToDeg}},
                            {"lab_from_body_translation_mm", {p[3], p[4], p[5]}},
                            {"covariance_6x6", cov}});
    }
    b["distances"] = nlohmann::json::array();
    for (const BodyDistance& d : r.distances) {
      if (d.body != body.id) continue;
      nlohmann::json dist = nlohmann::json::array(), sig = nlohmann::json::array();
      for (size_t f = 0; f < r.frames.size(); ++f) {
        dist.push_back(JsonNumber(d.distance_mm[f]));
        sig.push_back(JsonNumber(d.sigma_mm[f]));
      }
      b["distances"].push_back({{"points", {d.bead_a, d.bead_b}},
                                {"distance_mm", dist},
                                {"sigma_mm", sig},
                                {"spread_mm", d.spread_mm},
                                {"max_change_sigmas", d.max_change_sigmas}});
    }
    j["bodies"].push_back(b);
  }
  const TrackChecks& c = r.checks;
  j["checks"] = {{"min_beads_per_frame", c.min_beads_per_frame},
                 {"pixel_sigma_scale", c.pixel_sigma_scale},
                 {"max_change_sigmas_stated", c.max_change_sigmas_stated},
                 {"rms_px", c.rms_px},
                 {"max_change_sigmas", c.max_change_sigmas},
                 {"max_spread_mm", c.max_spread_mm},
                 {"predicted_max_spread_mm", c.predicted_max_spread_mm},
                 {"rms_spread_mm", c.rms_spread_mm},
                 {"distance_chi2", c.distance_chi2},
                 {"distance_dof", c.distance_dof},
                 {"distance_chi2_p_value", c.distance_chi2_p}};
  j["bundle_adjustment"] = {{"chi2", r.ba_chi2}, {"dof", r.ba_dof}, {"sigma0", r.ba_sigma0}};
  j["warnings"] = r.warnings;
  return j;
}

std::string TrackOverlayName(const TrackResult& r, size_t i) {
  const TrackImage& im = r.images[i];
  return "overlays/frame" + std::to_string(r.frames[im.frame].number) + "_" +
         r.cameras[im.camera].name + ".png";
}

cv::Mat DrawTrackOverlay(const TrackResult& r, size_t i) {
  const TrackImage& im = r.images[i];
  cv::Mat grey = ImRead(im.path, cv::IMREAD_GRAYSCALE);
  if (grey.empty()) return grey;
  cv::Mat out;
  cv::cvtColor(grey, out, cv::COLOR_GRAY2BGR);
  const TrackCamera& cam = r.cameras[im.camera];
  const auto& cands = r.candidates[im.frame];
  // Epipolar lines: the rays of the other cameras' labelled beads, projected into this camera.
  for (const TrackBead& bead : r.beads) {
    const int k = bead.candidate[im.frame];
    if (k < 0) continue;
    for (const TrackObservation& ob : cands[k].observations) {
      if (ob.camera == im.camera) continue;
      const TrackCamera& other = r.cameras[ob.camera];
      double xy[2];
      if (!UnprojectToNormalized(other.intrinsics.data(), ob.uv_px.data(), xy)) continue;
      const Eigen::Matrix3d Ro = RotationOf(other.cam_from_lab.data());
      const Eigen::Vector3d c = other.CentreInLab();
      const Eigen::Vector3d d = (Ro.transpose() * Eigen::Vector3d(xy[0], xy[1], 1)).normalized();
      const double depth = (cands[k].point.p_lab - c).norm();
      std::vector<cv::Point> pts;
      for (double s : {depth - 150.0, depth + 150.0}) {
        const Eigen::Vector3d p = c + s * d;
        double uv[2];
        if (ProjectPoint(cam.intrinsics.data(), cam.cam_from_lab.data(), p.data(), uv)) {
          pts.emplace_back(cvRound(uv[0]), cvRound(uv[1]));
        }
      }
      if (pts.size() == 2) cv::line(out, pts[0], pts[1], cv::Scalar(255, 200, 0), 1, cv::LINE_AA);
    }
  }
  // The marks first, every one kept free of labels; then the labels, the beads' ids first.
  LabelPlacer labels(out.size());
  const cv::Scalar red(0, 0, 255), green(0, 220, 0), yellow(0, 220, 255);
  std::vector<std::pair<cv::Point, std::string>> reasons;
  for (const RejectedBlob& rb : im.detection.rejected) {
    if (rb.why == "low contrast") continue;  // thousands of them: background texture
    const cv::Point p(cvRound(rb.uv_px.x), cvRound(rb.uv_px.y));
    cv::drawMarker(out, p, red, cv::MARKER_TILTED_CROSS, 9, 1);
    labels.Reserve(cv::Rect(p - cv::Point(4, 4), cv::Size(9, 9)));
    // The reason's head only ("merged", not the pair fit's detail: the report has room for it).
    reasons.emplace_back(p, rb.why.substr(0, rb.why.find(" (")));
  }
  std::map<int, int> id_of_blob;
  for (const TrackBead& bead : r.beads) {
    const int k = bead.candidate[im.frame];
    if (k < 0) continue;
    for (const TrackObservation& ob : cands[k].observations)
      if (ob.camera == im.camera) id_of_blob[ob.blob] = bead.id;
  }
  const auto id_of = [&](size_t b) {
    const auto it = id_of_blob.find(static_cast<int>(b));
    return it == id_of_blob.end() ? -1 : it->second;
  };
  const auto centre_of = [&](size_t b) {
    return cv::Point(cvRound(im.detection.blobs[b].uv_px.x),
                     cvRound(im.detection.blobs[b].uv_px.y));
  };
  const auto radius_of = [&](size_t b) {
    return std::max(4, cvRound(im.detection.blobs[b].diameter_px));
  };
  for (size_t b = 0; b < im.detection.blobs.size(); ++b) {
    const cv::Point p = centre_of(b);
    const int radius = radius_of(b);
    cv::circle(out, p, radius, id_of(b) >= 0 ? green : yellow, 1, cv::LINE_AA);
    labels.Reserve(
        cv::Rect(p - cv::Point(radius, radius), cv::Size(2 * radius + 1, 2 * radius + 1)));
  }
  for (const bool with_id : {true, false}) {  // the beads' ids first
    for (size_t b = 0; b < im.detection.blobs.size(); ++b) {
      const int id = id_of(b);
      if ((id >= 0) != with_id) continue;
      if (with_id) {
        labels.Write(&out,
                     centre_of(b),
                     radius_of(b) + 2,
                     std::to_string(id),
                     {cv::FONT_HERSHEY_SIMPLEX, 0.5, green, 1});
      } else {
        labels.Write(&out,
                     centre_of(b),
                     radius_of(b) + 2,
                     "no id",
                     {cv::FONT_HERSHEY_PLAIN, 0.9, yellow, 1});
      }
    }
  }
  for (const auto& [p, why] : reasons)
    labels.Write(&out, p, 6, why, {cv::FONT_HERSHEY_PLAIN, 0.9, red, 1});
  const std::string title =
      "frame " + std::to_string(r.frames[im.frame].number) + ", camera " + cam.name +
      ": green = bead (id), yellow = blob without id, red = rejected (reason), "
      "cyan = epipolar lines of the other cameras' beads";
  cv::putText(
      out, title, cv::Point(10, 24), cv::FONT_HERSHEY_SIMPLEX, 0.6, cv::Scalar(255, 255, 255), 2);
  return out;
}

namespace {

// What the spread check says about the data: met; out of reach (the noise alone exceeds the
// target); or beyond what the noise explains (a wrong match or a body that is not rigid).
std::string SpreadVerdict(const TrackChecks& c, const TrackTargets& t) {
  const std::string measured = Fmt("%.3f", c.max_spread_mm) + " mm",
                    predicted = Fmt("%.3f", c.predicted_max_spread_mm) + " mm";
  if (c.max_spread_mm <= t.max_spread_mm) {
    return "The spread target holds: the largest spread is " + measured +
           " (the noise alone would give " + predicted + ").";
  }
  // The sigmas scale linearly with the pixel sigma scale, and so does the prediction.
  const double stated = c.predicted_max_spread_mm / c.pixel_sigma_scale;
  if (std::min(c.predicted_max_spread_mm, stated) > t.max_spread_mm) {
    return "The spread target (<= " + Fmt("%.2f", t.max_spread_mm) +
           " mm) is out of reach on these data: the pixel "
           "noise alone, propagated to each distance, gives an expected largest spread of " +
           predicted + " over these distances and frames at the sigmas above, and " +
           Fmt("%.3f", stated) + " mm even at the detector's stated covariances. The measured " +
           measured +
           " is within what the noise predicts (see the chi-square). Smaller spreads need less "
           "noise per bead (larger or denser beads, more photons, more cameras), not a different "
           "method.";
  }
  if (c.max_spread_mm <= c.predicted_max_spread_mm) {
    return "The largest spread, " + measured +
           ", exceeds the target but not what the noise predicts at the data's "
           "own sigmas (" +
           predicted + "; " + Fmt("%.3f", stated) +
           " mm at the detector's stated covariances): "
           "the target is within reach only if the detector's stated noise holds.";
  }
  return "The largest spread, " + measured +
         ", exceeds both the target and what the noise alone gives (" + predicted +
         "): look for a wrong match or a body that is not rigid (the distances table above).";
}

// The targets against what was measured, without ground truth.
void ChecksSection(const TrackResult& r, const TrackTargets& t, ReportDoc* doc) {
  const TrackChecks& c = r.checks;
  doc->Heading(2, "Checks");
  doc->Paragraph(
      "Without ground truth: the distances between the beads of one body, triangulated in each "
      "frame on its own (pixels only, the cameras held), must not change between frames beyond "
      "their predicted sigmas. The sigmas use the detector's pixel covariances scaled by the "
      "bundle adjustment's variance component of the detected blobs (sigma x " +
      Fmt("%.2f", c.pixel_sigma_scale) +
      "); at the detector's stated covariances the largest "
      "change is " +
      Fmt("%.2f", c.max_change_sigmas_stated) +
      " sigma. The chi-square treats the "
      "distances as independent (beads shared by two distances make them correlated).");
  doc->Table(
      {"check", "target", "measured", "holds"},
      {{"beads per frame from >= 2 cameras (least frame)",
        ">= " + std::to_string(t.min_beads_per_frame),
        std::to_string(c.min_beads_per_frame),
        Verdict(c.min_beads_per_frame >= t.min_beads_per_frame)},
       {"reprojection RMS (bundle adjustment, px per coordinate)",
        "<= " + Fmt("%.2f", t.max_rms_px),
        Fmt("%.3f", c.rms_px),
        Verdict(c.rms_px <= t.max_rms_px)},
       {"largest change of a body distance between frames",
        "<= " + Fmt("%.0f", t.max_change_sigmas) + " sigma",
        Fmt("%.2f", c.max_change_sigmas) + " sigma",
        Verdict(c.max_change_sigmas <= t.max_change_sigmas)},
       {"largest spread of a body distance over the frames",
        "<= " + Fmt("%.2f", t.max_spread_mm) + " mm",
        Fmt("%.3f", c.max_spread_mm) + " mm",
        Verdict(c.max_spread_mm <= t.max_spread_mm)},
       {"largest spread the noise alone gives (expected, from the sigmas)",
        "",
        Fmt("%.3f", c.predicted_max_spread_mm) + " mm",
        ""},
       {"RMS of the distances about their means", "", Fmt("%.4f", c.rms_spread_mm) + " mm", ""},
       {"chi-square of the distances about their means",
        "P >= 0.005",
        Fmt("%.1f", c.distance_chi2) + " on " + std::to_string(c.distance_dof) +
            " dof, P = " + Fmt("%.3g", c.distance_chi2_p),
        Verdict(c.distance_chi2_p >= 0.005)}});
  doc->Paragraph(
      SpreadVerdict(c, t) +
      " (Published marker-tracking precisions are usually a standard deviation of "
      "each inter-marker distance over the frames; its analogue here, the RMS of the distances "
      "about their means, is " +
      Fmt("%.3f", c.rms_spread_mm) + " mm.)");
}

// Per frame: the blobs each camera found and the beads given an id.
void FramesSection(const TrackResult& r, ReportDoc* doc) {
  doc->Heading(2, "Frames");
  std::vector<std::vector<std::string>> rows;
  for (size_t f = 0; f < r.frames.size(); ++f) {
    int beads = 0, single = 0;
    for (size_t b = 0; b < r.beads.size(); ++b) {
      beads += r.bead_num_views[f][b] >= 2;
      single += r.bead_num_views[f][b] == 1;
    }
    std::string per_cam;
    for (const TrackImage& im : r.images) {
      if (im.frame != static_cast<int>(f)) continue;
      per_cam +=
          (per_cam.empty() ? "" : ", ") + r.cameras[im.camera].name + " " +
          std::to_string(im.detection.blobs.size()) +
          (im.split_pairs ? " (" + std::to_string(2 * im.split_pairs) + " from split pairs)" : "");
    }
    rows.push_back({std::to_string(r.frames[f].number),
                    per_cam,
                    std::to_string(r.candidates[f].size() - single),
                    std::to_string(beads),
                    std::to_string(single)});
  }
  doc->Table({"frame",
              "blobs per camera",
              "epipolar candidates",
              "beads with an id (2+ cameras)",
              "beads seen by one camera (by prediction)"},
             rows);
}

// Per body and frame: its pose from the first frame with the sigmas of its rotation and of its
// beads' centroid.
void BodiesSection(const TrackResult& r, ReportDoc* doc) {
  doc->Heading(2, "Rigid bodies");
  std::vector<std::vector<std::string>> rows;
  for (const TrackBody& body : r.bodies) {
    std::string ids;
    for (int bi : body.beads) ids += (ids.empty() ? "" : " ") + std::to_string(r.beads[bi].id);
    for (size_t f = 0; f < r.frames.size(); ++f) {
      if (!body.found[f]) {
        rows.push_back({std::to_string(body.id),
                        ids,
                        std::to_string(r.frames[f].number),
                        "not found",
                        "",
                        "",
                        ""});
        continue;
      }
      const Pose6& p = body.lab_from_body[f];
      const Matrix6 C = InDegrees(body.covariance[f]);
      const double angle = Eigen::Vector3d(p[0], p[1], p[2]).norm() * kRadToDeg;
      // The beads' centroid moves by R c + t - c: its sigma, from the pose's covariance (the
      // translation's own sigma is about the lab origin, far from the body).
      Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
      for (int bi : body.beads) centroid += r.bead_in_body[bi];
      centroid /= static_cast<double>(body.beads.size());
      Eigen::Vector3d Rc;
      Eigen::Matrix<double, 3, 3, Eigen::RowMajor> J_r;
      RotatePointWithJac(p.data(), centroid.data(), Rc.data(), J_r.data());
      Eigen::Matrix<double, 3, 6> J;
      J << J_r, Eigen::Matrix3d::Identity();
      const double centroid_sigma = std::sqrt((J * body.covariance[f] * J.transpose()).trace());
      rows.push_back({std::to_string(body.id),
                      ids,
                      std::to_string(r.frames[f].number),
                      Fmt("%.2f", angle),
                      Fmt("%.2f", p[3]) + ", " + Fmt("%.2f", p[4]) + ", " + Fmt("%.2f", p[5]),
                      f == 0 ? "held (gauge)"
                             : Fmt("%.3f", std::sqrt(C.topLeftCorner<3, 3>().trace())) + " deg",
                      f == 0 ? "" : Fmt("%.3f", centroid_sigma) + " mm"});
    }
  }
  doc->Table({"body",
              "beads",
              "frame",
              "rotation from the first frame (deg)",
              "translation (mm, lab_from_body)",
              "sigma of the rotation (root of the trace)",
              "sigma of the beads' centroid (root of the trace)"},
             rows);
}

// Per pair of beads in one body: the distance in each frame, its sigma, spread and change.
void DistancesSection(const TrackResult& r, ReportDoc* doc) {
  doc->Heading(2, "Distances within the bodies");
  std::vector<std::vector<std::string>> rows;
  for (const BodyDistance& d : r.distances) {
    std::string per_frame;
    for (size_t f = 0; f < r.frames.size(); ++f) {
      per_frame +=
          (f ? ", " : "") +
          (std::isfinite(d.distance_mm[f]) ? Fmt("%.3f", d.distance_mm[f]) : std::string("-"));
    }
    double sigma = 0;
    for (double s : d.sigma_mm) if (std::isfinite(s)) sigma = std::max(sigma, s);
    rows.push_back({std::to_string(d.body),
                    std::to_string(d.bead_a) + "-" + std::to_string(d.bead_b),
                    per_frame,
                    Fmt("%.3f", sigma),
                    Fmt("%.3f", d.spread_mm),
                    Fmt("%.2f", d.max_change_sigmas)});
  }
  doc->Table({"body",
              "beads",
              "distance per frame (mm)",
              "sigma (mm, largest)",
              "spread (mm)",
              "largest change (sigma)"},
             rows);
}

// The bundle adjustment, the time per stage and the overlays.
void AdjustmentAndOverlaysSection(const TrackResult& r, ReportDoc* doc) {
  doc->Heading(2, "Bundle adjustment");
  doc->Paragraph(
      "Beads in their body's frame and the bodies' poses per frame, the cameras held, the first "
      "frame's poses held at the identity; pixels whitened by the detector's 2x2 covariances, "
      "scaled per noise group (covariance.scale per_group). Chi-square " +
      Fmt("%.1f", r.ba_chi2) + " on " + std::to_string(r.ba_dof) +
      " dof at the detector's "
      "covariances (sigma0 " +
      Fmt("%.2f", r.ba_sigma0) + ").");
  doc->Paragraph("Time: detection " + Fmt("%.2f", r.time_detect_s) + " s, matching and identity " +
                 Fmt("%.3f", r.time_match_s) + " s, bundle adjustment " + Fmt("%.3f", r.time_ba_s) +
                 " s.");
  doc->Heading(2, "Overlays");
  doc->Paragraph(
      "Around the beads (report.html); the whole images are in `overlays/`. Green: a bead and its "
      "id; yellow: a blob without an id; red: a rejected blob and the reason; cyan: the epipolar "
      "lines of the other cameras' beads.");
  doc->Figures({"overlay-"});
  std::vector<std::string> items;
  for (size_t i = 0; i < r.images.size(); ++i) items.push_back("`" + TrackOverlayName(r, i) + "`");
  doc->List(items);
}

}  // namespace

ReportDoc TrackReportDoc(const TrackResult& r, const TrackTargets& t) {
  ReportDoc doc;
  doc.Heading(1, "carmba track");
  doc.Paragraph(
      std::to_string(r.cameras.size()) + " cameras, " + std::to_string(r.frames.size()) +
      " frames, " + std::to_string(r.beads.size()) + " beads in " +
      std::to_string(r.bodies.size()) +
      " rigid bodies. Positions are in the cameras' lab frame (mm); a body's frame is the lab "
      "frame at the first frame (frame " +
      std::to_string(r.frames.front().number) + ").");
  for (const std::string& w : r.warnings) doc.Warning(w);
  ChecksSection(r, t, &doc);
  FramesSection(r, &doc);
  BodiesSection(r, &doc);
  DistancesSection(r, &doc);
  AdjustmentAndOverlaysSection(r, &doc);
  return doc;
}

std::vector<ReportPlot> TrackOverlayPlots(const TrackResult& r,
                                          const std::vector<cv::Mat>& overlays) {
  std::vector<ReportPlot> plots;
  for (size_t i = 0; i < r.images.size() && i < overlays.size(); ++i) {
    const TrackImage& im = r.images[i];
    // The beads' bounding box with a margin (the whole overlay when none has an id).
    cv::Rect box;
    for (const TrackBead& bead : r.beads) {
      const int k = bead.candidate[im.frame];
      if (k < 0) continue;
      for (const TrackObservation& ob : r.candidates[im.frame][k].observations) {
        if (ob.camera != im.camera) continue;
        const cv::Rect p(cvRound(ob.uv_px[0]) - 60, cvRound(ob.uv_px[1]) - 60, 121, 121);
        box = box.area() == 0 ? p : (box | p);
      }
    }
    box = box.area() == 0 ? cv::Rect(0, 0, overlays[i].cols, overlays[i].rows)
                          : box & cv::Rect(0, 0, overlays[i].cols, overlays[i].rows);
    std::vector<uint8_t> png;
    if (!ImEncode(".png", overlays[i](box), &png)) continue;
    ReportPlot p;
    p.id = "overlay-" + std::to_string(i);
    p.title =
        "frame " + std::to_string(r.frames[im.frame].number) + ", " + r.cameras[im.camera].name;
    p.caption = "Pixels " + std::to_string(box.x) + ".." + std::to_string(box.x + box.width) +
                " x " + std::to_string(box.y) + ".." + std::to_string(box.y + box.height) + " of " +
                TrackOverlayName(r, i) + ".";
    p.png_base64 = Base64(png);
    plots.push_back(std::move(p));
  }
  return plots;
}

Status WriteTrackOutputs(const TrackResult& r,
                         const TrackTargets& targets,
                         const std::string& dir) {
  if (Status s = WriteFileAtomic(JoinPath(dir, "points.csv"), TrackPointsCsv(r)); !s.ok()) return s;
  if (Status s = WriteFileAtomic(JoinPath(dir, "observations.csv"), TrackObservationsCsv(r));
      !s.ok())
    return s;
  if (Status s =
          WriteFileAtomic(JoinPath(dir, "rigid_bodies.json"), TrackBodiesJson(r).dump(2) + "\n");
      !s.ok()) {
    return s;
  }
  if (Status s = MakeDirs(JoinPath(dir, "overlays")); !s.ok()) return s;
  std::vector<cv::Mat> overlays;
  for (size_t i = 0; i < r.images.size(); ++i) {
    overlays.push_back(DrawTrackOverlay(r, i));
    const std::string path = JoinPath(dir, TrackOverlayName(r, i));
    if (overlays.back().empty() || !ImWrite(path, overlays.back()))
      return Status::Error(path + ": cannot be written");
  }
  const ReportDoc doc = TrackReportDoc(r, targets);
  if (Status s = WriteFileAtomic(JoinPath(dir, "report.md"), doc.Markdown()); !s.ok()) return s;
  return WriteFileAtomic(JoinPath(dir, "report.html"),
                         doc.Html("carmba track", TrackOverlayPlots(r, overlays), ""));
}

}  // namespace carmba
