#!/usr/bin/env bash
# Installs the dependencies (skipping what is present), builds everything and runs all tests with
# ctest. This is the README's test command and what CI runs (.ci/run).
set -euo pipefail
cd "$(dirname "$0")/.."
# Chromium renders the study report in one test; without it that test skips.
CARMBA_WITH_BROWSER=${CARMBA_WITH_BROWSER:-1} bash scripts/setup.sh
bash scripts/build.sh
BUILD_DIR=${CARMBA_BUILD_DIR:-build}
# The fuzz harnesses (tests/fuzz/): the libraries with ASan + UBSan and libFuzzer's coverage,
# built with clang in their own directory (only the libraries and the harnesses, not the test
# suite), then each harness fuzzes for 20 s from the shipped files. Opt-in (CARMBA_FUZZ=1; it
# installs clang): the sanitizer build alone took 530 s cold on 2 cores, which would take the
# suite well past 15 minutes.
if [[ "${CARMBA_FUZZ:-0}" == 1 ]]; then
  CARMBA_WITH_FUZZ=1 bash scripts/setup.sh
  FUZZ_DIR=${CARMBA_FUZZ_BUILD_DIR:-build-fuzz}
  CC=clang CXX=clang++ cmake -S . -B "$FUZZ_DIR" -DCARMBA_FUZZ=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    >/dev/null
  cmake --build "$FUZZ_DIR" -j"${CARMBA_JOBS:-$(nproc)}" --target carmba_fuzz
  ctest --test-dir "$FUZZ_DIR" -L fuzz --output-on-failure -j"${CARMBA_JOBS:-$(nproc)}"
else
  echo "test.sh: fuzz harnesses not run (CARMBA_FUZZ=1 runs them, 20 s each: tests/fuzz/README.md)"
fi
ctest --test-dir "$BUILD_DIR" --output-on-failure -j"${CARMBA_JOBS:-$(nproc)}" --timeout 900
