// Fuzz target `markers_csv` (fuzz_main.cc): the marker tables. carmba::ReadMarkersCsv
// (io/object_views.h): fiducials.csv as carmba ct-fiducials writes it (covariance columns) and the
// thesis marker tables (isotropic sigma); carmba::ReadModelCsv (ct/marker_labelling.h): the marker
// model of ct-fiducials --model (coordinate columns found from the header, or named).
#include "ct/marker_labelling.h"
#include "fuzz_target.h"
#include "fuzz_util.h"
#include "io/object_views.h"

namespace {

int FuzzMarkersCsv(const uint8_t* data, size_t size) {
  const std::string path = carmba::fuzz::WriteInput("markers.csv", data, size);
  (void)carmba::ReadMarkersCsv(path, "id", {"x_mm", "y_mm", "z_mm"}, -1, "fiducials.sigma_mm");
  (void)carmba::ReadMarkersCsv(path, "marker", {"x", "y", "z"}, 0.3, "markers.sigma_mm");
  (void)carmba::ReadModelCsv(path, {});
  (void)carmba::ReadModelCsv(path, {"x_ct", "y_ct", "z_ct"});
  return 0;
}

}  // namespace

CARMBA_FUZZ_TARGET(markers_csv, FuzzMarkersCsv, nullptr)
