// `carmba calibrate` writes camera.cameramodel with mrcal's optimization_inputs (carmba's
// solution, the same observations, serialised by mrcal), so that mrcal's uncertainty tools work on
// it directly: mrcal-show-projection-uncertainty runs, and mrcal.projection_uncertainty at the
// image centre, given carmba's pixel sigma, equals carmba's own projection uncertainty there.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "synthetic/synthetic_views.h"
#include "cli_test_util.h"
#include "detect/observations.h"
#include "util/file_util.h"

namespace carmba::test {
namespace {

namespace fs = std::filesystem;

// Same formula (mrcal's definition: a point at the range along the pixel's ray, fixed in the frame
// averaged over the plate poses), same pixel sigma, same solution: they agree to rounding; 1e-6
// relative leaves room for the Jacobians' different evaluation order.
constexpr double kSameFormulaRelTol = 1e-6;

TEST(CameraModelUncertainty, MrcalToolsWorkOnTheTopLevelModel) {
  ScratchDir dir;
  ASSERT_TRUE(WriteSyntheticGridObservations(dir.File("obs.csv")));
  const auto r = RunCarmba("calibrate --no-opencv --no-plots --observations " +
                           dir.File("obs.csv") + " --out " + dir.File("out"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string model = dir.File("out/camera.cameramodel");
  const auto model_text = ReadFile(model);
  ASSERT_TRUE(model_text.ok());
  EXPECT_NE(model_text->find("'optimization_inputs'"), std::string::npos);
  const auto cam = nlohmann::json::parse(*ReadFile(dir.File("out/camera.json")));
  const double distance = cam["projection_uncertainty"]["distance_mm"].get<double>();
  double carmba_centre = NAN;
  for (const auto& p : cam["projection_uncertainty"]["points"]) {
    if (p["where"] == "centre") carmba_centre = p["worst_px"].get<double>();
  }
  ASSERT_TRUE(carmba_centre > 0);

  // The command-line tool, as a user would run it.
  const std::string png = dir.File("uncertainty.png");
  const std::string tool = "mrcal-show-projection-uncertainty --gridn 8 6 --distance " +
                           std::to_string(distance) + " --hardcopy " + png + " " + model +
                           " >" + dir.File("tool.log") + " 2>&1";
  EXPECT_EQ(std::system(tool.c_str()), 0) << *ReadFile(dir.File("tool.log"));
  EXPECT_TRUE(fs::exists(png) && fs::file_size(png) > 1000);

  // The Python API: the model's intrinsics are carmba's (full precision), and the uncertainty at
  // the centre with carmba's pixel sigma, and with mrcal's own estimate of it.
  dir.Write("check.py", R"(import sys, json, numpy as np, mrcal
m = mrcal.cameramodel(sys.argv[1])
j = json.load(open(sys.argv[2]))
ours = np.array([j['fx'], j['fy'], j['cx'], j['cy']] + j['distortion'])
W, H = m.imagersize()
q = np.array(((W - 1) / 2, (H - 1) / 2))
d = j['projection_uncertainty']['distance_mm']
p = mrcal.unproject(q, *m.intrinsics(), normalize=True) * d
u = lambda **kw: float(mrcal.projection_uncertainty(p, model=m, atinfinity=False,
                                                      what='worstdirection-stdev', **kw))
print(json.dumps({'max_abs_intrinsics_diff': float(np.max(np.abs(m.intrinsics()[1] - ours))),
                  'given_sigma': u(observed_pixel_uncertainty=j['sigma_px']),
                  'mrcal_sigma': u()}))
)");
  const std::string py = "/usr/bin/python3 " + dir.File("check.py") + " " + model + " " +
                         dir.File("out/camera.json") + " >" + dir.File("py.out") + " 2>&1";
  ASSERT_EQ(std::system(py.c_str()), 0) << *ReadFile(dir.File("py.out"));
  const auto m = nlohmann::json::parse(*ReadFile(dir.File("py.out")));
  EXPECT_EQ(m["max_abs_intrinsics_diff"].get<double>(), 0.0);
  const double given = m["given_sigma"].get<double>();
  EXPECT_NEAR(given, carmba_centre, kSameFormulaRelTol * carmba_centre)
      << "carmba " << carmba_centre << " px, mrcal " << given << " px";
  // mrcal's default estimates the pixel sigma itself (from the residuals, without the dof
  // correction): a different sigma, so a different but same-order figure.
  const double own = m["mrcal_sigma"].get<double>();
  EXPECT_GT(own, 0.5 * carmba_centre);
  EXPECT_LT(own, 2.0 * carmba_centre);
  std::cout << "projection uncertainty at the centre at " << distance << " mm: carmba "
            << carmba_centre << " px, mrcal (carmba's sigma " << cam["sigma_px"] << " px) "
            << given << " px, mrcal (its own sigma) " << own << " px\n";
}

// Without the cross-check the model is the plain one (no optimization_inputs), full precision.
TEST(CameraModelUncertainty, WithoutMrcalThePlainModel) {
  ScratchDir dir;
  ASSERT_TRUE(WriteSyntheticGridObservations(dir.File("obs.csv")));
  const auto r = RunCarmba("calibrate --no-mrcal --no-opencv --no-plots --observations " +
                           dir.File("obs.csv") + " --out " + dir.File("out"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto text = ReadFile(dir.File("out/camera.cameramodel"));
  ASSERT_TRUE(text.ok());
  EXPECT_EQ(text->find("optimization_inputs"), std::string::npos);
  EXPECT_NE(text->find("'lensmodel':  'LENSMODEL_OPENCV5'"), std::string::npos);
}

}  // namespace
}  // namespace carmba::test
