#!/usr/bin/python3
"""Places the 9-marker object and the C-arm isocentre of thesis_pose.yaml so that the simulated
views resemble the thesis's (Table 5.2), and prints the YAML keys to paste.

1. Full-perspective PnP (OpenCV, thesis intrinsics, no distortion) of markers 3, 4, 7, 8 in each
   of the five views (object frame as printed, a proper rotation).
2. The relative rotations cam_a_from_cam_0 turn about the image's -y axis: the thesis's orbital
   rotation is, in carmba's convention, a NEGATIVE (RAO) primary angle.
3. The isocentre c (camera-0 frame) solves p_a = R_a0 (p_0 - c) + c over the views, least squares
   (it is fixed relative to the source), in the plane normal to the rotation axis; along the axis
   it is put level with marker 3. sod = c_z, axis_offset = -(c_x, c_y).
4. world_from_object = inverse(cam_from_world(primary 0)) * cam0_from_object, written as
   object_pose {rotation_deg about the spheres' centroid, center_mm}.
Usage: /usr/bin/python3 scripts/fit_thesis_pose.py  (from the repository root)
"""
import csv
import math

import cv2
import numpy as np

K = np.array([[2061.389, 0, 203.655], [0, 2254.646, 205.117], [0, 0, 1]])
ANGLES = [0, 10, 30, 50, 90]


def main():
    rows = [r for r in csv.reader(l for l in open("data/thesis/projections_table_5_2.csv")
                                  if not l.startswith("#"))]
    head, rows = rows[0], rows[1:]
    obj3 = np.array([[float(r[1]), float(r[2]), float(r[3])] for r in rows])  # origin marker 3
    uv = {a: np.array([[float(r[head.index(f"u_{a}")]), float(r[head.index(f"v_{a}")])]
                       for r in rows]) for a in ANGLES}
    poses = {}
    for a in ANGLES:
        _, r, t = cv2.solvePnP(obj3, uv[a], K, None, flags=cv2.SOLVEPNP_SQPNP)
        _, r, t = cv2.solvePnP(obj3, uv[a], K, None, r, t, True, flags=cv2.SOLVEPNP_ITERATIVE)
        poses[a] = (cv2.Rodrigues(r)[0], t.ravel())
    R0, t0 = poses[0]
    A, b, axes = [], [], []
    for a in ANGLES[1:]:
        Ra, ta = poses[a]
        Rrel = Ra @ R0.T
        rv = cv2.Rodrigues(Rrel)[0].ravel()
        print(f"# {a:3d} deg: relative rotation {np.linalg.norm(rv) * 180 / math.pi:.1f} deg "
              f"about {np.round(rv / np.linalg.norm(rv), 2)} (camera 0)")
        # object points: p_a = Ra x + ta, p_0 = R0 x + t0 -> ta - Rrel t0 = (I - Rrel) c
        axes.append(rv / np.linalg.norm(rv))
        A.append(np.eye(3) - Rrel)
        b.append(ta - Rrel @ t0)
    # The position of c ALONG the rotation axis is not observable: solve in the plane normal to
    # the mean axis and put c level with the object (marker 3) along the axis.
    n = np.mean(axes, axis=0)
    n /= np.linalg.norm(n)
    e1 = np.cross(n, [1.0, 0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    B = np.stack([e1, e2], axis=1)
    ab = np.linalg.lstsq(np.vstack(A) @ B, np.concatenate(b), rcond=None)[0]
    c = B @ ab + n * (n @ t0)
    print(f"# isocentre in camera 0: {np.round(c, 1)}")
    # marker-1 object frame: p_o3 = p_o1 - m3
    m = {}
    for r in csv.DictReader(l for l in open("data/thesis/markers_table_5_1.csv")
                            if not l.startswith("#")):
        m[int(r["marker"])] = np.array([float(r["x_o"]), float(r["y_o"]), float(r["z_o"])])
    t0_obj1 = t0 - R0 @ m[3]  # cam0_from_object1 = cam0_from_object3 * T(-m3)
    # carmba CamFromWorld at primary = secondary = 0, isocentre at the world origin
    R0w = np.array([[-1, 0, 0], [0, 0, -1], [0, -1, 0]], float).T  # world_from_cam columns
    sod = c[2]
    offset = -c[:2]
    source = R0w @ np.array([offset[0], offset[1], -sod])
    Rwo = R0w @ R0
    two = R0w @ t0_obj1 + source
    centroid = np.mean(list(m.values()), axis=0)
    rot_deg = cv2.Rodrigues(Rwo)[0].ravel() * 180 / math.pi
    center = Rwo @ centroid + two
    print(f"carm: {{sid_mm: 1000, sod_mm: {sod:.1f}, "
          f"axis_offset_mm: [{offset[0]:.1f}, {offset[1]:.1f}]}}")
    print(f"object_pose: {{rotation_deg: [{rot_deg[0]:.3f}, {rot_deg[1]:.3f}, {rot_deg[2]:.3f}], "
          f"center_mm: [{center[0]:.2f}, {center[1]:.2f}, {center[2]:.2f}]}}")


if __name__ == "__main__":
    main()
