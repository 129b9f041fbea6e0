// carmba's random engine: std::mt19937_64, as its own type.
//
// Every std distribution turns the engine's integers into [0, 1) through std::generate_canonical.
// libstdc++'s computes log(2^64) / log(2) in long double on every draw; GCC folds that at compile
// time, Clang calls logl, which made the simulators about 5x slower under Clang
// (src/docs/speed.md, "Build time"). As a type of carmba's own, Rng may have its own
// generate_canonical: the same arithmetic with that constant written out, so every draw is the
// same, to the bit, as std::mt19937_64's under either compiler (tests/core/random_test.cc).
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <random>

namespace carmba {

class Rng : public std::mt19937_64 {
 public:
  using std::mt19937_64::mt19937_64;
};

namespace internal {

// libstdc++'s generate_canonical of one draw `u` of a full 64-bit engine, for a type of at most
// 64 digits (one draw per value): u / 2^64, and a result that rounds up to 1 becomes the largest
// value below 1.
template <typename Real>
Real CanonicalFrom64Bits(std::uint64_t u) {
  static_assert(std::numeric_limits<Real>::digits <= 64, "one 64-bit draw per value");
  const Real r = static_cast<Real>(u) / static_cast<Real>(18446744073709551616.0L);  // 2^64
  return r >= Real(1) ? std::nextafter(Real(1), Real(0)) : r;
}

static_assert(Rng::min() == 0 && Rng::max() == ~std::uint64_t{0}, "a full 64-bit engine");

}  // namespace internal
}  // namespace carmba

namespace std {

// Specialisations for a program-defined engine type (allowed in C++17, [namespace.std]).
template <>
inline double generate_canonical<double, numeric_limits<double>::digits, carmba::Rng>(
    carmba::Rng& rng) {
  return carmba::internal::CanonicalFrom64Bits<double>(rng());
}

template <>
inline float generate_canonical<float, numeric_limits<float>::digits, carmba::Rng>(
    carmba::Rng& rng) {
  return carmba::internal::CanonicalFrom64Bits<float>(rng());
}

}  // namespace std
