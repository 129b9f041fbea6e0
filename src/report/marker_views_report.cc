#include "report/marker_views_report.h"

#include <opencv2/imgproc.hpp>

#include <cctype>
#include <sstream>

#include "camera/camera_model.h"
#include "report/overlays.h"
#include "util/format.h"

namespace carmba {

std::string MarkerObservationsCsv(const std::vector<ObjectView>& views) {
  std::ostringstream os;
  os.precision(10);
  os << "# carmba marker observations: detected blobs labelled with CT markers\n"
        "# u_px, v_px: sub-pixel centre (pixel (0,0) = centre of the top-left pixel); cov_*: "
        "its 2x2 covariance (px^2) from the local image noise\n"
        "view,marker,u_px,v_px,cov_uu,cov_uv,cov_vv\n";
  for (const ObjectView& v : views) {
    for (const Observation& o : LabelledObservations(v)) {
      os << v.id << "," << o.marker_id << "," << o.uv_px.x() << "," << o.uv_px.y() << ","
         << o.covariance_px2(0, 0) << "," << o.covariance_px2(0, 1) << "," << o.covariance_px2(1, 1)
         << "\n";
    }
  }
  return os.str();
}

nlohmann::json ObjectViewsToJson(const std::vector<ObjectView>& views) {
  nlohmann::json out = nlohmann::json::array();
  for (const ObjectView& v : views) {
    nlohmann::json j;
    j["view"] = v.id;
    j["image"] = v.name;
    j["blobs"] = v.detection.blobs.size();
    j["labelled"] = v.labelled;
    if (!v.labelled) j["skipped"] = v.skipped;
    if (v.labelled) {
      j["markers_labelled"] = v.labelling.num_labelled;
      j["method"] = v.labelling.method;
      j["rms_px"] = v.labelling.rms_px;
      j["hypotheses"] = v.labelling.hypotheses;
      int unlabelled = 0;
      for (int id : v.marker_id_of_blob) unlabelled += id < 0;
      j["blobs_not_markers"] = unlabelled;
      if (v.labelling.second_num_labelled > 0) {
        j["second_best"] = {{"markers", v.labelling.second_num_labelled},
                            {"rms_px", v.labelling.second_rms_px}};
      }
    }
    j["px_per_mm"] = v.px_per_mm;
    j["noise_correlation_factor"] = v.detection.correlation_factor;
    j["blur_variance_px2"] = v.detection.blur_variance_px2;
    j["blur_correction_max_px"] = LargestBlurCorrectionPx(v.detection);
    nlohmann::json rej = nlohmann::json::array();
    for (const RejectedBlob& b : v.detection.rejected) {
      rej.push_back({{"u_px", b.uv_px.x},
                     {"v_px", b.uv_px.y},
                     {"diameter_px", b.diameter_px},
                     {"why", b.why}});
    }
    j["rejected"] = rej;
    out.push_back(j);
  }
  return out;
}

std::string OverlayFileName(const std::string& view_id) {
  std::string stem = view_id;  // `#frameN` becomes `_frameN` too
  for (char& c : stem) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-')) c = '_';
  }
  return "overlay_" + stem + ".png";
}

cv::Mat DrawMarkerOverlay(const ObjectView& v,
                          const Camera& camera,
                          const std::vector<Marker>& markers,
                          const std::optional<Pose6>& cam_from_object) {
  cv::Mat out = StretchedColourImage(v.image);
  const double scale = std::max(0.35, std::min(out.cols, out.rows) / 1400.0);
  const cv::Scalar green(0, 200, 0), red(0, 0, 255), yellow(0, 220, 255), cyan(255, 255, 0);
  if (cam_from_object) {
    for (const Marker& m : markers) {
      Eigen::Vector2d q;
      if (!ProjectPoint(
              camera.params.data(), cam_from_object->data(), m.p_in_object.data(), q.data()))
        continue;
      cv::drawMarker(out, cv::Point2d(q.x(), q.y()), cyan, cv::MARKER_CROSS, 14, 1, cv::LINE_AA);
    }
  }
  // The marks first, every one kept free of labels; then the labels, the markers' ids first.
  LabelPlacer labels(out.size());
  for (const RejectedBlob& b : v.detection.rejected) {
    cv::drawMarker(out, b.uv_px, red, cv::MARKER_TILTED_CROSS, 10, 1, cv::LINE_AA);
    labels.Reserve(cv::Rect(cv::Point(b.uv_px) - cv::Point(5, 5), cv::Size(11, 11)));
  }
  const auto id_of = [&](size_t i) { return v.labelled ? v.marker_id_of_blob[i] : -1; };
  const auto radius_of = [](const MarkerBlob& b) {
    return static_cast<int>(std::lround(std::max(4.0, 0.5 * b.diameter_px + 2)));
  };
  for (size_t i = 0; i < v.detection.blobs.size(); ++i) {
    const MarkerBlob& b = v.detection.blobs[i];
    const int r = radius_of(b);
    cv::circle(out, b.uv_px, r, id_of(i) >= 0 ? green : yellow, 1, cv::LINE_AA);
    labels.Reserve(cv::Rect(cv::Point(b.uv_px) - cv::Point(r, r), cv::Size(2 * r + 1, 2 * r + 1)));
  }
  for (const bool with_id : {true, false}) {
    for (size_t i = 0; i < v.detection.blobs.size(); ++i) {
      const int id = id_of(i);
      if ((id >= 0) != with_id) continue;
      const MarkerBlob& b = v.detection.blobs[i];
      labels.Write(
          &out,
          cv::Point(b.uv_px),
          radius_of(b) + 2,
          with_id ? std::to_string(id) : std::string("not a marker"),
          {cv::FONT_HERSHEY_SIMPLEX, (with_id ? 1.0 : 0.8) * scale, with_id ? green : yellow, 1});
    }
  }
  for (const RejectedBlob& b : v.detection.rejected)
    labels.Write(
        &out, cv::Point(b.uv_px), 6, b.why, {cv::FONT_HERSHEY_SIMPLEX, 0.8 * scale, red, 1});
  std::ostringstream head;
  head.precision(3);
  if (v.labelled) {
    head << v.labelling.num_labelled << " markers labelled (" << v.labelling.method << "), RMS "
         << v.labelling.rms_px << " px; " << v.detection.rejected.size() << " rejected";
  } else {
    head << "skipped: " << v.skipped;
  }
  DrawHeadLine(&out, head.str(), scale, v.labelled ? green : yellow);
  return out;
}

}  // namespace carmba
