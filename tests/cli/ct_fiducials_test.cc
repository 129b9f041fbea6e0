// End-to-end: `carmba simulate` a thesis_ct series (and its tilted twin), then
// `carmba ct-fiducials` on it; bad inputs one at a time, each with its message and no output.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "ct/ct_fiducials.h"
#include "report_browser.h"
#include "scratch.h"
#include "cli_test_util.h"

namespace carmba {
namespace {

namespace fs = std::filesystem;

struct CmdResult {
  int code = -1;
  std::string out, err;
};

CmdResult RunCarmba(const std::string& args, const std::string& scratch) {
  const std::string out = scratch + "/stdout.txt", err = scratch + "/stderr.txt";
  const std::string cmd = std::string(CARMBA_BIN) + " " + args + " >" + out + " 2>" + err;
  CmdResult r;
  const int status = std::system(cmd.c_str());
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.out = test::ReadTextFile(out);
  r.err = test::ReadTextFile(err);
  return r;
}

class CtFiducialsCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = test::MakeScratchDir("cli_ct");
    // The rendered scenes (read only) at root_/NAME.
    for (const char* name : {"thesis_ct", "thesis_ct_tilted"}) {
      ASSERT_EQ(test::LinkSimulatedScene(name, root_ + "/" + name), "");
    }
  }
  static void TearDownTestSuite() { fs::remove_all(root_); }

  static std::map<int, Eigen::Vector3d> Truth(const std::string& scene) {
    std::ifstream f(root_ + "/" + scene + "/truth.json");
    const nlohmann::json t = nlohmann::json::parse(f);
    std::map<int, Eigen::Vector3d> m;
    for (const auto& p : t["markers"]) {
      m[p["id"].get<int>()] = Eigen::Vector3d(p["x_mm"].get<double>(), p["y_mm"].get<double>(),
                                              p["z_mm"].get<double>());
    }
    return m;
  }

  static std::string root_;
};
std::string CtFiducialsCli::root_;

const std::string kModel =
    std::string(CARMBA_SOURCE_DIR) + "/data/thesis/markers_table_5_1.csv";
// The requirement on the thesis_ct series.
constexpr double kCentreTolMm = 0.1;
// Tilted and untilted centres agree to well within their sampling error (~0.003 mm each).
constexpr double kTiltAgreementMm = 0.02;

TEST_F(CtFiducialsCli, ThesisCtCentresWithinATenthOfAMillimetreTiltedTheSame) {
  std::map<std::string, std::vector<CtFiducialRow>> rows;
  for (const std::string scene : {"thesis_ct", "thesis_ct_tilted"}) {
    const std::string csv = root_ + "/" + scene + ".csv";
    const CmdResult r = RunCarmba("ct-fiducials --dicom " + root_ + "/" + scene + "/ct --model " +
                                kModel + " --model_columns x_o,y_o,z_o --diameter-mm 2 --out " +
                                csv,
                            root_);
    ASSERT_EQ(r.code, 0) << r.err;
    auto f = ReadFiducialsCsv(csv);
    ASSERT_TRUE(f.ok()) << f.status().message();
    ASSERT_EQ(f->size(), 9u);
    const auto truth = Truth(scene);
    for (const auto& m : *f) {
      ASSERT_TRUE(truth.count(m.id));
      EXPECT_LT((m.p_mm - truth.at(m.id)).norm(), kCentreTolMm) << scene << " marker " << m.id;
    }
    rows[scene] = *f;
    const std::string md = test::ReadTextFile(root_ + "/" + scene + ".md");
    EXPECT_NE(md.find("bbox centre"), std::string::npos);
    EXPECT_NE(md.find("rigid fit model <- CT"), std::string::npos);
  }
  // <stem>.html: the same tables and the markers with their covariance ellipsoids, rendered.
  const std::string html = test::ReadTextFile(root_ + "/thesis_ct.html");
  EXPECT_NE(html.find("data-plot=\"markers\""), std::string::npos);
  EXPECT_NE(html.find("<th>bbox centre</th>"), std::string::npos);
  test::ExpectReportRenders(root_ + "/thesis_ct.html", 1);
  for (size_t a = 0; a < 9; ++a) {
    EXPECT_EQ(rows["thesis_ct"][a].id, rows["thesis_ct_tilted"][a].id);
    EXPECT_LT((rows["thesis_ct"][a].p_mm - rows["thesis_ct_tilted"][a].p_mm).norm(),
              kTiltAgreementMm);
  }
}

