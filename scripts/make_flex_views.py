#!/usr/bin/python3
"""Draws the plate views of the flexing C-arm scene (configs/scenes/flex_plate.yaml), seeded.

Plate views at a few C-arm orientations (the orientation groups a calibration of C-arm flex
needs), several per orientation: the plate lies on the table (normal along the patient's A-P
axis), tilted by 12-22 deg about a random horizontal axis and turned about its normal, so that
every orientation group alone determines its intrinsics.
Usage: /usr/bin/python3 scripts/make_flex_views.py SEED VIEWS_PER_ORIENTATION P,S [P,S ...]
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
    seed, per = int(sys.argv[1]), int(sys.argv[2])
    rng = random.Random(seed)
    for o in sys.argv[3:]:
        p, s = (float(x) for x in o.split(","))
        for k in range(per):
            turn = rng.uniform(-45, 45)
            tilt = rng.uniform(12, 22) * rng.choice([-1, 1])
            axis = rng.choice([0, 2])  # patient x (left) or z (superior): horizontal axes
            R = rot(axis, tilt) @ rot(1, turn) @ rot(0, 90)
            rv = [round(float(x) * 180 / math.pi, 3) for x in cv2.Rodrigues(R)[0].ravel()]
            c = [round(rng.uniform(-6, 6), 1) for _ in range(3)]
            name = "plate_p%s_s%s_%d" % (("%+03d" % p).replace("+", "p").replace("-", "m"), ("%+03d" % s).replace("+", "p").replace("-", "m"), k + 1)
            print(f"  - {{name: {name}, primary_deg: {p:g}, secondary_deg: {s:g}, "
                  f"object_rotation_deg: {rv}, object_center_mm: {c}}}")


if __name__ == "__main__":
    main()
