#include "detect/blob_pair_fit.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <vector>

namespace carmba {

namespace {

constexpr int kParams = 10;  // b0, bx, by, a1, u1, v1, a2, u2, v2, s
using Vec = Eigen::Matrix<double, kParams, 1>;

struct Window {
  std::vector<double> x, y, value;  // window pixels, coordinates relative to the window centre
  cv::Point2d origin;               // the window centre in the image
};

// Residuals model - value and (optionally) the Jacobian rows.
double Evaluate(const Window& w, const Vec& p, Eigen::VectorXd* r, Eigen::MatrixXd* J) {
  const size_t n = w.value.size();
  r->resize(static_cast<Eigen::Index>(n));
  if (J) J->resize(static_cast<Eigen::Index>(n), kParams);
  const double s2 = p[9] * p[9];
  double sum = 0;
  for (size_t i = 0; i < n; ++i) {
    double model = p[0] + p[1] * w.x[i] + p[2] * w.y[i];
    double d_s = 0;
    const auto e = static_cast<Eigen::Index>(i);
    for (int k = 0; k < 2; ++k) {
      const double a = p[3 + 3 * k], dx = w.x[i] - p[4 + 3 * k], dy = w.y[i] - p[5 + 3 * k];
      const double q = dx * dx + dy * dy;
      const double g = std::exp(-q / (2 * s2));
      model -= a * g;
      if (J) {
        (*J)(e, 3 + 3 * k) = -g;
        (*J)(e, 4 + 3 * k) = -a * g * dx / s2;
        (*J)(e, 5 + 3 * k) = -a * g * dy / s2;
      }
      d_s += -a * g * q / (s2 * p[9]);
    }
    if (J) {
      (*J)(e, 0) = 1;
      (*J)(e, 1) = w.x[i];
      (*J)(e, 2) = w.y[i];
      (*J)(e, 9) = d_s;
    }
    (*r)[e] = model - w.value[i];
    sum += (*r)[e] * (*r)[e];
  }
  return sum;
}

// No pair: `why` says the reason.
std::optional<BlobPairFit> Refuse(std::string* why, const std::string& text) {
  if (why) *why = text;
  return std::nullopt;
}

}  // namespace

std::optional<BlobPairFit> FitBlobPair(const cv::Mat& grey,
                                       cv::Point2d centre,
                                       double diameter_px,
                                       double min_contrast,
                                       double correlation_factor,
                                       std::string* why) {
  if (grey.type() != CV_32F || !(diameter_px > 1)) return Refuse(why, "bad input");
  const int half = static_cast<int>(std::ceil(1.6 * diameter_px));
  const cv::Rect box =
      cv::Rect(cvRound(centre.x) - half, cvRound(centre.y) - half, 2 * half + 1, 2 * half + 1) &
      cv::Rect(0, 0, grey.cols, grey.rows);
  if (box.width < 2 * half + 1 || box.height < 2 * half + 1)
    return Refuse(why, "at the image border");
  const cv::Mat patch = grey(box);
  Window w;
  w.origin = cv::Point2d(box.x + half, box.y + half);
  std::vector<double> border;
  for (int y = 0; y < patch.rows; ++y) {
    for (int x = 0; x < patch.cols; ++x) {
      w.x.push_back(x - half);
      w.y.push_back(y - half);
      w.value.push_back(patch.at<float>(y, x));
      if (x == 0 || y == 0 || x == patch.cols - 1 || y == patch.rows - 1)
        border.push_back(patch.at<float>(y, x));
    }
  }
  std::nth_element(border.begin(), border.begin() + border.size() / 2, border.end());
  const double background = border[border.size() / 2];
  // Start: the two darkest separated pixels of the blurred window, near the merged region.
  cv::Mat blurred;
  cv::GaussianBlur(patch, blurred, cv::Size(3, 3), 0.8);
  auto darkest = [&](const cv::Point* away) {
    cv::Point best(-1, -1);
    float v = 1e30f;
    for (int y = 0; y < blurred.rows; ++y) {
      for (int x = 0; x < blurred.cols; ++x) {
        if (std::hypot(x - half, y - half) > 1.1 * diameter_px) continue;
        if (away && std::hypot(x - away->x, y - away->y) < 0.6 * diameter_px) continue;
        if (blurred.at<float>(y, x) < v) v = blurred.at<float>(y, x), best = cv::Point(x, y);
      }
    }
    return best;
  };
  const cv::Point p1 = darkest(nullptr);
  const cv::Point p2 = darkest(&p1);
  if (p1.x < 0 || p2.x < 0) return Refuse(why, "no second dark blob");
  if (!(background - blurred.at<float>(p2) > min_contrast * background)) {
    return Refuse(why, "one of the two is fainter than min_contrast");
  }
  Vec p;
  p << background, 0, 0, background - blurred.at<float>(p1), p1.x - half, p1.y - half,
      background - blurred.at<float>(p2), p2.x - half, p2.y - half, diameter_px / 2.355;
  // Levenberg-Marquardt.
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  double cost = Evaluate(w, p, &r, &J), lambda = 1e-3;
  int it = 0;
  bool converged = false;
  for (; it < 50 && !converged; ++it) {
    const Eigen::MatrixXd H = J.transpose() * J;
    const Eigen::VectorXd g = J.transpose() * r;
    for (int tries = 0; tries < 10; ++tries) {
      Eigen::MatrixXd A = H;
      A.diagonal() += lambda * H.diagonal().cwiseMax(1e-12);
      const Vec step = -A.ldlt().solve(g);
      if (!step.allFinite()) return Refuse(why, "singular fit");
      const Vec q = p + step;
      if (!(q[9] > 0)) {
        lambda *= 10;
        continue;
      }
      Eigen::VectorXd r2;
      const double c2 = Evaluate(w, q, &r2, nullptr);
      if (c2 < cost) {
        converged = (cost - c2) < 1e-10 * cost || step.segment<6>(3).cwiseAbs().maxCoeff() < 1e-6;
        p = q;
        cost = Evaluate(w, p, &r, &J);
        lambda = std::max(lambda / 10, 1e-12);
        break;
      }
      lambda *= 10;
      if (tries == 9) converged = true;  // no further decrease: at the minimum
    }
  }
  if (!converged) return Refuse(why, "the fit did not converge");
  const double separation = std::hypot(p[4] - p[7], p[5] - p[8]);
  const double bg = p[0];
  if (!(p[3] > min_contrast * bg) || !(p[6] > min_contrast * bg)) {
    return Refuse(why, "one of the two is fainter than min_contrast");
  }
  if (separation < 0.5 * diameter_px || separation > 2.5 * diameter_px) {
    return Refuse(why, "the two centres are not 0.5-2.5 diameters apart");
  }
  if (p[9] < 0.1 * diameter_px || p[9] > 0.6 * diameter_px) {
    return Refuse(why, "the fitted width is not blob-sized");
  }
  const auto n = static_cast<double>(w.value.size());
  const double sigma2 = cost / (n - kParams);
  const Eigen::MatrixXd C =
      (J.transpose() * J).inverse() * sigma2 * std::max(1.0, correlation_factor);
  if (!C.allFinite()) return Refuse(why, "singular fit");
  BlobPairFit out;
  out.rms_grey = std::sqrt(cost / n);
  out.iterations = it;
  for (int k = 0; k < 2; ++k) {
    MarkerBlob& b = out.blobs[k];
    b.uv_px = w.origin + cv::Point2d(p[4 + 3 * k], p[5 + 3 * k]);
    b.covariance_px2 = cv::Matx22d(C(4 + 3 * k, 4 + 3 * k),
                                   C(4 + 3 * k, 5 + 3 * k),
                                   C(5 + 3 * k, 4 + 3 * k),
                                   C(5 + 3 * k, 5 + 3 * k));
    b.diameter_px = 2.355 * p[9];
    b.contrast = p[3 + 3 * k] / bg;
  }
  return out;
}

}  // namespace carmba
