// The outputs of object views read from images (detect/marker_views.h): observations.csv,
// result.json's `marker_detection` section, and an overlay per view.
#pragma once

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "detect/marker_views.h"

namespace carmba {

// observations.csv: `view,marker,u_px,v_px,cov_uu,cov_uv,cov_vv` (px, px^2), one row per labelled
// blob, after '#' comment lines (the columns' meaning).
std::string MarkerObservationsCsv(const std::vector<ObjectView>& views);
// Per view: blobs found, markers labelled (method, RMS, hypotheses), unlabelled blobs, rejected
// candidates by reason, or why it was skipped.
nlohmann::json ObjectViewsToJson(const std::vector<ObjectView>& views);
// A file name for a view's overlay: overlay_<id>.png (`#frameN` as `_frameN`, characters other
// than letters, digits, '_' and '-' as '_').
std::string OverlayFileName(const std::string& view_id);

// An overlay for checking by eye: the image stretched to 1..99 %, labelled blobs (green circle and
// marker id), unlabelled accepted blobs (yellow, "not a marker"), rejected candidates (red cross
// and reason), the markers reprojected with `cam_from_object` when given (cyan +), and a first
// line with the view's result or the reason it was skipped.
cv::Mat DrawMarkerOverlay(const ObjectView& view,
                          const Camera& camera,
                          const std::vector<Marker>& markers,
                          const std::optional<Pose6>& cam_from_object);

}  // namespace carmba
