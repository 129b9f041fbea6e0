// The files `carmba export-geometry` writes from a solved geometry (export/view_geometry.h), as
// (relative name, contents) pairs: geometry.json; RTK's rtk_geometry.xml and rtk_detector.json
// (export/rtk_geometry.h); plastimatch/NNNN_<view>.txt projection matrices and
// plastimatch/drr.sh (export/plastimatch_geometry.h). The CLI writes them all or none; the
// Python module (src/python/) returns them and writes them when asked.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "export/view_geometry.h"
#include "util/status.h"

namespace carmba {

struct GeometryExport {
  std::vector<std::pair<std::string, std::string>> files;  // name relative to the output dir
  double sdd_mm = 0;     // the source-detector distance used
  std::string summary;   // one line per format, for the CLI's message
};

// `format`: rtk | plastimatch | json | all. `sdd_mm` 0: the first view's nominal sid_mm, else
// 1000. `where` (the geometry's file) prefixes the errors. Errors: an unknown format, an
// implausible sdd_mm, a view the RTK or plastimatch geometry cannot express.
StatusOr<GeometryExport> ExportGeometryFiles(const GeometrySet& set,
                                             const std::string& where,
                                             const std::string& format,
                                             double sdd_mm);

}  // namespace carmba
