// `carmba export-geometry`: the solved per-view geometry (geometry.json, written by `carmba
// solve`) for other tools: RTK's ThreeDCircularGeometry XML (export/rtk_geometry.h) and
// plastimatch's projection-matrix files with `plastimatch drr` commands
// (export/plastimatch_geometry.h). Every output is written or none.
#include <gflags/gflags.h>

#include <iostream>

#include "cli/command.h"
#include "cli/common_flags.h"
#include "export/geometry_export.h"
#include "export/view_geometry.h"
#include "util/file_util.h"
#include "util/plausible.h"

DEFINE_string(result, "",
              "A solve's output directory (its geometry.json is read) or a geometry.json file.");
DEFINE_string(format, "all", "rtk | plastimatch | json | all.");
DEFINE_double(sdd_mm, 0,
              "Source-to-detector distance (mm) that sets the detector pitch of the RTK and "
              "plastimatch geometries (pitch = sdd / fx; any value gives the same rays). 0: the "
              "views' nominal sid_mm from geometry.json, else 1000.");

namespace {

using namespace carmba;

int RunExportGeometry() {
  const char* kCmd = "export-geometry";
  if (FLAGS_result.empty())
    return cli::FailUsage(kCmd, "--result (solve output directory) is required");
  if (FLAGS_out.empty()) return cli::FailUsage(kCmd, "--out (directory) is required");
  const bool rtk = FLAGS_format == "rtk" || FLAGS_format == "all";
  const bool plm = FLAGS_format == "plastimatch" || FLAGS_format == "all";
  const bool json = FLAGS_format == "json" || FLAGS_format == "all";
  if (!rtk && !plm && !json) {
    return cli::FailUsage(kCmd, "--format: expected rtk, plastimatch, json or all, got '" +
                               FLAGS_format + "'");
  }
  if (FLAGS_sdd_mm != 0 && !InRange(FLAGS_sdd_mm, plausible::kDistanceMm)) {
    return cli::FailUsage(kCmd, "--sdd-mm: expected 0 (not given) or " +
                               FormatRange(plausible::kDistanceMm) + ", got " +
                               FormatCompact(FLAGS_sdd_mm));
  }
  {
    const Status s = cli::CheckOutDir();
    if (!s.ok()) return cli::Fail(kCmd, s);
  }
  const std::string path =
      IsDirectory(FLAGS_result) ? JoinPath(FLAGS_result, "geometry.json") : FLAGS_result;
  cli::Step(kCmd, "reading " + path);
  auto set = ReadGeometryJson(path);
  if (!set.ok()) return cli::Fail(kCmd, set.status());
  cli::Step(kCmd, "converting " + std::to_string(set->views.size()) + " views");
  auto exported = ExportGeometryFiles(*set, path, FLAGS_format, FLAGS_sdd_mm);
  if (!exported.ok()) return cli::Fail(kCmd, exported.status());
  cli::Step(kCmd, "writing the outputs");
  StagedOutputDir staged(FLAGS_out);
  Status s = staged.Begin();
  if (s.ok() && plm) s = MakeDirs(JoinPath(staged.path(), "plastimatch"));
  for (const auto& [name, text] : exported->files) {
    if (s.ok()) s = WriteFileAtomic(JoinPath(staged.path(), name), text);
  }
  if (s.ok()) s = staged.Commit(/*replace_all=*/false);
  if (!s.ok()) return cli::Fail(kCmd, s);
  std::cout << "exported " << set->views.size() << " views to " << FLAGS_out << ":"
            << exported->summary << " source-detector distance "
            << FormatCompact(exported->sdd_mm) << " mm" << std::endl;
  return 0;
}

const bool kExportGeometryRegistered [[maybe_unused]] = carmba::cli::RegisterCommand(
    "export-geometry",
    "The solved geometry for other tools: --format rtk (rtk_geometry.xml, RTK "
    "ThreeDCircularGeometry v3, + rtk_detector.json: projection spacing, origin, rows flipped), "
    "plastimatch (plastimatch/NNNN_<view>.txt projection matrices + drr.sh), json "
    "(geometry.json) or all; from --result DIR (a solve's geometry.json).",
    __FILE__,
    RunExportGeometry);
const bool kExportGeometryFlags [[maybe_unused]] =
    carmba::cli::RegisterCommandFlags("export-geometry", "out,force");

}  // namespace
