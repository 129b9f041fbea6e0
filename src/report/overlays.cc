#include "report/overlays.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "detect/detect_steps.h"

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
  // The marks first, every one kept free of labels; then the labels, the points' ids first.
  LabelPlacer labels(out.size());
  for (size_t i = 0; i < d.view.uv_px.size(); ++i) {
    const cv::Point p(cvRound(d.view.uv_px[i].x()), cvRound(d.view.uv_px[i].y()));
    cv::circle(out, p, 6, green, 1, cv::LINE_AA);
    labels.Reserve(cv::Rect(p - cv::Point(6, 6), cv::Size(13, 13)));
  }
  for (const RejectedBlob& b : d.rejected) {
    cv::drawMarker(out, b.uv_px, red, cv::MARKER_CROSS, 10, 1, cv::LINE_AA);
    labels.Reserve(cv::Rect(cv::Point(b.uv_px) - cv::Point(5, 5), cv::Size(11, 11)));
  }
  for (size_t i = 0; i < d.view.uv_px.size(); ++i) {
    const cv::Point p(cvRound(d.view.uv_px[i].x()), cvRound(d.view.uv_px[i].y()));
    labels.Write(&out,
                 p,
                 7,
                 std::to_string(d.view.point_ids[i]),
                 {cv::FONT_HERSHEY_SIMPLEX, scale, green, 1});
  }
  for (const RejectedBlob& b : d.rejected) {
    if (b.why == "no grid") continue;
    labels.Write(
        &out, cv::Point(b.uv_px), 6, b.why, {cv::FONT_HERSHEY_SIMPLEX, 0.8 * scale, red, 1});
  }
  const std::string head =
      d.found
          ? "found " + std::to_string(d.view.uv_px.size()) + " of " +
                std::to_string(grid.NumPoints()) + " points" +
                (d.rejected.empty() ? "" : ", " + std::to_string(d.rejected.size()) + " rejected")
          : "not found: " + d.reason;
  DrawHeadLine(&out, head, scale, d.found ? green : yellow);
  return out;
}

void DrawHeadLine(cv::Mat* image, const std::string& text, double scale, const cv::Scalar& colour) {
  cv::putText(*image,
              text,
              cv::Point(4, static_cast<int>(4 + 28 * scale)),
              cv::FONT_HERSHEY_SIMPLEX,
              scale,
              colour,
              1,
              cv::LINE_AA);
}

std::vector<cv::Rect> LabelPlacer::LabelBoxes() const {
  std::vector<cv::Rect> boxes;
  for (const Taken& t : taken_)
    if (!t.text.empty()) boxes.push_back(t.box);
  return boxes;
}

double LabelPlacer::Covered(const cv::Rect& box) const {
  double covered = box.area() - (box & image_).area();  // outside the picture counts too
  for (const Taken& t : taken_) covered += (box & t.box).area();
  return covered;
}

bool LabelPlacer::Write(
    cv::Mat* image, cv::Point p, int gap, const std::string& text, const LabelStyle& style) {
  int baseline = 0;
  const cv::Size size = cv::getTextSize(text, style.font, style.scale, style.thickness, &baseline);
  const int w = size.width, h = size.height + baseline;
  // Boxes (top-left corner) around p, in the order they are tried.
  const cv::Point corners[] = {{p.x + gap, p.y - gap - h},
                               {p.x + gap, p.y + gap},
                               {p.x - gap - w, p.y - gap - h},
                               {p.x - gap - w, p.y + gap},
                               {p.x + gap, p.y - h / 2},
                               {p.x - gap - w, p.y - h / 2},
                               {p.x - w / 2, p.y - gap - h},
                               {p.x - w / 2, p.y + gap}};
  cv::Rect best;
  double least = -1;
  for (const cv::Point& c : corners) {
    const cv::Rect box(c, cv::Size(w, h));
    const double covered = Covered(box);
    if (least < 0 || covered < least) least = covered, best = box;
    if (covered == 0) break;
  }
  if (least > 0) {
    for (const Taken& t : taken_) {
      const cv::Point d = (t.box.tl() + t.box.br()) / 2 - p;
      if (t.text == text && std::hypot(d.x, d.y) < kSameTextReachPx) return false;
    }
  }
  taken_.push_back({best, text});
  cv::putText(*image,
              text,
              cv::Point(best.x, best.y + size.height),
              style.font,
              style.scale,
              style.colour,
              style.thickness,
              cv::LINE_AA);
  return true;
}

}  // namespace carmba
