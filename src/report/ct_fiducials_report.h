// The outputs of `carmba ct-fiducials` (ct/ct_fiducials.h) above the CT layer: the report
// (<stem>.md and <stem>.html, report/report_doc.h) with its plot (the markers with their
// covariance ellipsoids, report/plots.h), and the writer of the whole output set.
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "ct/ct_fiducials.h"
#include "report/plots.h"
#include "report/report_doc.h"
#include "util/status.h"

namespace carmba {

// The report as a document, naming the CSV file `csv_name`, and the data of its plot.
ReportDoc FiducialsReportDoc(const CtFiducialsResult& result, const std::string& csv_name);
nlohmann::json FiducialsPlotData(const CtFiducialsResult& result);

// Writes the CSV (FormatFiducialsCsv) to `out_csv`, the report to <stem>.md and <stem>.html and,
// with an object frame, <stem>.object_from_ct.json; each atomically, all only after everything
// is computed. `report_warning` (if given): why <stem>.html has no plot, if it has none. `plots`:
// the plot drawn beforehand from FiducialsPlotData (report/plots.h PlotProcess); null: drawn here.
Status WriteCtFiducials(const CtFiducialsResult& result,
                        const std::string& out_csv,
                        std::string* report_warning = nullptr,
                        const PlotSet* plots = nullptr);

}  // namespace carmba
