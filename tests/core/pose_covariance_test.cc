// PoseCovarianceBySchur on hand-built inputs: the rank test and bad input. (Its agreement with
// ceres::Covariance on solved problems is in pose_solver_test.cc.)
#include "problem/pose_covariance.h"

#include <gtest/gtest.h>

#include <memory>
#include <vector>

#include "ba/reprojection_error.h"

namespace carmba {
namespace {

struct Fixture {
  double intrinsics[9] = {2000, 2000, 200, 200, 0, 0, 0, 0, 0};
  double pose[6] = {0.1, -0.2, 0.05, 5, -3, 700};
  std::vector<Eigen::Vector3d> points;
  std::vector<std::unique_ptr<ceres::CostFunction>> costs;
  PoseCovarianceInput in;

  // `n` markers on a non-planar pattern, each observed once (exact projection).
  explicit Fixture(int n) {
    for (int k = 0; k < n; ++k) {
      points.emplace_back(20.0 * (k % 3) - 20, 20.0 * ((k / 3) % 3) - 20, 7.0 * (k % 2));
    }
    in.intrinsics = intrinsics;
    in.poses = {pose};
    for (int k = 0; k < n; ++k) {
      double uv[2];
      EXPECT_TRUE(ProjectPoint(intrinsics, pose, points[k].data(), uv));
      costs.emplace_back(ReprojectionError::Create(uv[0], uv[1], 0.5));
      in.markers.push_back(points[k].data());
      in.marker_information.push_back(Eigen::Matrix3d::Identity() / (0.2 * 0.2));
      in.blocks.push_back({costs.back().get(), nullptr, 0, k});
    }
  }
};

TEST(PoseCovariance, NineMarkersGiveAPositiveDefiniteCovariance) {
  Fixture f(9);
  auto cov = PoseCovarianceBySchur(f.in);
  ASSERT_TRUE(cov.ok()) << cov.status().message();
  ASSERT_EQ(cov->rows(), 6);
  Eigen::LLT<Eigen::MatrixXd> llt(*cov);
  EXPECT_EQ(llt.info(), Eigen::Success);
}

// Two observed points cannot fix six pose parameters.
TEST(PoseCovariance, TooFewObservationsAreRankDeficient) {
  Fixture f(2);
  auto cov = PoseCovarianceBySchur(f.in);
  ASSERT_FALSE(cov.ok());
  EXPECT_NE(cov.status().message().find("rank-deficient"), std::string::npos)
      << cov.status().message();
}

TEST(PoseCovariance, BadInputIsAnError) {
  {
    Fixture f(9);
    f.in.marker_information.pop_back();
    EXPECT_FALSE(PoseCovarianceBySchur(f.in).ok());
  }
  {
    Fixture f(9);
    f.in.blocks[0].marker = 9;  // no such marker
    EXPECT_FALSE(PoseCovarianceBySchur(f.in).ok());
  }
  {
    Fixture f(9);
    f.in.marker_information[3].setZero();  // and no observation makes up for it in 3-D
    EXPECT_FALSE(PoseCovarianceBySchur(f.in).ok());
  }
  {
    Fixture f(9);
    f.pose[5] = -700;  // every marker behind the source
    EXPECT_FALSE(PoseCovarianceBySchur(f.in).ok());
  }
}

}  // namespace
}  // namespace carmba
