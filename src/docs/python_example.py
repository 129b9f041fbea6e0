# carmba from Python, notebook style (src/docs/python.md). Run from the top level of the checkout
# after the build (scripts/build.sh):  /usr/bin/python3 src/docs/python_example.py
# tests/python/test_example.py runs it. Each "# %%" is a notebook cell.

# %% The module lands in build/python/ (carmba.cpython-311-x86_64-linux-gnu.so).
import os
import sys

import numpy as np

ROOT = os.environ.get("CARMBA_SOURCE_DIR", ".")
sys.path.insert(0, os.environ.get("CARMBA_PYTHON_DIR", os.path.join(ROOT, "build", "python")))
import carmba  # noqa: E402

np.set_printoptions(precision=4, suppress=True)

# %% The thesis's pose experiment: the same solve as `carmba solve` (scripts/demo.sh step 1).
result = carmba.solve(os.path.join(ROOT, "problems/thesis_pose.yaml"),
                      os.path.join(ROOT, "configs/posit_ba_analytic.yaml"))
print(result, result.statistics["rms_px"], "px RMS")

# %% Each view: cam_from_object = [rx ry rz (rad, Rodrigues), tx ty tz (mm)] and its 6 x 6
# covariance in that order (rotation first), parameters of the Rodrigues vector itself.
for v in result.views:
    print(v.id, v.pose, "sigma rot (deg, about the camera axes)", v.sigma_rotation_deg)
v0, v90 = result.views[0], result.views[-1]
print(v0.covariance_6x6)

# %% The cross-covariance of two views' poses (rows: view 0's parameters, columns: view 90's).
C = result.covariance("view " + v0.id, "view " + v90.id)
print(result.block_parameters("view " + v0.id), C.shape)

# %% Relative poses cam_b_from_cam_a with covariance, and the error budget by noise source.
for r in result.relative_poses[:3]:
    print(f"{r['a']} -> {r['b']}: {r['angle_deg']:.3f} +- {r['sigma_angle_deg']:.3f} deg")
row = next(r for r in result.error_budget if r["quantity"].endswith("relative rotation"))
print(row["quantity"], row["sigma"], {k: round(v, 3) for k, v in row["share_by_source"].items() if v})

# %% Projection as mrcal's: points (..., 3) in the camera frame -> pixels (..., 2), with the
# Jacobians d q / d points (..., 2, 3) and d q / d intrinsics (..., 2, 9).
camera = carmba.read_camera(os.path.join(ROOT, "data/thesis/camera.json"))
p_cam = np.array([[0.0, 0.0, 700.0], [20.0, -10.0, 690.0]])
q, dq_dp, dq_dintrinsics = carmba.project(p_cam, camera, get_gradients=True)
print(q, dq_dp.shape, dq_dintrinsics.shape)

# %% A point seen in three views, triangulated in the CT frame with its 3 x 3 covariance.
t = carmba.triangulate(result, {"0": (160.0, 200.0), "30": (190.0, 205.0), "90": (170.0, 210.0)})
print("point", t["p_in_ct_mm"], "mm, sigma", np.sqrt(np.diag(t["covariance_mm2"])), "mm")

# %% Errors are carmba.Error with carmba's one-line message.
try:
    carmba.solve(os.path.join(ROOT, "problems/no_such.yaml"),
                 os.path.join(ROOT, "configs/posit_ba_analytic.yaml"))
except carmba.Error as e:
    print("carmba.Error:", e)

# %% The geometry as `carmba export-geometry` writes it. This problem's CT frame is mirrored
# (handedness: mirrored), which RTK's and plastimatch's geometries cannot carry: geometry.json
# only (a joint problem exports all formats).
files = carmba.export_geometry(result, format="json")
print(sorted(files))
