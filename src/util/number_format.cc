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

}  // namespace carmba
