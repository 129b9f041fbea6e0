#!/usr/bin/env bash
# Configures and builds carmba (Release) into ${CARMBA_BUILD_DIR:-build}. Used by demo.sh and
# test.sh; assumes the dependencies are installed (scripts/setup.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${CARMBA_BUILD_DIR:-build}
JOBS=${CARMBA_JOBS:-$(nproc)}
cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$BUILD_DIR" -j"$JOBS" "$@"
