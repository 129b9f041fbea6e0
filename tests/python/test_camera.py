"""carmba.read_camera, carmba.Camera and carmba.project against camera.json, the command's
solve (its per-view RMS is recomputed with project) and finite differences."""
import csv
import json
import os

import numpy as np
import pytest

from conftest import POSE_PROBLEM, assert_rel, read_json, source

CAMERA = source("data", "thesis", "camera.json")
# A camera with distortion and a covariance, so every intrinsic moves the projection.
DISTORTED = np.array([2061.4, 2254.6, 203.7, 205.1, -0.21, 0.13, 0.004, -0.003, 0.05])
# Central differences with h = 1e-6 relative: truncation ~h^2, rounding ~1e-16/h, so 1e-6
# relative to the Jacobian's largest entry is loose enough for both and far below a wrong entry.
FD_REL = 1e-6


def test_read_camera_matches_the_file(carmba):
    cam = carmba.read_camera(CAMERA)
    j = read_json(CAMERA)
    assert (cam.width, cam.height) == tuple(j["image_size"])
    assert_rel(cam.intrinsics, [j["fx"], j["fy"], j["cx"], j["cy"], *j["distortion"]], what="intrinsics")
    assert cam.covariance is None


def test_read_camera_covariance_round_trip(carmba, tmp_path):
    names = ["fx", "fy", "cx", "cy"]
    cov = np.array([[4.0, 0.5, 0.1, 0.0], [0.5, 5.0, 0.0, 0.2], [0.1, 0.0, 1.0, 0.05],
                    [0.0, 0.2, 0.05, 1.5]])
    j = {"image_size": [408, 408], "fx": 2061.0, "fy": 2254.0, "cx": 204.0, "cy": 205.0,
         "distortion": [0.01, 0, 0, 0, 0], "covariance": {"names": names, "matrix": cov.tolist()}}
    path = tmp_path / "camera.json"
    path.write_text(json.dumps(j))
    cam = carmba.read_camera(str(path))
    assert cam.covariance_names == names
    assert_rel(cam.covariance, cov, what="covariance")
    assert_rel(cam.intrinsics[4], 0.01, what="k1")
    again = json.loads(cam.to_json())
    assert again["covariance"]["names"] == names
    assert_rel(again["covariance"]["matrix"], cov, what="to_json covariance")


def test_read_camera_error_is_carmbas_message(carmba, tmp_path):
    path = tmp_path / "camera.json"
    path.write_text('{"image_size": [408, 408], "fx": -5, "fy": 2254, "cx": 204, "cy": 205,'
                    ' "distortion": [0, 0, 0, 0, 0]}')
    with pytest.raises(carmba.Error) as e:
        carmba.read_camera(str(path))
    msg = str(e.value)
    assert "\n" not in msg
    assert str(path) in msg and "fx" in msg


def observations_of(view):
    """The thesis's measured pixels of one view by marker id."""
    with open(source("data", "thesis", "projections_table_5_2.csv")) as f:
        rows = [r for r in csv.reader(f) if r and not r[0].startswith("#")]
    head = rows[0]
    out = {}
    for r in rows[1:]:
        d = dict(zip(head, r))
        out[int(d["marker"])] = (float(d[f"u_{view}"]), float(d[f"v_{view}"]))
    return out


def rodrigues(r):
    t = np.linalg.norm(r)
    if t == 0:
        return np.eye(3)
    k = r / t
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * K @ K


def test_project_reproduces_the_solves_rms(carmba, pose_cli):
    """Every view's RMS in the command's result.json, recomputed by projecting its refined markers
    through its pose with carmba.project: binds the C++ projection, not a re-implementation."""
    j = read_json(pose_cli / "result.json")
    cam = carmba.read_camera(CAMERA)
    markers = {m["id"]: np.array(m["p_in_object_mm"]) for m in j["markers"]}
    for v in j["views"]:
        R = np.array(v["cam_from_object"]["R"]).reshape(3, 3)
        t = np.array(v["cam_from_object"]["t_mm"])
        obs = observations_of(v["id"])
        ids = sorted(obs)
        p_cam = np.array([R @ markers[i] + t for i in ids])
        q = carmba.project(p_cam, cam)
        r = q - np.array([obs[i] for i in ids])
        rms = np.sqrt(np.mean(r ** 2))
        # Summed in another order than the C++: ~1e-15 apart, not bit-identical.
        assert abs(rms - v["rms_px"]) <= 1e-10 * v["rms_px"], (v["id"], rms, v["rms_px"])


