// Number and text formatting: for the engine's warnings and errors, and for every report and
// result file (markdown, HTML, JSON).
//
// Reports print numbers with an explicit printf format chosen per column (the number of digits
// says how precise the number is); a number that is not finite prints as "n/a" in a report. JSON
// has no NaN or infinity: such a number is written as null.
#pragma once

#include <string>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

namespace carmba {

// printf(`format`, v) for one double; "n/a" when v is not finite.
std::string Fmt(const char* format, double v);

// "%.17g": the shortest printf form that reads back to the same double (geometry and result
// files).
std::string FmtRoundTrip(double v);

// "(x, y, z)" with each number printed by Fmt(`format`, .).
std::string FmtTriple(const char* format, double x, double y, double z);

// Fixed point with `digits` decimals ("%.*f"); "n/a" when not finite.
std::string Fixed(double v, int digits = 4);
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
