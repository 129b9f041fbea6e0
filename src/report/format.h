// Number and text formatting shared by every report and result file (markdown, HTML, JSON).
//
// Reports print numbers with an explicit printf format chosen per column (the number of digits
// says how precise the number is); a number that is not finite prints as "n/a" in a report. JSON
// has no NaN or infinity: such a number is written as null.
#pragma once

#include <string>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "util/number_format.h"  // Fmt

namespace carmba {
// Fixed point with `digits` decimals ("%.*f"); "n/a" when not finite.
std::string Fixed(double v, int digits = 4);
// All 17 significant digits ("%.17g"): round-trips a double.
std::string FullPrecision(double v);
// %.6g with "nan" / "inf" / "-inf" spelled out and "-0" as "0" (study tables and CSV, where the
// text must be the same for the same number).
std::string FormatNumber(double v);

// A markdown table cell: '|' escaped, newlines as spaces.
std::string MarkdownCell(const std::string& s);
// HTML text: & < > " escaped.
std::string HtmlEscape(const std::string& s);

// JSON: a number (null when not finite), a vector, a matrix as an array of rows.
nlohmann::json JsonNumber(double v);
nlohmann::json JsonVector(const Eigen::VectorXd& v);
nlohmann::json JsonRows(const Eigen::MatrixXd& m);

}  // namespace carmba
