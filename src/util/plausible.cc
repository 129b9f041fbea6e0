#include "util/plausible.h"

#include <cmath>
#include <cstdio>

namespace carmba {

std::string FormatCompact(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%g", v);
  return buf;
}

std::string FormatRange(const PlausibleRange& r) {
  std::string s = FormatCompact(r.lo) + " .. " + FormatCompact(r.hi);
  if (r.unit[0] != '\0') s += std::string(" ") + r.unit;
  return s;
}

bool InRange(double v, const PlausibleRange& r) {
  return std::isfinite(v) && v >= r.lo && v <= r.hi;
}

bool CheckRange(const std::string& name,
                double v,
                const PlausibleRange& range,
                std::string* error) {
  if (InRange(v, range)) return true;
  if (error) *error = name + ": expected " + FormatRange(range) + ", got " + FormatCompact(v);
  return false;
}

bool CheckRange(const std::string& name, int v, const PlausibleRange& range, std::string* error) {
  if (InRange(v, range)) return true;
  if (error) *error = name + ": expected " + FormatRange(range) + ", got " + std::to_string(v);
  return false;
}

}  // namespace carmba
