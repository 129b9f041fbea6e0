// A vector of random draws in a fixed order.
//
// C++ leaves unspecified the order in which a call's arguments are evaluated, so
// Eigen::Vector2d(g(rng), g(rng)) draws (y, x) under GCC and (x, y) under Clang: a simulated scene
// then depends on the compiler that built carmba. Every vector of draws goes through here (or
// through named locals, one draw per statement). The order is GCC's, last component first: every
// result shipped so far was drawn in it, and keeping it keeps them.
#pragma once

#include <Eigen/Core>

namespace carmba {

// N draws of `dist` from `rng`, component N-1 drawn first and component 0 last.
template <int N, typename Dist, typename Engine>
Eigen::Matrix<double, N, 1> RandomVector(Dist& dist, Engine& rng) {
  Eigen::Matrix<double, N, 1> v;
  for (int i = N - 1; i >= 0; --i) v[i] = dist(rng);
  return v;
}

}  // namespace carmba
