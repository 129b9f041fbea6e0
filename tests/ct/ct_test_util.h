// Helpers shared by the CT tests: scratch directories and small scene files.
#pragma once

#include <fstream>
#include <string>

#include "scratch.h"

namespace carmba::testing {

using test::ScratchDir;  // tests/scratch.h

inline void WriteText(const std::string& path, const std::string& text) {
  std::ofstream f(path);
  f << text;
}

}  // namespace carmba::testing
