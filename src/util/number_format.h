// printf of one number, for messages below the reports (the engine's warnings and errors) and for
// the reports themselves (report/format.h includes this).
#pragma once

#include <string>

namespace carmba {

// printf(`format`, v) for one double; "n/a" when v is not finite.
std::string Fmt(const char* format, double v);

}  // namespace carmba
