// printf of one number, for messages below the reports (the engine's warnings and errors) and for
// the reports themselves (report/format.h includes this).
#pragma once

#include <string>

namespace carmba {

// printf(`format`, v) for one double; "n/a" when v is not finite.
std::string Fmt(const char* format, double v);

// "%.17g": the shortest printf form that reads back to the same double (geometry files).
std::string FmtRoundTrip(double v);

// "(x, y, z)" with each number printed by Fmt(`format`, .).
std::string FmtTriple(const char* format, double x, double y, double z);

}  // namespace carmba