def test_project_broadcasts_like_mrcal(carmba):
    cam = carmba.Camera(DISTORTED, 408, 408)
    pts = np.random.default_rng(1).normal([5, -3, 700], [40, 40, 20], size=(4, 5, 3))
    q = carmba.project(pts, cam)
    assert q.shape == (4, 5, 2)
    one = carmba.project(pts[2, 3], cam)
    assert one.shape == (2,)
    assert_rel(one, q[2, 3], what="single point")
    # intrinsics (3, 1, 9) against points (5, 3): (3, 5, 2), each camera its own.
    intr = np.stack([DISTORTED, DISTORTED * [1.01, 1, 1, 1, 1, 1, 1, 1, 1], DISTORTED * 0.99])
    qb = carmba.project(pts[0], intr[:, None, :])
    assert qb.shape == (3, 5, 2)
    for c in range(3):
        assert_rel(qb[c], carmba.project(pts[0], carmba.Camera(intr[c])), what=f"camera {c}")
    assert not np.allclose(qb[0], qb[1])


def test_project_pinhole_by_hand(carmba):
    cam = carmba.Camera([2000.0, 2100.0, 200.0, 210.0, 0, 0, 0, 0, 0], 408, 408)
    q = carmba.project(np.array([10.0, -20.0, 500.0]), cam)
    assert_rel(q, [2000 * 10 / 500 + 200, 2100 * -20 / 500 + 210], what="pinhole")


def finite_difference(f, x, rel_step=1e-6):
    x = np.asarray(x, dtype=float)
    cols = []
    for i in range(x.size):
        h = rel_step * max(1.0, abs(x[i]))
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        cols.append((f(xp) - f(xm)) / (2 * h))
    return np.stack(cols, axis=-1)


def test_project_gradients_against_finite_differences(carmba):
    pts = np.random.default_rng(2).normal([5, -3, 700], [60, 60, 20], size=(6, 3))
    q, dq_dp, dq_di = carmba.project(pts, carmba.Camera(DISTORTED), get_gradients=True)
    assert dq_dp.shape == (6, 2, 3) and dq_di.shape == (6, 2, 9)
    assert_rel(q, carmba.project(pts, carmba.Camera(DISTORTED)), what="q with gradients")
    for k in range(len(pts)):
        fd_p = finite_difference(lambda p: carmba.project(p, carmba.Camera(DISTORTED)), pts[k])
        fd_i = finite_difference(lambda i: carmba.project(pts[k], carmba.Camera(i)), DISTORTED)
        assert_rel(dq_dp[k], fd_p, FD_REL, what=f"dq/dp point {k}", per_entry=False)
        assert_rel(dq_di[k], fd_i, FD_REL, what=f"dq/dintrinsics point {k}", per_entry=False)


def test_project_errors(carmba):
    cam = carmba.Camera(DISTORTED)
    with pytest.raises(carmba.Error, match=r"points\[1\]: not in front of the source \(z = -5"):
        carmba.project(np.array([[0, 0, 100.0], [0, 0, -5.0]]), cam)
    with pytest.raises(carmba.Error, match=r"points: expected an array of shape \(\.\.\., 3\)"):
        carmba.project(np.zeros((4, 2)), cam)
    with pytest.raises(carmba.Error, match="do not broadcast"):
        carmba.project(np.ones((4, 3)), np.ones((3, 9)))
    with pytest.raises(carmba.Error, match="intrinsics: expected 9 values"):
        carmba.Camera([1.0, 2.0])
