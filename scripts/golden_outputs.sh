#!/usr/bin/env bash
# Runs carmba on every shipped problem and scene and keeps the text outputs, so that a refactoring
# can be checked to change no result: run it before and after, then compare the two directories
# with scripts/compare_outputs.py (numbers to the last printed digit; only timings and the output
# directory's own path are ignored).
#   bash scripts/golden_outputs.sh BIN OUT      e.g. build/bin/carmba /tmp/golden_before
# Takes about 90 s on 2 cores. Plots are skipped (--no-plots): they are drawn from the same numbers.
# So are the cross-checks (--no-mrcal --no-opencv): mrcal.projection_diff samples at random, and
# cv::calibrateCamera's last digits (calib_thesis.yaml: fx 2062.95014293 or 2062.95019092) change
# from run to run of the same binary; they are references, not carmba's results.
set -euo pipefail
BIN=$(realpath "$1")
OUT=$2
cd "$(dirname "$0")/.."
rm -rf "$OUT"
mkdir -p "$OUT"
OUT=$(realpath "$OUT")
SIM="$OUT/sim"
run() { echo "+ carmba $*" >&2; "$BIN" "$@" > /dev/null; }

# 1. Pose problems from the thesis tables, every shipped pose config.
for c in posit_ba_analytic posit_ba_autodiff posit_ba_dense_svd posit_ba_sparse epnp_ba_analytic \
         sqpnp_ba_analytic legacy_posit_only; do
  run solve --problem=problems/thesis_pose.yaml --config="configs/$c.yaml" --out="$OUT/thesis_pose_$c" --no-plots
done

# 2. Calibration from simulated images (every shipped calibration config) and OpenCV's photos.
run simulate --scene=configs/scenes/thesis_calibration.yaml --out="$SIM/calibration"
for c in calib calib_free calib_radial calib_robust calib_thesis; do
  run calibrate --images="$SIM/calibration/*.png" --pattern=circles --rows=5 --cols=5 \
    --spacing-mm=20 --sphere-diameter-mm=3.06 --truth="$SIM/calibration/truth.json" \
    --config="configs/$c.yaml" \
    --out="$OUT/calibration_$c" --no-plots --no-mrcal --no-opencv
done
run simulate --scene=configs/scenes/calib_7x6_pincushion.yaml --out="$SIM/pincushion"
run calibrate --images="$SIM/pincushion/*.png" --pattern=circles --rows=6 --cols=7 --spacing-mm=15 \
  --sphere-diameter-mm=2.5 --truth="$SIM/pincushion/truth.json" --config=configs/calib_free.yaml \
  --out="$OUT/calibration_pincushion_calib_free" --no-plots --no-mrcal --no-opencv
run calibrate --problem=problems/calib_opencv_left.yaml --config=configs/calib_free.yaml --out="$OUT/calibration_opencv_left" --no-plots --no-mrcal --no-opencv

# 3. CT fiducials, and 4. the joint problems (thesis and flexing C-arm) as the problem files read them.
mkdir -p "$OUT/out/sim"
run simulate --scene=configs/scenes/thesis_joint.yaml --out="$OUT/out/sim/joint"
run ct-fiducials --dicom="$OUT/out/sim/joint/ct" --model=data/thesis/markers_table_5_1.csv \
  --model-columns=x_o,y_o,z_o --diameter-mm=2 --expected=9 --out="$OUT/out/sim/joint/fiducials.csv"
run simulate --scene=configs/scenes/flex_joint.yaml --out="$OUT/out/sim/flex"
run ct-fiducials --dicom="$OUT/out/sim/flex/ct" --model=data/thesis/markers_table_5_1.csv \
  --model-columns=x_o,y_o,z_o --diameter-mm=2 --expected=9 --out="$OUT/out/sim/flex/fiducials.csv"
mkdir -p "$OUT/problems"
cp problems/thesis_joint.yaml problems/flex_joint_*.yaml "$OUT/problems/"
for c in joint joint_radial; do
  run solve --problem="$OUT/problems/thesis_joint.yaml" --config="configs/$c.yaml" --out="$OUT/joint_$c" --no-plots
done
for m in shared per_group smooth; do
  run solve --problem="$OUT/problems/flex_joint_$m.yaml" --config=configs/joint_radial.yaml \
    --out="$OUT/flex_$m" --no-plots
done

# The leave-one-marker-out TRE (tre: true) on the pose and the joint problem, and triangulation of
# the joint problem's markers from its object views' pixels.
mkdir -p "$OUT/configs"
for c in posit_ba_analytic joint; do
  { cat "configs/$c.yaml"; echo "tre: true"; } > "$OUT/configs/${c}_tre.yaml"
done
run solve --problem=problems/thesis_pose.yaml --config="$OUT/configs/posit_ba_analytic_tre.yaml" \
  --out="$OUT/thesis_pose_tre" --no-plots
run solve --problem="$OUT/problems/thesis_joint.yaml" --config="$OUT/configs/joint_tre.yaml" \
  --out="$OUT/joint_tre" --no-plots
sed -e 's/^view,marker,/view,point,/' "$OUT/out/sim/joint/object/observations.csv" > "$OUT/points.csv"
run triangulate --problem="$OUT/problems/thesis_joint.yaml" --config=configs/joint.yaml \
  --points="$OUT/points.csv" --out="$OUT/triangulate_joint"

# 5. Pose from images: the clutter scene, its true camera and marker centres (0.1 mm CT sigma).
run simulate --scene=configs/scenes/markers_clutter.yaml --out="$SIM/clutter"
python3 - "$SIM/clutter" <<'EOF'
import json, sys
d = sys.argv[1]
truth = json.load(open(d + "/truth.json"))
json.dump(truth["camera"], open(d + "/camera.json", "w"), indent=2)
with open(d + "/fiducials.csv", "w") as f:
    f.write("id,x_mm,y_mm,z_mm,cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz\n")
    obj = truth["object"]
    for i, c in zip(obj["sphere_ids"], obj["centers_mm"]):
        f.write("%d,%r,%r,%r,0.01,0,0,0.01,0,0.01\n" % (i, c[0], c[1], c[2]))
EOF
run pose --images="$SIM/clutter/*.png" --fiducials="$SIM/clutter/fiducials.csv" \
  --camera="$SIM/clutter/camera.json" --marker-diameter-mm=2 --source-to-object-mm=700 \
  --out="$OUT/pose_clutter" --no-plots

# 6. Bead tracking on the real wrist radiographs, and triangulation on the thesis joint solve.
W=data/real/autoscoper-wrist
run track --cameras="cam01=$W/calibration/xr_calib_wrist_cam01.txt;cam02=$W/calibration/xr_calib_wrist_cam02.txt" \
  --images="cam01=$W/images/cam01;cam02=$W/images/cam02" --marker-diameter-mm=1 --out="$OUT/track_wrist"
rm -rf "$OUT/track_wrist/overlays"

# 7. Metal spheres in a real CT (clipped at the scanner's maximum), at the nominal and at rough
# diameters.
mkdir -p "$OUT/real_ct"
for d in 6 5 7 8; do
  run ct-fiducials --dicom=data/real/ggn-phantom-ct/series --diameter-mm=$d --expected=4 \
    --out="$OUT/real_ct/fiducials_${d}mm.csv" --no-plots
done
find "$OUT" \( -name '*.png' -o -name '*.dcm' -o -name '*.html' \) -delete
echo "golden outputs in $OUT" >&2
