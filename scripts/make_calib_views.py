#!/usr/bin/python3
"""Draws the view lists of the shipped calibration scenes (seeded, so re-running reproduces them).

Each view: C-arm primary/secondary angles and in-plane detector rotation, and the plate lying on
the table (plate normal along the patient's A-P axis) turned about that normal and moved a little.
Usage: /usr/bin/python3 scripts/make_calib_views.py NAME_PREFIX COUNT SEED MAX_PRIMARY MAX_SECONDARY MAX_SHIFT_MM
"""
import math
import random
import sys

import cv2
import numpy as np


def rot(axis, deg):
    r = np.zeros(3)
    r[axis] = math.radians(deg)
    return cv2.Rodrigues(r)[0]


def main():
    prefix, count, seed = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    max_p, max_s, max_shift = float(sys.argv[4]), float(sys.argv[5]), float(sys.argv[6])
    rng = random.Random(seed)
    for i in range(count):
        p = round(rng.uniform(-max_p, max_p), 1)
        s = round(rng.uniform(-max_s, max_s), 1)
        d = round(rng.uniform(-20, 20), 1)
        turn = rng.uniform(-45, 45)
        # plate lying on the table: plate y -> patient superior (rotate +90 about x), then turned
        # about the table normal (patient y)
        R = rot(1, turn) @ rot(0, 90)
        rv = [round(float(x) * 180 / math.pi, 3) for x in cv2.Rodrigues(R)[0].ravel()]
        c = [round(rng.uniform(-max_shift, max_shift), 1) for _ in range(3)]
        print(f"  - {{name: {prefix}{i + 1:03d}, primary_deg: {p}, secondary_deg: {s}, "
              f"detector_rotation_deg: {d},\n"
              f"     object_rotation_deg: {rv}, object_center_mm: {c}}}")


if __name__ == "__main__":
    main()
