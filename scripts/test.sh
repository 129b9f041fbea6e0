#!/usr/bin/env bash
# Installs the dependencies (skipping what is present), builds everything and runs all tests with
# ctest. This is the README's test command and what CI runs (.ci/run).
set -euo pipefail
cd "$(dirname "$0")/.."
# Chromium renders the study report in one test; without it that test skips.
CARMBA_WITH_BROWSER=${CARMBA_WITH_BROWSER:-1} bash scripts/setup.sh
bash scripts/build.sh
BUILD_DIR=${CARMBA_BUILD_DIR:-build}
ctest --test-dir "$BUILD_DIR" --output-on-failure -j"${CARMBA_JOBS:-$(nproc)}" --timeout 900
