#!/usr/bin/env bash
# Configures and builds carmba (Release) into ${CARMBA_BUILD_DIR:-build}. Used by demo.sh and
# test.sh; assumes the dependencies are installed (scripts/setup.sh).
#   build.sh [BUILD_ARGS...] [-- CONFIGURE_ARGS...]
# BUILD_ARGS go to `cmake --build` (e.g. --target carmba), CONFIGURE_ARGS to the configure step
# after -DCMAKE_BUILD_TYPE=Release, which they may override (test.sh's fuzz build does).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${CARMBA_BUILD_DIR:-build}
BUILD_ARGS=()
while (($#)) && [[ "$1" != -- ]]; do
  BUILD_ARGS+=("$1")
  shift
done
(($#)) && shift  # the --
JOBS=${CARMBA_JOBS:-$(nproc)}
# The compiler of a new build directory: Clang when it is installed (scripts/setup.sh installs it
# for the fuzz harnesses), GCC otherwise. Clang 14 builds carmba in less time than GCC 12, and the
# two give the same results to the last bit (src/docs/speed.md, "Build time"). CC and CXX set in
# the environment win; an existing build directory keeps the compiler it was configured with.
if [[ ! -f "$BUILD_DIR/CMakeCache.txt" && -z "${CXX:-}" ]] && command -v clang >/dev/null &&
  command -v clang++ >/dev/null; then
  export CC=clang CXX=clang++
fi
# A new build directory is generated for Ninja when it is installed (scripts/setup.sh installs
# it): Ninja compiles a target's sources while the libraries it links are still being built, where
# Make's per-target steps leave a core idle behind each large object; a cold `all` took 252 s
# instead of 295 s (src/docs/speed.md, "Build time"). An existing directory keeps its generator.
GENERATOR=()
if [[ ! -f "$BUILD_DIR/CMakeCache.txt" ]] && command -v ninja >/dev/null; then
  GENERATOR=(-G Ninja)
fi
cmake -S . -B "$BUILD_DIR" "${GENERATOR[@]}" -DCMAKE_BUILD_TYPE=Release "$@" >/dev/null
cmake --build "$BUILD_DIR" -j"$JOBS" "${BUILD_ARGS[@]}"
