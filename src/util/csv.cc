#include "util/csv.h"

#include <cctype>

#include <cmath>
#include <cstdlib>
#include <sstream>

#include "util/accepted_keys.h"
#include "util/file_util.h"

namespace carmba {

std::string TrimSpaces(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r");
  return s.substr(b, e - b + 1);
}

namespace {

std::vector<std::string> SplitFields(const std::string& line) {
  std::vector<std::string> out;
  std::string field;
  std::istringstream ss(line);
  while (std::getline(ss, field, ',')) out.push_back(TrimSpaces(field));
  if (!line.empty() && line.back() == ',') out.push_back("");
  return out;
}

}  // namespace

bool ParseFiniteDouble(const std::string& s, double* value) {
  const std::string t = TrimSpaces(s);
  if (t.empty()) return false;
  // Decimal notation only: strtod would also take hexadecimal ("0x10" = 16), "inf" and "nan".
  for (char c : t) {
    if (!std::isdigit(static_cast<unsigned char>(c)) && c != '+' && c != '-' && c != '.' &&
        c != 'e' && c != 'E') {
      return false;
    }
  }
  char* end = nullptr;
  const double v = std::strtod(t.c_str(), &end);
  if (end != t.c_str() + t.size() || !std::isfinite(v)) return false;
  *value = v;
  return true;
}

StatusOr<int> CsvTable::Column(const std::string& name) const {
  RecordAcceptedKey(path, name);
  for (size_t i = 0; i < header.size(); ++i) {
    if (header[i] == name) return static_cast<int>(i);
  }
  return Status::Error(path + ": missing column '" + name + "' in the header");
}

StatusOr<double> CsvTable::Number(int row, int col) const {
  double v = 0;
  const std::string& f = rows[row][col];
  if (!ParseFiniteDouble(f, &v)) {
    return Status::Error(path + ":" + std::to_string(line_numbers[row]) + ": column '" +
                         header[col] + "': expected a finite number, got '" + f + "'");
  }
  return v;
}

StatusOr<double> CsvTable::Number(int row, const std::string& col) const {
  auto c = Column(col);
  if (!c.ok()) return c.status();
  return Number(row, *c);
}

StatusOr<double> CsvTable::NumberIn(int row,
                                    const std::string& col,
                                    const PlausibleRange& range) const {
  auto v = Number(row, col);
  if (!v.ok()) return v.status();
  if (!InRange(*v, range)) {
    return Status::Error(path + ":" + std::to_string(line_numbers[row]) + ": column '" + col +
                         "': expected " + FormatRange(range) + ", got " + FormatCompact(*v));
  }
  return v;
}

StatusOr<int> CsvTable::Integer(int row, const std::string& col) const {
  auto v = Number(row, col);
  if (!v.ok()) return v.status();
  if (*v != std::floor(*v) || std::fabs(*v) > 1e9) {
    return Status::Error(path + ":" + std::to_string(line_numbers[row]) + ": column '" + col +
                         "': expected an integer, got '" + rows[row][*Column(col)] + "'");
  }
  return static_cast<int>(*v);
}

StatusOr<CsvTable> ParseCsv(const std::string& text, const std::string& path) {
  CsvTable t;
  t.path = path;
  // A UTF-8 byte-order mark (spreadsheet exports) is not part of the first field.
  const bool bom = text.size() >= 3 && text.compare(0, 3, "\xEF\xBB\xBF") == 0;
  std::istringstream in(bom ? text.substr(3) : text);
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    const std::string s = TrimSpaces(line);
    if (s.empty()) continue;
    if (s[0] == '#') {
      t.comments.push_back(s.substr(1));
      continue;
    }
    auto fields = SplitFields(s);
    if (t.header.empty()) {
      t.header = fields;
      continue;
    }
    if (fields.size() != t.header.size()) {
      return Status::Error(path + ":" + std::to_string(lineno) + ": expected " +
                           std::to_string(t.header.size()) + " comma-separated fields (" +
                           "as in the header), got " + std::to_string(fields.size()));
    }
    t.rows.push_back(std::move(fields));
    t.line_numbers.push_back(lineno);
  }
  if (t.header.empty()) return Status::Error(path + ": empty file, expected a CSV header line");
  return t;
}

StatusOr<CsvTable> ReadCsv(const std::string& path) {
  auto text = ReadFile(path);
  if (!text.ok()) return text.status();
  return ParseCsv(*text, path);
}

}  // namespace carmba
