// The one reader of pixel-observation CSVs (problem/pixel_csv.h): columns, keys, covariance,
// and one-line errors naming file, line and column.
#include "io/pixel_csv.h"

#include <gtest/gtest.h>

#include "scratch.h"

namespace carmba {
namespace {

class PixelCsv : public ::testing::Test {
 protected:
  std::string Write(const std::string& text) {
    dir_.Write("pixels.csv", text);
    return dir_.File("pixels.csv");
  }
  std::string ErrorOf(const std::string& text, const PixelCsvColumns& c = {}) {
    auto r = ReadPixelCsv(Write(text), c);
    EXPECT_FALSE(r.ok());
    return r.ok() ? "" : r.status().message();
  }
  test::ScratchDir dir_{"pixel_csv"};
};

TEST_F(PixelCsv, MarkersWithAndWithoutCovariance) {
  auto r = ReadPixelCsv(Write("# picks\nview,marker,u_px,v_px\na,3,10.5,20.25\nb,4,1,2\n"));
  ASSERT_TRUE(r.ok()) << r.status().message();
  ASSERT_EQ(r->size(), 2u);
  EXPECT_EQ((*r)[0].view, "a");
  EXPECT_EQ((*r)[0].id, 3);
  EXPECT_EQ((*r)[0].uv_px, Eigen::Vector2d(10.5, 20.25));
  EXPECT_FALSE((*r)[0].HasCovariance());
  EXPECT_NE((*r)[1].where.find("pixels.csv:4"), std::string::npos) << (*r)[1].where;

  auto c =
      ReadPixelCsv(Write("u_px,v_px,cov_vv,view,cov_uv,marker,cov_uu\n1,2,0.09,a,0.01,7,0.04\n"));
  ASSERT_TRUE(c.ok()) << c.status().message();
  Eigen::Matrix2d expected;
  expected << 0.04, 0.01, 0.01, 0.09;
  EXPECT_EQ((*c)[0].covariance_px2, expected);
  EXPECT_EQ((*c)[0].id, 7);
}

TEST_F(PixelCsv, OptionalPointNameAndSigmaColumn) {
  PixelCsvColumns points;
  points.key = "point";
  points.key_required = false;
  points.absent_key = "1";
  points.integer_key = false;
  points.sigma_column = true;
  auto one = ReadPixelCsv(Write("view,u_px,v_px,sigma_px\na,1,2,0.5\n"), points);
  ASSERT_TRUE(one.ok()) << one.status().message();
  EXPECT_EQ((*one)[0].key, "1");
  EXPECT_EQ((*one)[0].covariance_px2, 0.25 * Eigen::Matrix2d::Identity());
  auto named = ReadPixelCsv(Write("view,point,u_px,v_px\na,tip,1,2\n"), points);
  ASSERT_TRUE(named.ok()) << named.status().message();
  EXPECT_EQ((*named)[0].key, "tip");
  EXPECT_FALSE((*named)[0].HasCovariance());
  // Without sigma_column the column is not read.
  auto ignored = ReadPixelCsv(Write("view,marker,u_px,v_px,sigma_px\na,1,1,2,0.5\n"));
  ASSERT_TRUE(ignored.ok());
  EXPECT_FALSE((*ignored)[0].HasCovariance());
}

TEST_F(PixelCsv, ErrorsNameFileLineAndColumn) {
  EXPECT_NE(ErrorOf("view,u_px,v_px\na,1,2\n").find("marker"), std::string::npos);
  EXPECT_NE(ErrorOf("view,marker,u_px,v_px\n,1,1,2\n")
                .find("pixels.csv:2: column 'view': expected a view id"),
            std::string::npos);
  EXPECT_NE(ErrorOf("view,marker,u_px,v_px\na,x,1,2\n").find("pixels.csv:2"), std::string::npos);
  EXPECT_NE(ErrorOf("view,marker,u_px,v_px\na,1,nan,2\n").find("u_px"), std::string::npos);
  // The covariance columns come all three or none.
  EXPECT_NE(ErrorOf("view,marker,u_px,v_px,cov_uu,cov_vv\na,1,1,2,1,1\n").find("cov_uv"),
            std::string::npos);
  EXPECT_NE(ErrorOf("view,marker,u_px,v_px,cov_uu,cov_uv,cov_vv\na,1,1,2,1,2,1\n")
                .find("pixels.csv:2: columns cov_uu, cov_uv, cov_vv: expected a positive definite"),
            std::string::npos);
}

}  // namespace
}  // namespace carmba
