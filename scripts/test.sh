#!/usr/bin/env bash
# Installs the dependencies (skipping what is present), builds everything and runs all tests with
# ctest. This is the README's test command and what CI runs (.ci/run).
set -euo pipefail
cd "$(dirname "$0")/.."
# Each finished step's wall time, printed when the script ends (also when a step fails).
STEP_TIMES=()
record_time() {  # SECONDS_TAKEN WHAT
  STEP_TIMES+=("$(printf '%4d s  %s' "$1" "$2")")
}
step() {
  local start=$SECONDS
  "$@"
  record_time $((SECONDS - start)) "$*"
}
report_times() {
  if ((${#STEP_TIMES[@]})); then printf 'test.sh: %s\n' "${STEP_TIMES[@]}"; fi
  echo "test.sh: ${SECONDS} s in all"
}
trap report_times EXIT
# Chromium renders the study report in one test; without it that test skips.
step env CARMBA_WITH_BROWSER="${CARMBA_WITH_BROWSER:-1}" bash scripts/setup.sh

step bash scripts/build.sh
BUILD_DIR=${CARMBA_BUILD_DIR:-build}

# One test more than cores: some tests spend seconds waiting (a Slurm cluster scheduling, Chromium,
# a Python plot process), and the next test fills that core. On 2 cores: -j2 389 s, -j3 341 s,
# -j4 355 s (src/docs/speed.md).
step ctest --test-dir "$BUILD_DIR" --output-on-failure -j"${CARMBA_JOBS:-$(($(nproc) + 1))}" \
  --timeout 900

# The fuzz harnesses (tests/fuzz/README.md): the readers of outside input built with clang,
# ASan + UBSan and libFuzzer's coverage in their own directory (only the sources the harnesses
# link; -O0 without debug information, which compiles fastest: reports name functions, not
# lines), then each harness fuzzes for about 5 s from the shipped files. CARMBA_FUZZ=0 skips this.
# After the suite, not beside it: on this 2-core machine a fuzz build beside the Ninja build (even
# under SCHED_IDLE) or beside the suite made them slower by about as much as it took alone
# (src/docs/speed.md, "Test suite time"). Its output goes to a log, printed if it fails.
fuzz_build() {  # DIR LOG
  if ! CC=clang CXX=clang++ CARMBA_BUILD_DIR="$1" bash scripts/build.sh --target carmba_fuzz -- \
    -DCARMBA_FUZZ=ON -DCMAKE_BUILD_TYPE=Fuzz -DCMAKE_CXX_FLAGS_FUZZ="-O0 -DNDEBUG" \
    -DCMAKE_C_FLAGS_FUZZ="-O0 -DNDEBUG" >"$2" 2>&1; then
    tail -n 40 "$2"
    echo "test.sh: the fuzz build failed (log: $2)"
    return 1
  fi
}
if [[ "${CARMBA_FUZZ:-1}" == 1 ]]; then
  FUZZ_DIR=${CARMBA_FUZZ_BUILD_DIR:-build-fuzz}
  mkdir -p "$FUZZ_DIR"
  step fuzz_build "$FUZZ_DIR" "$FUZZ_DIR/build.log"
  step ctest --test-dir "$FUZZ_DIR" -L fuzz --output-on-failure -j"${CARMBA_JOBS:-$(nproc)}"
else
  echo "test.sh: fuzz harnesses not run (CARMBA_FUZZ=0)"
fi
