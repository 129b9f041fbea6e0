#include "detect/overlays.h"
#include "detect/detect_steps.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <string>
#include <vector>

namespace carmba {

cv::Mat StretchedColourImage(const cv::Mat& image) {
  cv::Mat f, shown, out;
  GreyImage(image).convertTo(f, CV_32F);
  std::vector<float> vals(f.begin<float>(), f.end<float>());
  double lo = 0, hi = 1;
  if (!vals.empty()) {
    const size_t k01 = vals.size() / 100, k99 = vals.size() - 1 - vals.size() / 100;
    std::nth_element(vals.begin(), vals.begin() + k01, vals.end());
    lo = vals[k01];
    std::nth_element(vals.begin(), vals.begin() + k99, vals.end());
    hi = vals[k99];
  }
  if (!(hi > lo)) hi = lo + 1;
  f.convertTo(shown, CV_8U, 255.0 / (hi - lo), -255.0 * lo / (hi - lo));
  cv::cvtColor(shown, out, cv::COLOR_GRAY2BGR);
  return out;
}

cv::Mat DrawDetectionOverlay(const cv::Mat& image, const GridSpec& grid, const GridDetection& d) {
  cv::Mat out = StretchedColourImage(image);
  const double scale = std::max(0.35, std::min(out.cols, out.rows) / 1400.0);
  const cv::Scalar green(0, 200, 0), red(0, 0, 255), yellow(0, 220, 255);
  for (size_t i = 0; i < d.view.uv_px.size(); ++i) {
    const cv::Point2d p(d.view.uv_px[i].x(), d.view.uv_px[i].y());
    cv::circle(out, p, 6, green, 1, cv::LINE_AA);
    cv::putText(out, std::to_string(d.view.point_ids[i]), p + cv::Point2d(6, -6),
                cv::FONT_HERSHEY_SIMPLEX, scale, green, 1, cv::LINE_AA);
  }
  for (const RejectedBlob& b : d.rejected) {
    cv::drawMarker(out, b.uv_px, red, cv::MARKER_CROSS, 10, 1, cv::LINE_AA);
    if (b.why != "no grid") {
      cv::putText(out, b.why, b.uv_px + cv::Point2d(6, 12), cv::FONT_HERSHEY_SIMPLEX, 0.8 * scale,
                  red, 1, cv::LINE_AA);
    }
  }
  const std::string head =
      d.found
          ? "found " + std::to_string(d.view.uv_px.size()) + " of " +
                std::to_string(grid.NumPoints()) + " points" +
                (d.rejected.empty() ? "" : ", " + std::to_string(d.rejected.size()) + " rejected")
          : "not found: " + d.reason;
  cv::putText(out, head, cv::Point(4, static_cast<int>(4 + 28 * scale)), cv::FONT_HERSHEY_SIMPLEX,
              scale, d.found ? green : yellow, 1, cv::LINE_AA);
  return out;
}

}  // namespace carmba
