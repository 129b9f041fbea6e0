// libFuzzer harness: carmba::ReadMarkersCsv (problem/pose_problem.h): fiducials.csv as carmba ct-fiducials writes it (covariance columns) and the thesis marker tables (isotropic sigma).
#include "fuzz_util.h"
#include "problem/pose_problem.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("markers.csv", data, size);
  (void)carmba::ReadMarkersCsv(path, "id", {"x_mm", "y_mm", "z_mm"}, -1, "fiducials.sigma_mm");
  (void)carmba::ReadMarkersCsv(path, "marker", {"x", "y", "z"}, 0.3, "markers.sigma_mm");
  return 0;
}