TEST_F(CtFiducialsCli, ObjectFrames) {
  const std::string csv = root_ + "/model_frame.csv";
  CmdResult r = RunCarmba("ct-fiducials --dicom " + root_ + "/thesis_ct/ct --model " + kModel +
                              " --model_columns x_o,y_o,z_o --frame model --no-plots --out " + csv,
                          root_);
  ASSERT_EQ(r.code, 0) << r.err;
  auto f = ReadFiducialsCsv(csv);
  ASSERT_TRUE(f.ok()) << f.status().message();
  auto model = ReadModelCsv(kModel, {"x_o", "y_o", "z_o"});
  ASSERT_TRUE(model.ok());
  // Table 5.1's object columns are not exactly a rigid motion of its CT columns (printed
  // rounding and a re-measurement): the fit residual is ~0.2 mm, so 0.5 mm per marker.
  constexpr double kModelFrameTolMm = 0.5;
  for (size_t a = 0; a < f->size(); ++a) {
    EXPECT_EQ((*f)[a].id, (*model)[a].id);
    EXPECT_LT(((*f)[a].p_mm - (*model)[a].p_in_object).norm(), kModelFrameTolMm);
  }
  EXPECT_TRUE(fs::exists(root_ + "/model_frame.object_from_ct.json"));

  const std::string csv1 = root_ + "/marker1_frame.csv";
  r = RunCarmba("ct-fiducials --dicom " + root_ + "/thesis_ct/ct --model " + kModel +
                    " --model_columns x_o,y_o,z_o --frame marker:1 --no-plots --out " + csv1,
                root_);
  ASSERT_EQ(r.code, 0) << r.err;
  auto g = ReadFiducialsCsv(csv1);
  ASSERT_TRUE(g.ok());
  EXPECT_EQ((*g)[0].id, 1);
  EXPECT_NEAR((*g)[0].p_mm.norm(), 0, 1e-4);
}

struct BadCase {
  std::string args;      // after "ct-fiducials"
  std::string expected;  // in the one-line error
};

TEST_F(CtFiducialsCli, BadInputsFailWithAMessageAndWriteNothing) {
  const std::string series = root_ + "/thesis_ct/ct";
  fs::create_directories(root_ + "/empty");
  std::ofstream(root_ + "/mirror.csv") << "id,x,y,z\n1,0,0,0\n2,10,0,0\n3,0,20,0\n4,0,0,30\n"
                                          "5,-12,7,0\n6,3,-9,14\n7,8,8,8\n8,-5,2,40\n9,20,1,-3\n";
  const std::vector<BadCase> cases = {
      {"--out OUT", "--dicom is required"},
      {"--dicom " + series, "--out is required"},
      {"--dicom " + root_ + "/missing --out OUT", "not a directory"},
      {"--dicom " + root_ + "/empty --out OUT", "no DICOM image files"},
      {"--dicom " + series + " --expected 8 --out OUT", "found 9 markers"},
      {"--dicom " + series + " --diameter_mm -1 --out OUT", "diameter"},
      {"--dicom " + series + " --threshold_hu 5000 --out OUT", "found 0 markers"},
      {"--dicom " + series + " --frame sideways --out OUT", "frame must be"},
      {"--dicom " + series + " --frame model --out OUT", "needs a model CSV"},
      {"--dicom " + series + " --model " + kModel + " --model_columns a,b,c --out OUT",
       "column 'a'"},
      {"--dicom " + series + " --model " + root_ + "/mirror.csv --out OUT", "no labelling"},
      {"--dicom " + series + " --frame marker:12 --out OUT", "no marker with id 12"},
      {"--dicom " + series + " --out " + root_ + "/mirror.csv/f.csv",
       "is a file, expected a directory"},
      {"--dicom /usr/lib/python3/dist-packages/pydicom/data/test_files/dicomdirtests/77654033/"
       "CT2 --out OUT",
       "gap of 202.500 mm"},
  };
  for (const auto& c : cases) {
    if (c.args.find("pydicom") != std::string::npos &&
        !fs::exists("/usr/lib/python3/dist-packages/pydicom")) {
      continue;
    }
    const std::string out = root_ + "/bad.csv";
    std::string args = c.args;
    const auto pos = args.find("OUT");
    if (pos != std::string::npos) args.replace(pos, 3, out);
    const CmdResult r = RunCarmba("ct-fiducials " + args, root_);
    EXPECT_NE(r.code, 0) << args;
    EXPECT_NE(r.err.find(c.expected), std::string::npos) << args << "\n" << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(fs::exists(out)) << args;
    EXPECT_FALSE(fs::exists(root_ + "/bad.md")) << args;
    EXPECT_FALSE(fs::exists(root_ + "/bad.html")) << args;
  }
}

}  // namespace
}  // namespace carmba
