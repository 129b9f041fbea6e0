#include "util/number_format.h"

#include <cmath>
#include <cstdio>

namespace carmba {

std::string Fmt(const char* format, double v) {
  if (!std::isfinite(v)) return "n/a";
  char buf[64];
  std::snprintf(buf, sizeof(buf), format, v);
  return buf;
}

std::string FmtRoundTrip(double v) {
  char buf[40];
  std::snprintf(buf, sizeof(buf), "%.17g", v);
  return buf;
}

std::string FmtTriple(const char* format, double x, double y, double z) {
  return "(" + Fmt(format, x) + ", " + Fmt(format, y) + ", " + Fmt(format, z) + ")";
}

}  // namespace carmba
