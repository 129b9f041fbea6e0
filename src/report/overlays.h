// Pictures of detections for checking by eye (the overlays/ of `carmba calibrate` and `carmba
// pose`).
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "detect/grid_detector.h"

namespace carmba {

// An 8-bit BGR copy of an image (any depth, grey or colour) stretched to its 1..99 % range, for
// overlays.
cv::Mat StretchedColourImage(const cv::Mat& image);

// An overlay's first line (its result, or why there is none) at the top left, in cv::putText's
// simplex font at `scale`.
void DrawHeadLine(cv::Mat* image, const std::string& text, double scale, const cv::Scalar& colour);

// An 8-bit colour picture of a detection for checking by eye: the image stretched to its 1..99 %
// range, found points as green circles with their ids, rejected blobs as red crosses with the
// reason, and a first line saying found (points of the grid) or the reason it was not.
cv::Mat DrawDetectionOverlay(const cv::Mat& image, const GridSpec& grid, const GridDetection& d);

// How a label is written (cv::putText's font, scale, colour and thickness).
struct LabelStyle {
  int font = 0;  // cv::FONT_HERSHEY_SIMPLEX
  double scale = 0.5;
  cv::Scalar colour;
  int thickness = 1;
};

// Writes the text labels of one picture so that they do not cover one another: a label goes to
// the first of eight places around its point (right above, right below, left above, left below,
// right, left, above, below) whose box is free of the labels and the reserved boxes already
// there. With no place free, a label whose text already stands within kSameTextReachPx is left
// out (where rejected blobs crowd along an edge their reason is read once), any other goes where
// it covers least. Labels written first keep their places: write the important ones first.
class LabelPlacer {
 public:
  static constexpr double kSameTextReachPx = 60;

  explicit LabelPlacer(cv::Size image_size) : image_(cv::Point(0, 0), image_size) {}
  // Keeps `box` free of later labels (a circle or marker drawn there).
  void Reserve(const cv::Rect& box) { taken_.push_back({box, ""}); }
  // Writes `text` beside `p`, `gap` px from it, onto `image`; false when it is left out.
  bool Write(
      cv::Mat* image, cv::Point p, int gap, const std::string& text, const LabelStyle& style);
  // The boxes of the labels written so far, in order.
  std::vector<cv::Rect> LabelBoxes() const;

 private:
  struct Taken {
    cv::Rect box;
    std::string text;
  };
  double Covered(const cv::Rect& box) const;

  cv::Rect image_;
  std::vector<Taken> taken_;
};

}  // namespace carmba
