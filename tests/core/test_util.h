// Shared helpers for the core tests.
#pragma once

#include <string>

#include "util/csv.h"

namespace carmba::test {

inline std::string SourcePath(const std::string& rel) {
  return std::string(CARMBA_SOURCE_DIR) + "/" + rel;
}

}  // namespace carmba::test
