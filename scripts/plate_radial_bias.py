#!/usr/bin/env python3
"""The calibration plate detector's radial bias against the simulator's truth, and how much of it
the spheres' cone-beam shadows explain.

  python3 scripts/plate_radial_bias.py SCENE_DIR OBSERVATIONS_CSV SPHERE_RADIUS_MM

SCENE_DIR holds `carmba simulate`'s truth.json; OBSERVATIONS_CSV is the observations.csv that
`carmba calibrate` (or `carmba detect`) wrote for those images. Each detected centre is matched to
the nearest true centre of its view (within 2 px). Printed: the mean radial error (from the
principal point) against the projection of the sphere's centre, the mean radial offset of the
shadow's centre predicted at the true camera and pose, and the error left after subtracting it.
The offset is re-implemented here from its closed form (src/ba/shadow_correction.h
SphereShadowOffsetPx: the tangent cone's ellipse, and the lens's curvature and area change over it
to second order), an independent check of the C++ one.
"""
import json, sys, csv, numpy as np
import csv
import json
import sys

import numpy as np


def project(intr, p):
    """OPENCV5 projection of a camera-frame point (src/camera/camera_model.h)."""
    k1, k2, p1, p2, k3 = intr["distortion"]
    x, y = p[0] / p[2], p[1] / p[2]
    r2 = x * x + y * y
    a = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2**3
    xd = x * a + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * a + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.array([intr["fx"] * xd + intr["cx"], intr["fy"] * yd + intr["cy"]])


def lens(intr, x):
    return project(intr, [x[0], x[1], 1.0])


def lens_jacobian(intr, x, h):
    return np.column_stack([(lens(intr, x + h * e) - lens(intr, x - h * e)) / (2 * h)
                            for e in np.eye(2)])


def shadow_offset_px(intr, p_cam, radius):
    """The shadow's centre minus the projection of the sphere's centre (px)."""
    p_cam = np.asarray(p_cam, float)
    p = p_cam[:2] / p_cam[2]
    tan_t = np.linalg.norm(p)
    theta, alpha = np.arctan(tan_t), np.arcsin(radius / np.linalg.norm(p_cam))
    tan2_a, tan2_t = np.tan(alpha) ** 2, tan_t * tan_t
    e = p * (1 + tan2_a * (1 + tan2_t) / (1 - tan2_t * tan2_a))
    a = 0.5 * (np.tan(theta + alpha) - np.tan(theta - alpha))
    ecc = np.sin(theta) / np.cos(alpha)
    b = a * np.sqrt(max(0.0, 1 - ecc * ecc))
    u = p / tan_t if tan_t > 0 else np.array([1.0, 0.0])
    w = np.array([-u[1], u[0]])
    m = 0.25 * (a * a * np.outer(u, u) + b * b * np.outer(w, w))
    h = 1e-3
    curvature, grad_log_det = np.zeros(2), np.zeros(2)
    for k, step in enumerate(h * np.eye(2)):
        jp, jm = lens_jacobian(intr, e + step, h), lens_jacobian(intr, e - step, h)
        dj = (jp - jm) / (2 * h)
        for l in range(2):
            curvature += 0.5 * dj[:, l] * m[l, k]
        grad_log_det[k] = (np.log(abs(np.linalg.det(jp))) - np.log(abs(np.linalg.det(jm)))) / (2 * h)
    return (lens(intr, e) + curvature + lens_jacobian(intr, e, h) @ m @ grad_log_det
            - lens(intr, p))


def main():
    scene_dir, obs_path, radius = sys.argv[1], sys.argv[2], float(sys.argv[3])
    truth = json.load(open(scene_dir + "/truth.json"))
    detected = {}  # image file name -> detected centres
    for row in csv.reader(line for line in open(obs_path) if not line.startswith("#")):
        if row[0] == "view":
            continue
        detected.setdefault(row[1].split("/")[-1], []).append(
            np.array([float(row[3]), float(row[4])]))
    errors, offsets = [], []
    for view in truth["views"]:
        intr = view["intrinsics"]
        centre = np.array([intr["cx"], intr["cy"]])
        found = detected.get(view["file"], [])
        for true_px, p_cam in zip(view["centers_px"], view["centers_in_cam_mm"]):
            true_px = np.array(true_px)
            if not found:
                continue
            q = min(found, key=lambda d: np.linalg.norm(d - true_px))
            r = np.linalg.norm(true_px - centre)
            if np.linalg.norm(q - true_px) > 2 or r < 1:
                continue
            radial = (true_px - centre) / r
            errors.append((q - true_px) @ radial)
            offsets.append(shadow_offset_px(intr, p_cam, radius) @ radial)
    errors, offsets = np.array(errors), np.array(offsets)
    left = errors - offsets
    se = lambda x: x.std() / np.sqrt(len(x))
    print("%d centres: mean radial error %+.4f +- %.4f px; predicted shadow offset %+.4f "
          "(largest %.4f); left after subtracting it %+.4f +- %.4f px"
          % (len(errors), errors.mean(), se(errors), offsets.mean(), np.abs(offsets).max(),
             left.mean(), se(left)))


if __name__ == "__main__":
    main()
