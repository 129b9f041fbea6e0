// Test knobs read from the environment: seeds, counts and sizes for by-hand runs of the
// randomised tests (the defaults are what CI runs).
#pragma once

#include <cstdlib>
#include <type_traits>

namespace carmba {
namespace testing {

// The environment variable `name` as a T (an integer or floating-point type), or `fallback` when
// it is unset or empty.
template <typename T>
T EnvOr(const char* name, T fallback) {
  const char* v = std::getenv(name);
  if (v == nullptr || *v == '\0') return fallback;
  if constexpr (std::is_floating_point_v<T>) {
    return static_cast<T>(std::atof(v));
  } else {
    return static_cast<T>(std::atoll(v));
  }
}

}  // namespace testing
}  // namespace carmba
