#!/usr/bin/env bash
# The main job: installs the dependencies (skipping what is present), builds carmba, and runs it
# on the shipped data: the thesis's pose experiment reproduced and improved (legacy POSIT vs
# POSIT + bundle adjustment with covariance), written to out/thesis_pose/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh --target carmba
BIN=${CARMBA_BUILD_DIR:-build}/bin/carmba
OUT=${CARMBA_OUT:-out}
mkdir -p "$OUT"

echo "== Thesis pose experiment (Tables 5.2-5.6): legacy POSIT vs bundle adjustment"
"$BIN" solve --problem=problems/thesis_pose.yaml --config=configs/posit_ba_analytic.yaml \
  --out="$OUT/thesis_pose"
cat "$OUT/thesis_pose/report.md"
echo
echo "Outputs: $OUT/thesis_pose/result.json and $OUT/thesis_pose/report.md"
