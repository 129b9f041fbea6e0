// Pictures of detections for checking by eye (the overlays/ of `carmba calibrate` and `carmba
// pose`).
#pragma once

#include <opencv2/core.hpp>

#include "detect/grid_detector.h"

namespace carmba {

// An 8-bit BGR copy of an image (any depth, grey or colour) stretched to its 1..99 % range, for
// overlays.
cv::Mat StretchedColourImage(const cv::Mat& image);

// An 8-bit colour picture of a detection for checking by eye: the image stretched to its 1..99 %
// range, found points as green circles with their ids, rejected blobs as red crosses with the
// reason, and a first line saying found (points of the grid) or the reason it was not.
cv::Mat DrawDetectionOverlay(const cv::Mat& image, const GridSpec& grid, const GridDetection& d);

}  // namespace carmba
