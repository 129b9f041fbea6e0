#!/usr/bin/env bash
# The ctest fixture cli_scenes (tests/CMakeLists.txt): `carmba simulate` of the shipped scenes that
# many CLI tests read, once per ctest run, before them. Each test binary used to render them again
# in every test process (gtest_discover_tests runs one test per process). The tests find the
# directory through CARMBA_TEST_SCENES and only read it (tests/cli/cli_test_util.h
# SimulatedScene); run on their own, without ctest, they render the scenes themselves.
# A joint scene (NAME_joint) also gets its CT fiducials (fiducials.csv), as its problem file reads
# them (cli_test_util.h SimulateJointScene, tests/python/conftest.py simulate_joint_scene).
# Usage: simulate_scenes.sh CARMBA_BIN SOURCE_DIR OUT_DIR SCENE...
set -euo pipefail
bin=$1 src=$2 out=$3
shift 3
mkdir -p "$out"
for scene in "$@"; do
  # simulate writes into a temporary directory and renames it, so a scene is whole or absent.
  "$bin" simulate --scene "$src/configs/scenes/$scene.yaml" --out "$out/$scene" --force >/dev/null
  # A joint scene's CT fiducials, where problems/$scene.yaml reads them (its header's command).
  if [[ $scene == *_joint ]]; then
    "$bin" ct-fiducials --dicom "$out/$scene/ct" --model "$src/data/thesis/markers_table_5_1.csv" \
      --model_columns x_o,y_o,z_o --no-plots --out "$out/$scene/fiducials.csv" >/dev/null
  fi
done
