// Undistortion onto the projection matrices' pixel grid (undistort.h).
#include "export/undistort.h"

#include <opencv2/imgproc.hpp>

namespace carmba {

void UndistortMaps(const Camera& camera, cv::Mat* map_x, cv::Mat* map_y) {
  const double* k = camera.params.data();
  map_x->create(camera.height, camera.width, CV_32FC1);
  map_y->create(camera.height, camera.width, CV_32FC1);
  for (int v = 0; v < camera.height; ++v) {
    float* mx = map_x->ptr<float>(v);
    float* my = map_y->ptr<float>(v);
    for (int u = 0; u < camera.width; ++u) {
      const double p[3] = {(u - k[kCx]) / k[kFx], (v - k[kCy]) / k[kFy], 1.0};
      double uv[2];
      if (!ProjectCamPoint(k, p, uv)) uv[0] = uv[1] = -1e6;  // never: z = 1
      mx[u] = static_cast<float>(uv[0]);
      my[u] = static_cast<float>(uv[1]);
    }
  }
}

StatusOr<cv::Mat> UndistortImage(const cv::Mat& image, const Camera& camera) {
  if (image.cols != camera.width || image.rows != camera.height) {
    return Status::Error("image is " + std::to_string(image.cols) + "x" +
                         std::to_string(image.rows) + " px, the camera's image_size " +
                         std::to_string(camera.width) + "x" + std::to_string(camera.height));
  }
  if (image.depth() != CV_8U && image.depth() != CV_16U && image.depth() != CV_32F) {
    return Status::Error("expected an 8- or 16-bit unsigned or 32-bit float image");
  }
  cv::Mat mx, my, out;
  UndistortMaps(camera, &mx, &my);
  cv::remap(image, out, mx, my, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
  return out;
}

}  // namespace carmba
