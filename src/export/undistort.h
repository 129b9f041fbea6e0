// Undistortion of X-ray images with a calibrated camera (camera/camera_model.h), onto the pixel
// grid the exported projection matrices use (export/view_geometry.h):
//   * same width x height, same pixel convention (pixel (0,0) = centre of the top-left pixel);
//   * an ideal pinhole with the camera's fx, fy, cx, cy and no distortion.
// Undistorted pixel (u, v) takes the original image at the DISTORTED projection of its ray
// x = (u - cx)/fx, y = (v - cy)/fy (the forward model, no iteration), bilinearly interpolated
// (cv::remap, INTER_LINEAR); pixels whose source falls outside the original image are 0.
// The depth and channels are kept: CV_8U stays 8-bit, CV_16U 16-bit, CV_32F float.
#pragma once

#include <opencv2/core.hpp>

#include "camera/camera.h"
#include "util/status.h"

namespace carmba {

// The maps for cv::remap (CV_32FC1 each: the original image's x and y of every undistorted pixel).
void UndistortMaps(const Camera& camera, cv::Mat* map_x, cv::Mat* map_y);

// Errors: the image's size differs from the camera's image_size; a depth other than 8 or 16 bit
// unsigned or 32-bit float.
StatusOr<cv::Mat> UndistortImage(const cv::Mat& image, const Camera& camera);

}  // namespace carmba
