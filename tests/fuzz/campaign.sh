#!/usr/bin/env bash
# A long fuzzing campaign: each harness (or those named) in turn, one at a time, at nice 19, with the
# ctest test's corpus and seed directories, for RUNS executions or at most MAX_TIME seconds.
# Usage: bash tests/fuzz/campaign.sh [BUILD_DIR] [NAME...]
#   RUNS=1000000 MAX_TIME=900 bash tests/fuzz/campaign.sh build-fuzz csv camera_json
# Logs and crash artifacts go to BUILD_DIR/campaign/; one summary line per harness on stdout:
#   name executions seconds coverage features result
set -uo pipefail
cd "$(dirname "$0")/../.."
BUILD_DIR=${1:-build-fuzz}
shift || true
RUNS=${RUNS:-1000000}
MAX_TIME=${MAX_TIME:-900}
OUT=$BUILD_DIR/campaign
export LSAN_OPTIONS=suppressions=$PWD/tests/fuzz/lsan.supp
mkdir -p "$OUT"
ctest --test-dir "$BUILD_DIR" -L fuzz -N -V | sed -n 's/^[0-9]*: Test command: //p' | tr -d '"' |
while read -r cmd; do
  exe=${cmd%% *}
  name=$(basename "$exe")
  name=${name#fuzz_}
  if [[ $# -gt 0 ]] && ! printf '%s\n' "$@" | grep -qx "$name"; then continue; fi
  args=${cmd#* }
  # ctest's run time (CARMBA_FUZZ_SECONDS, whatever it is) becomes the campaign's.
  args=$(sed -E "s/-max_total_time=[0-9]+/-max_total_time=$MAX_TIME -runs=$RUNS/" <<<"$args")
  log=$OUT/$name.log
  start=$(date +%s.%N)
  # shellcheck disable=SC2086
  nice -n 19 "$exe" $args -artifact_prefix="$OUT/$name-" >"$log" 2>&1
  rc=$?
  end=$(date +%s.%N)
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  cov=$(grep -oE 'cov: [0-9]+ ft: [0-9]+' "$log" | tail -1)
  result=ok
  [[ $rc -ne 0 ]] && result="FAILED rc=$rc (see $log)"
  printf '%s %s %.0f s %s %s\n' "$name" "${execs:-?}" "$(echo "$end - $start" | bc)" "$cov" "$result"
done
