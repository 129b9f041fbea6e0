#!/usr/bin/env bash
# The ctest fixture cli_scenes (tests/CMakeLists.txt): `carmba simulate` of the shipped scenes that
# many CLI tests read, once per ctest run, before them. Each test binary used to render them again
# in every test process (gtest_discover_tests runs one test per process). The tests find the
# directory through CARMBA_TEST_SCENES and only read it (tests/cli/cli_test_util.h
# SimulatedScene); run on their own, without ctest, they render the scenes themselves.
# Usage: simulate_scenes.sh CARMBA_BIN SOURCE_DIR OUT_DIR SCENE...
set -euo pipefail
bin=$1 src=$2 out=$3
shift 3
mkdir -p "$out"
for scene in "$@"; do
  # simulate writes into a temporary directory and renames it, so a scene is whole or absent.
  "$bin" simulate --scene "$src/configs/scenes/$scene.yaml" --out "$out/$scene" --force >/dev/null
done
