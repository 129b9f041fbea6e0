#include "export/geometry_export.h"

#include <cctype>
#include <cstdio>

#include "export/plastimatch_geometry.h"
#include "export/rtk_geometry.h"
#include "util/plausible.h"

namespace carmba {
namespace {

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

Status AddRtk(const GeometrySet& set, const std::string& where, GeometryExport* out) {
  RtkDetector det;
  auto ps = RtkFromGeometry(set, out->sdd_mm, &det);
  if (!ps.ok()) return ps.status().WithContext(where + ": RTK");
  out->files.emplace_back("rtk_geometry.xml", RtkGeometryXml(*ps));
  out->files.emplace_back("rtk_detector.json", RtkDetectorJson(det, *ps).dump(2) + "\n");
  out->summary += " RTK (detector pitch " + FormatCompact(det.spacing_u_mm) + " x " +
                  FormatCompact(det.spacing_v_mm) + " mm, fx/fy " +
                  FormatCompact(det.spacing_v_mm / det.spacing_u_mm) + ", rows flipped);";
  return Status::Ok();
}

Status AddPlastimatch(const GeometrySet& set, const std::string& where, GeometryExport* out) {
  auto pms = PlastimatchFromGeometry(set, out->sdd_mm);
  if (!pms.ok()) return pms.status().WithContext(where + ": plastimatch");
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
    out->files.emplace_back("plastimatch/" + stem + ".txt", PlastimatchProjMatText(pm));
    script += "plastimatch drr -t raw -I \"$1\" -O \"$2/" + stem + "_\" " +
              PlastimatchDrrArgs(pm) + "\n";
  }
  out->files.emplace_back("plastimatch/drr.sh", script);
  out->summary += " plastimatch (" + std::to_string(pms->size()) + " projection matrices, drr.sh);";
  return Status::Ok();
}

}  // namespace

StatusOr<GeometryExport> ExportGeometryFiles(const GeometrySet& set,
                                             const std::string& where,
                                             const std::string& format,
                                             double sdd_mm) {
  const bool rtk = format == "rtk" || format == "all";
  const bool plm = format == "plastimatch" || format == "all";
  const bool json = format == "json" || format == "all";
  if (!rtk && !plm && !json) {
    return Status::Error("format: expected rtk, plastimatch, json or all, got '" + format + "'");
  }
  if (sdd_mm != 0 && !InRange(sdd_mm, plausible::kDistanceMm)) {
    return Status::Error("sdd_mm: expected 0 (not given) or " +
                         FormatRange(plausible::kDistanceMm) + ", got " + FormatCompact(sdd_mm));
  }
  if (set.views.empty()) return Status::Error(where + ": no views");
  GeometryExport out;
  out.sdd_mm = sdd_mm != 0 ? sdd_mm : set.views[0].sid_mm.value_or(1000.0);
  if (json) out.files.emplace_back("geometry.json", GeometryToJson(set).dump(2) + "\n");
  if (rtk) CARMBA_RETURN_IF_ERROR(AddRtk(set, where, &out));
  if (plm) CARMBA_RETURN_IF_ERROR(AddPlastimatch(set, where, &out));
  return out;
}

}  // namespace carmba
