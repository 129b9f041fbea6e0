// util/random.h: carmba::Rng draws, through every distribution the simulators use, exactly what
// std::mt19937_64 with the same seed draws through libstdc++'s own generate_canonical.
#include "util/random.h"

#include <gtest/gtest.h>

#include <cstring>
#include <random>

namespace carmba {
namespace {

// Bit equality (a NaN or a signed zero would compare wrongly with ==).
template <typename T>
bool SameBits(T a, T b) {
  return std::memcmp(&a, &b, sizeof(T)) == 0;
}

// n draws of `dist` from std::mt19937_64 and from Rng with one seed, compared bit by bit.
template <typename Dist>
void ExpectSameDraws(const Dist& dist, uint64_t seed, int n) {
  Dist dist_std = dist, dist_rng = dist;
  std::mt19937_64 reference(seed);
  Rng rng(seed);
  for (int i = 0; i < n; ++i) {
    const auto a = dist_std(reference), b = dist_rng(rng);
    ASSERT_TRUE(SameBits(a, b)) << "draw " << i << ": " << a << " against " << b;
  }
  EXPECT_EQ(reference(), rng()) << "the engines stay in step";
}

TEST(Rng, DrawsEqualStdMt19937ThroughEveryDistribution) {
  constexpr int kDraws = 200000;
  ExpectSameDraws(std::normal_distribution<double>(0.0, 1.0), 1, kDraws);
  ExpectSameDraws(std::normal_distribution<float>(0.0f, 30.0f), 2, kDraws);
  ExpectSameDraws(std::uniform_real_distribution<double>(-1, 1), 3, kDraws);
  ExpectSameDraws(std::uniform_real_distribution<float>(0, 1), 4, kDraws);
  for (double mean : {0.5, 3.0, 40.0, 2500.0}) {
    ExpectSameDraws(std::poisson_distribution<long>(mean), 5, kDraws / 10);
  }
}

// The arithmetic against libstdc++'s generic generate_canonical, on chosen draws: the extremes,
// and those whose quotient rounds up to 1 (all 64 bits set in a float or a double), which must
// become the largest value below 1.
struct FixedDraw {
  using result_type = uint64_t;
  static constexpr uint64_t min() { return 0; }
  static constexpr uint64_t max() { return ~uint64_t{0}; }
  uint64_t operator()() { return value; }
  uint64_t value;
};

TEST(Rng, CanonicalArithmeticEqualsLibstdcxxOnEdgeDraws) {
  const uint64_t ones = ~uint64_t{0};
  ASSERT_EQ(static_cast<float>(ones), 18446744073709551616.0f) << "rounds up to 2^64";
  for (uint64_t u : {uint64_t{0}, uint64_t{1}, uint64_t{1} << 63, ones, ones - (uint64_t{1} << 38),
                     ones - (uint64_t{1} << 40), ones - 1024, uint64_t{0x9E3779B97F4A7C15ull}}) {
    FixedDraw d{u};
    const float f = std::generate_canonical<float, 24>(d);
    const double x = std::generate_canonical<double, 53>(d);
    EXPECT_TRUE(SameBits(f, internal::CanonicalFrom64Bits<float>(u))) << u;
    EXPECT_TRUE(SameBits(x, internal::CanonicalFrom64Bits<double>(u))) << u;
    EXPECT_LT(internal::CanonicalFrom64Bits<float>(u), 1.0f) << u;
    EXPECT_LT(internal::CanonicalFrom64Bits<double>(u), 1.0) << u;
  }
}

}  // namespace
}  // namespace carmba
