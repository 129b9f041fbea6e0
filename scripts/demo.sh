#!/usr/bin/env bash
# The main job: installs the dependencies (skipping what is present), builds carmba, and runs it
# on the shipped data, writing everything under out/ (or $CARMBA_OUT):
#   1. the thesis's pose experiment (Tables 5.2-5.6) reproduced and improved: legacy POSIT vs
#      POSIT + bundle adjustment with covariance            -> out/thesis_pose/report.md
#   2. C-arm calibration from simulated X-ray images of the thesis's 5x5 sphere plate, with mrcal
#      and OpenCV cross-checks and the ground truth         -> out/calibration/report.md
#   3. marker centres with covariance from a simulated DICOM CT of the thesis's 9-marker object
#                                                           -> out/ct/fiducials.csv, fiducials.md
#   4. the joint bundle adjustment: plate views, object views and CT fiducials of one simulated
#      C-arm in ONE problem, with the error budget and the two-step comparison
#                                                           -> out/joint/report.md
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh --target carmba
BIN=${CARMBA_BUILD_DIR:-build}/bin/carmba
OUT=${CARMBA_OUT:-out}
rm -rf "$OUT/thesis_pose" "$OUT/sim" "$OUT/calibration" "$OUT/ct" "$OUT/joint"
mkdir -p "$OUT"

echo "== 1. Thesis pose experiment (Tables 5.2-5.6): legacy POSIT vs bundle adjustment"
"$BIN" solve --problem=problems/thesis_pose.yaml --config=configs/posit_ba_analytic.yaml \
  --out="$OUT/thesis_pose"
cat "$OUT/thesis_pose/report.md"

echo
echo "== 2. Calibration from simulated X-ray images of the 5x5 plate (thesis intrinsics)"
"$BIN" simulate --scene=configs/scenes/thesis_calibration.yaml --out="$OUT/sim/calibration"
"$BIN" calibrate --images="$OUT/sim/calibration/*.png" --pattern=circles --rows=5 --cols=5 \
  --spacing-mm=20 --sphere-diameter-mm=3.06 --truth="$OUT/sim/calibration/truth.json" \
  --out="$OUT/calibration"

echo
echo "== 3. CT fiducials from a simulated DICOM series of the 9-marker object"
"$BIN" simulate --scene=configs/scenes/thesis_ct.yaml --out="$OUT/sim/ct"
mkdir -p "$OUT/ct"
"$BIN" ct-fiducials --dicom="$OUT/sim/ct/ct" --model=data/thesis/markers_table_5_1.csv \
  --model-columns=x_o,y_o,z_o --diameter-mm=2 --expected=9 --out="$OUT/ct/fiducials.csv"

echo
echo "== 4. Joint bundle adjustment: calibration + pose + CT fiducials in one problem"
# problems/thesis_joint.yaml reads its data from out/sim/joint (relative to the problem file).
JOINT_SIM=out/sim/joint
rm -rf "$JOINT_SIM"
"$BIN" simulate --scene=configs/scenes/thesis_joint.yaml --out="$JOINT_SIM"
"$BIN" ct-fiducials --dicom="$JOINT_SIM/ct" --model=data/thesis/markers_table_5_1.csv \
  --model-columns=x_o,y_o,z_o --diameter-mm=2 --expected=9 --out="$JOINT_SIM/fiducials.csv"
"$BIN" solve --problem=problems/thesis_joint.yaml --config=configs/joint.yaml \
  --out="$OUT/joint"
sed -n '1,/^## Error budget/p' "$OUT/joint/report.md" | head -n -1
sed -n '/^## Joint against two-step/,$p' "$OUT/joint/report.md"

echo
echo "Reports: $OUT/thesis_pose/report.md, $OUT/calibration/report.md, $OUT/ct/fiducials.md," \
  "$OUT/joint/report.md"
