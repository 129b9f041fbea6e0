// A small, strict CSV reader for numeric tables.
//
// Format: lines starting with '#' are comments (kept in `comments`), blank lines are skipped, the
// first other line is the header (column names), every following line has exactly as many
// comma-separated fields as the header. Errors name the file, the line number (1-based) and the
// column, and say what was expected.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "util/plausible.h"
#include "util/status.h"

namespace carmba {

struct CsvTable {
  std::string path;                       // for error messages
  std::vector<std::string> comments;      // '#' lines, without the '#'
  std::vector<std::string> header;        // column names
  std::vector<std::vector<std::string>> rows;  // raw fields
  std::vector<int> line_numbers;          // file line of each row

  // Index of a column; error naming the file and the missing column.
  StatusOr<int> Column(const std::string& name) const;
  // The field at (row, column) parsed as a finite double; error names file:line and column.
  StatusOr<double> Number(int row, int col) const;
  StatusOr<double> Number(int row, const std::string& col) const;
  StatusOr<int> Integer(int row, const std::string& col) const;
  // Number() within a plausible range (util/plausible.h); the error names file:line, the column,
  // the range and the value (%g).
  StatusOr<double> NumberIn(int row, const std::string& col, const PlausibleRange& range) const;
};

// Parses CSV text. `path` is used in messages only.
StatusOr<CsvTable> ParseCsv(const std::string& text, const std::string& path);
// Reads and parses a CSV file.
StatusOr<CsvTable> ReadCsv(const std::string& path);
// Parses a string as a finite double, the whole string (surrounding blanks allowed).
bool ParseFiniteDouble(const std::string& s, double* value);

// `s` without leading and trailing spaces, tabs and carriage returns.
std::string TrimSpaces(const std::string& s);

}  // namespace carmba
