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

# The fuzz harnesses (tests/fuzz/README.md): the readers of outside input built with clang,
# ASan + UBSan and libFuzzer's coverage in their own directory (only the sources the harnesses
# link; -O0 without debug information, which compiles fastest: reports name functions, not
# lines), then each harness fuzzes for 5 s from the shipped files. CARMBA_FUZZ=0 skips this.
# The fuzz build runs beside the main build and the suite below, under the idle scheduling class
# (SCHED_IDLE: it gets a core only when nothing else wants it): the main build leaves a core idle
# while a large translation unit or a link holds up the rest, and the suite leaves about a tenth
# of the two cores idle (tests waiting for a Slurm cluster, Chromium or a plot process), which
# the fuzz build fills (src/docs/speed.md, "Test suite time"). Its output goes to a log, printed
# if it fails.
FUZZ=${CARMBA_FUZZ:-1}
if [[ "$FUZZ" == 1 ]]; then
  FUZZ_DIR=${CARMBA_FUZZ_BUILD_DIR:-build-fuzz}
  mkdir -p "$FUZZ_DIR"
  FUZZ_LOG=$FUZZ_DIR/build.log
  # In a process group of its own (job control, set -m), so that one kill stops all of it.
  set -m
  FUZZ_GENERATOR=()  # as scripts/build.sh: Ninja for a new directory when it is installed
  if [[ ! -f "$FUZZ_DIR/CMakeCache.txt" ]] && command -v ninja >/dev/null; then
    FUZZ_GENERATOR=(-G Ninja)
  fi
  (
    start=$SECONDS
    CC=clang CXX=clang++ chrt --idle 0 cmake -S . -B "$FUZZ_DIR" "${FUZZ_GENERATOR[@]}" \
      -DCARMBA_FUZZ=ON -DCMAKE_BUILD_TYPE=Fuzz -DCMAKE_CXX_FLAGS_FUZZ="-O0 -DNDEBUG" \
      -DCMAKE_C_FLAGS_FUZZ="-O0 -DNDEBUG"
    chrt --idle 0 cmake --build "$FUZZ_DIR" -j"${CARMBA_JOBS:-$(nproc)}" --target carmba_fuzz
    echo $((SECONDS - start)) >"$FUZZ_DIR/build.seconds"
  ) >"$FUZZ_LOG" 2>&1 &
  FUZZ_BUILD_PID=$!
  set +m
  # A failing step must not leave the fuzz build running.
  trap 'kill -- -"$FUZZ_BUILD_PID" 2>/dev/null || true; report_times' EXIT
fi

step bash scripts/build.sh
BUILD_DIR=${CARMBA_BUILD_DIR:-build}

# One test more than cores: some tests spend seconds waiting (a Slurm cluster scheduling, Chromium,
# a Python plot process), and the next test fills that core. On 2 cores: -j2 389 s, -j3 341 s,
# -j4 355 s (src/docs/speed.md).
step ctest --test-dir "$BUILD_DIR" --output-on-failure -j"${CARMBA_JOBS:-$(($(nproc) + 1))}" \
  --timeout 900

if [[ "$FUZZ" == 1 ]]; then
  if ! wait "$FUZZ_BUILD_PID"; then
    tail -n 40 "$FUZZ_LOG"
    echo "test.sh: the fuzz build failed (log: $FUZZ_LOG)"
    exit 1
  fi
  record_time "$(cat "$FUZZ_DIR/build.seconds")" \
    "fuzz build, beside the build and the suite ($FUZZ_LOG)"
  trap report_times EXIT
  step ctest --test-dir "$FUZZ_DIR" -L fuzz --output-on-failure -j"${CARMBA_JOBS:-$(nproc)}"
else
  echo "test.sh: fuzz harnesses not run (CARMBA_FUZZ=0)"
fi
