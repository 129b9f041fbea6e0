// Figures of src/docs/results.md measured by a test: scripts/results.py measure runs the test
// with --gtest_output=xml and takes each figure from the test's properties, so that the number
// in the document is the one the test computed (and asserted on).
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <string>

namespace carmba {
namespace testing {

// The figure `key` (the template's {{section.name}}), printf-formatted as the document states it.
template <typename... Args>
void RecordFigure(const std::string& key, const char* format, Args... args) {
  char text[256];
  std::snprintf(text, sizeof text, format, args...);
  ::testing::Test::RecordProperty("figure." + key, text);
}

// `x` in scientific notation with one decimal and no exponent padding (2.3e-3, 1.2e5), as
// scripts/results.py's sci() writes it.
inline std::string Sci(double x) {
  char text[32];
  std::snprintf(text, sizeof text, "%.1e", x);
  const std::string s = text;
  const size_t e = s.find('e');
  std::string exponent = s.substr(e + 2);
  exponent.erase(0, std::min(exponent.find_first_not_of('0'), exponent.size() - 1));
  return s.substr(0, e) + "e" + (s[e + 1] == '-' ? "-" : "") + exponent;
}

// A figure given as text of any length (a list the script parses).
inline void RecordFigureText(const std::string& key, const std::string& text) {
  ::testing::Test::RecordProperty("figure." + key, text);
}

}  // namespace testing
}  // namespace carmba
