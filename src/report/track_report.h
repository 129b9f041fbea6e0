// The outputs of `carmba track` (src/docs/formats.md has each file's columns and keys):
//   points.csv         frame,point,x_mm,y_mm,z_mm,cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz,
//                      num_views,rms_px: each bead per frame in the cameras' lab frame from the
//                      bundle adjustment (one id in every frame);
//   observations.csv   frame,camera,point,u_px,v_px,cov_uu,cov_uv,cov_vv: the pixels it used;
//   rigid_bodies.json  the bodies, their beads, per frame lab_from_body with its 6x6 covariance,
//                      the inter-bead distances per frame and the checks;
//   report.md / report.html, overlays/<frame>_<camera>.png (beads with ids, the other cameras'
//                      beads' epipolar lines, rejected blobs with their reasons).
#pragma once

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>

#include "report/report_doc.h"
#include "track/track.h"

namespace carmba {

// Targets of issue 22 for a tracking run (the report says which hold).
struct TrackTargets {
  int min_beads_per_frame = 10;
  double max_rms_px = 0.4;
  double max_change_sigmas = 3.0;
  double max_spread_mm = 0.1;
};

std::string TrackPointsCsv(const TrackResult& r);
std::string TrackObservationsCsv(const TrackResult& r);
nlohmann::json TrackBodiesJson(const TrackResult& r);
ReportDoc TrackReportDoc(const TrackResult& r, const TrackTargets& targets);
// The overlay of image `i` of r.images.
cv::Mat DrawTrackOverlay(const TrackResult& r, size_t i);
std::string TrackOverlayName(const TrackResult& r, size_t i);
// The overlays cropped to the beads, for report.html (PNG, base64).
std::vector<ReportPlot> TrackOverlayPlots(const TrackResult& r,
                                          const std::vector<cv::Mat>& overlays);

// Writes every output into `dir` (a staging directory: the caller commits it).
Status WriteTrackOutputs(const TrackResult& r, const TrackTargets& targets, const std::string& dir);

}  // namespace carmba
