// `carmba export-geometry`: the solved per-view geometry (geometry.json, written by `carmba
// solve`) for other tools: RTK's ThreeDCircularGeometry XML (export/rtk_geometry.h) and
// plastimatch's projection-matrix files with `plastimatch drr` commands
// (export/plastimatch_geometry.h). Every output is written or none.
#include <gflags/gflags.h>

#include <cstdio>
#include <iostream>

#include "cli/command.h"
#include "cli/common_flags.h"
#include "export/plastimatch_geometry.h"
#include "export/rtk_geometry.h"
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

// File-name-safe view id.
std::string Safe(const std::string& id) {
  std::string s = id;
  for (char& c : s) {
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_' && c != '.') c = '_';
  }
  return s;
}

std::string Index4(size_t k) {
  char b[32];
  std::snprintf(b, sizeof b, "%04zu", k);
  return b;
}

int RunExportGeometry() {
  const char* kCmd = "export-geometry";
  if (FLAGS_result.empty()) return cli::FailUsage(kCmd, "--result (solve output directory) is required");
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
  double sdd = FLAGS_sdd_mm;
  if (sdd == 0) sdd = set->views[0].sid_mm.value_or(1000.0);

  std::vector<std::pair<std::string, std::string>> files;  // name, contents
  std::string summary;
  if (json) {
    files.emplace_back("geometry.json", GeometryToJson(*set).dump(2) + "\n");
  }
  if (rtk) {
    RtkDetector det;
    auto ps = RtkFromGeometry(*set, sdd, &det);
    if (!ps.ok()) return cli::Fail(kCmd, ps.status().WithContext(path + ": RTK"));
    files.emplace_back("rtk_geometry.xml", RtkGeometryXml(*ps));
    files.emplace_back("rtk_detector.json", RtkDetectorJson(det, *ps).dump(2) + "\n");
    summary += " RTK (detector pitch " + FormatCompact(det.spacing_u_mm) + " x " +
               FormatCompact(det.spacing_v_mm) + " mm, fx/fy " +
               FormatCompact(det.spacing_v_mm / det.spacing_u_mm) + ", rows flipped);";
  }
  if (plm) {
    auto pms = PlastimatchFromGeometry(*set, sdd);
    if (!pms.ok()) return cli::Fail(kCmd, pms.status().WithContext(path + ": plastimatch"));
    std::string script =
        "#!/bin/sh\n"
        "# DRRs of a CT with carmba's solved geometry, one per view:  sh drr.sh CT OUTDIR\n"
        "# CT: a volume plastimatch reads (DICOM directory, .mha, .nrrd) in the CT frame of the\n"
        "# fiducials. Writes OUTDIR/NNNN_<view>_0000.raw (float32, H rows of W, row 0 at the\n"
        "# top) and its projection matrix .txt.\n"
        "set -e\nmkdir -p \"$2\"\n";
    for (size_t k = 0; k < pms->size(); ++k) {
      const auto& pm = (*pms)[k];
      const std::string stem = Index4(k) + "_" + Safe(pm.id);
      files.emplace_back("plastimatch/" + stem + ".txt", PlastimatchProjMatText(pm));
      script += "plastimatch drr -t raw -I \"$1\" -O \"$2/" + stem + "_\" " +
                PlastimatchDrrArgs(pm) + "\n";
    }
    files.emplace_back("plastimatch/drr.sh", script);
    summary += " plastimatch (" + std::to_string(pms->size()) + " projection matrices, drr.sh);";
  }
  cli::Step(kCmd, "writing the outputs");
  StagedOutputDir staged(FLAGS_out);
  Status s = staged.Begin();
  if (s.ok() && plm) s = MakeDirs(JoinPath(staged.path(), "plastimatch"));
  for (const auto& [name, text] : files) {
    if (s.ok()) s = WriteFileAtomic(JoinPath(staged.path(), name), text);
  }
  if (s.ok()) s = staged.Commit(/*replace_all=*/false);
  if (!s.ok()) return cli::Fail(kCmd, s);
  std::cout << "exported " << set->views.size() << " views to " << FLAGS_out << ":" << summary
            << " source-detector distance " << FormatCompact(sdd) << " mm" << std::endl;
  return 0;
}

const bool kRegistered [[maybe_unused]] = carmba::cli::RegisterCommand(
    "export-geometry",
    "The solved geometry for other tools: --format rtk (rtk_geometry.xml, RTK "
    "ThreeDCircularGeometry v3, + rtk_detector.json: projection spacing, origin, rows flipped), "
    "plastimatch (plastimatch/NNNN_<view>.txt projection matrices + drr.sh), json "
    "(geometry.json) or all; from --result DIR (a solve's geometry.json).",
    __FILE__,
    RunExportGeometry);
const bool kFlags [[maybe_unused]] = carmba::cli::RegisterCommandFlags("export-geometry", "out,force");

}  // namespace
