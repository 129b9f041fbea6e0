// Derived quantities of a solved bundle adjustment and their error budgets (ba/covariance.h):
// the numbers a user reports, each with its sigma and the share of its variance from each noise
// source.
//
// Quantities (value, unit, gradient over the free state):
//   * every free intrinsic of every group (`fx`, `lao30 cx`, ...), px or unitless;
//   * the projection of the image centre's ray: the point p = d * unproject(image centre) (at the
//     solution; the principal point when the image size is unknown) held fixed in the camera frame
//     (d = the mean object distance, or the plate distance without object views), projected with
//     the estimated intrinsics; u and v in px (intrinsics only: how well the camera maps a known
//     ray, the calibration's own uncertainty);
//   * every object view's pose: small rotations about the camera axes (deg; the rvec covariance
//     mapped by the SO(3) left Jacobian, as the pose report does) and the translation (mm);
//   * every validation pair of object views: the relative-rotation angle and the angle between the
//     viewing directions (deg; geometry/rotation.h), gradients by ceres::Jet.
#pragma once

#include <array>
#include <string>
#include <utility>
#include <vector>

#include "ba/bundle_adjuster.h"

namespace carmba {
namespace ba {

// What a derived quantity is, for look-ups by kind rather than by name (mrcal's state-index
// functions are the model): the view, group and component indices are the problem's.
enum class QuantityKind {
  kIntrinsic,             // group, component = intrinsic index (view >= 0: a smooth group's view)
  kCentreProjection,      // group, component 0 = u, 1 = v
  kViewRotation,          // view, component = axis 0..2 (a small rotation about the camera axis)
  kViewTranslation,       // view, component = axis 0..2
  kPairRelativeRotation,  // view, other_view
  kPairViewDirections,    // view, other_view
};

struct QuantityKey {
  QuantityKind kind = QuantityKind::kIntrinsic;
  int group = -1, view = -1, other_view = -1, component = -1;

  static QuantityKey ViewRotation(int view, int axis) {
    return {QuantityKind::kViewRotation, -1, view, -1, axis};
  }
  static QuantityKey ViewTranslation(int view, int axis) {
    return {QuantityKind::kViewTranslation, -1, view, -1, axis};
  }
  static QuantityKey PairRelativeRotation(int a, int b) {
    return {QuantityKind::kPairRelativeRotation, -1, a, b, -1};
  }
  static QuantityKey PairViewDirections(int a, int b) {
    return {QuantityKind::kPairViewDirections, -1, a, b, -1};
  }
  bool operator==(const QuantityKey& o) const {
    return kind == o.kind && group == o.group && view == o.view && other_view == o.other_view &&
           component == o.component;
  }
};

struct Quantity {
  std::string name;   // e.g. "fx", "view +030 rot x", "pair +000/+030 relative rotation"
  std::string unit;   // "px", "deg", "mm", ""
  double value = 0;
  QuantityKey key;
};

struct QuantitySet {
  std::vector<Quantity> quantities;
  Eigen::MatrixXd G;   // q x num_free (derivatives in the quantities' units)
  Eigen::MatrixXd Gc;  // q x num_consider: direct derivatives over the considered (held)
                       // intrinsics (ba/covariance.h), e.g. a held group's centre projection
};

// Adds the gradient `g` of a quantity over block b's ambient parameters (b.size values) to row
// `row` of G (q x num_free), through the block's basis (held parameters drop out, tied ones add
// to the parameter they follow). Constant blocks add nothing.
void AddGradientRow(const StateLayout& layout, int b, const double* g, int row, Eigen::MatrixXd* G);
// The same over block b's considered parameters into row `row` of Gc (q x num_consider).
void AddConsiderGradientRow(const StateLayout& layout,
                            int b,
                            const double* g,
                            int row,
                            Eigen::MatrixXd* Gc);

// `pairs` are view indices (problem order) of object views.
QuantitySet DerivedQuantities(const BaProblem& problem,
                              const BaResult& result,
                              const std::vector<std::pair<int, int>>& pairs);

struct BudgetRow {
  Quantity quantity;
  double sigma = 0;                                  // sqrt(total variance)
  std::array<double, kNumSources> source_sigma{};    // sqrt(variance of each source)
  std::array<double, kNumSources> share{};           // variance share, adds up to 1
};

// The error budget of the derived quantities (the residual sources scaled by the result's
// covariance_scale; the considered calibration's share, kCalibration, not).
std::vector<BudgetRow> ComputeErrorBudget(const BaProblem& problem,
                                          const BaResult& result,
                                          const std::vector<std::pair<int, int>>& pairs);
// The row of `budget` with `key`; null when there is none.
const BudgetRow* FindBudgetRow(const std::vector<BudgetRow>& budget, const QuantityKey& key);
// The sources that contribute to some row of `budget` (in Source order): the columns a report
// shows (a pose problem has no plate pixels, a joint problem no considered calibration).
std::vector<Source> ActiveSources(const std::vector<BudgetRow>& budget);

}  // namespace ba
}  // namespace carmba
