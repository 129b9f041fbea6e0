// Regression tests for what the fuzz harnesses (tests/fuzz/) found in the core readers: each input
// used to crash (uncaught exception, sanitizer report); now it is an error Status naming the file.
#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>
#include <string>
#include <vector>

#include "camera/camera.h"
#include "detect/observations.h"
#include "problem/problem.h"
#include "scratch.h"
#include "util/file_util.h"
#include "util/yaml_reader.h"

namespace carmba {
namespace {

class FuzzRegression : public ::testing::Test {
 protected:
  std::string Write(const std::string& name, const std::string& text) {
    const std::string path = dir_ + "/" + name;
    std::ofstream(path, std::ios::binary) << text;
    return path;
  }
  const test::ScratchDir scratch_{"fuzz_regression"};
  const std::string dir_ = scratch_.path();
};

// fuzz_problem: a chessboard of 2 x 9 inner corners passed the grid's range check (2 .. 1000) and
// reached OpenCV's findChessboardCorners, which throws below 3 x 3 (std::terminate).
TEST_F(FuzzRegression, ChessboardWithTwoRowsIsAnErrorNamingTheKey) {
  const std::string path = Write("problem.yaml",
                                 "name: x\n"
                                 "plate_views:\n"
                                 "  images: nowhere/left[01][0-9].jpg\n"
                                 "  pattern: chessboard\n"
                                 "  rows: 2\n"
                                 "  cols: 9\n"
                                 "  spacing_mm: 25\n");
  auto p = LoadProblem(path, ProblemReadOptions());
  ASSERT_FALSE(p.ok());
  EXPECT_NE(p.status().message().find(path + ":5: key 'plate_views.rows': grid: a chessboard "
                                             "needs at least 3 x 3 inner corners (rows 2, cols 9)"),
            std::string::npos)
      << p.status().message();
  GridSpec circles;
  circles.pattern = GridPattern::kCircles;
  circles.rows = 2;
  circles.cols = 9;
  std::string err;
  EXPECT_TRUE(circles.Check(&err)) << err;  // a circle grid of two rows is still fine
}

// fuzz_camera_json: a number beyond a double is not a parse_error but nlohmann's out_of_range,
// which ReadCameraJson did not catch (std::terminate).
TEST_F(FuzzRegression, CameraJsonNumberOutOfRangeIsAnError) {
  const std::string path = Write("camera.json", "{\"image_size\": [408, 408], \"fx\": 1E9999}");
  StatusOr<Camera> c = ReadCameraJson(path);
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.status().message().find(path + ": invalid JSON"), std::string::npos)
      << c.status().message();
}

// fuzz_ct_scene: a complex key (`? [a, b]`) made YamlMap::Finish() call as<std::string>() on a
// sequence, which throws YAML::TypedBadConversion (std::terminate in every YAML reader).
TEST_F(FuzzRegression, YamlComplexKeyIsAnErrorNamingItsLine) {
  for (const char* key : {"? [a, b]\n: 2\n", "? {a: 1}\n: 2\n"}) {
    const std::string path = Write("complex_key.yaml", std::string("name: x\n") + key);
    YamlMap m = YamlMap::Load(path);
    ASSERT_TRUE(m.status().ok()) << m.status().message();
    std::string name;
    m.Get("name", &name);
    const Status s = m.Finish();
    ASSERT_FALSE(s.ok()) << key;
    EXPECT_NE(s.message().find(path + ":2: top level: expected keys that are names"),
              std::string::npos)
        << s.message();
  }
}

// fuzz_xray_scene (UBSan): an integer list with an element beyond an int (4.1e98) was converted
// with static_cast<int> (undefined behaviour); the scalar integer getter already refused it.
TEST_F(FuzzRegression, YamlIntegerListElementBeyondAnIntIsAnError) {
  for (const char* value : {"[1, 4.1e98]", "[-3e9]"}) {
    const std::string path = Write("ints.yaml", std::string("size: ") + value + "\n");
    YamlMap m = YamlMap::Load(path);
    ASSERT_TRUE(m.status().ok()) << m.status().message();
    std::vector<int> size;
    m.Get("size", &size);
    const Status s = m.Finish();
    ASSERT_FALSE(s.ok()) << value;
    EXPECT_NE(s.message().find("size"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("expected an integer within +-2e9"), std::string::npos)
        << s.message();
  }
}

}  // namespace
}  // namespace carmba
