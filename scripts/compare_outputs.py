#!/usr/bin/env python3
"""Compares two directories written by scripts/golden_outputs.sh, file by file and line by line.

Every text file must be the same to the last printed digit. Two things are ignored: timings and
dates (the lines that hold "time_s", "..._seconds", OpenCV's calibration_time, or a figure in s or
ms) and each directory's own path, which is replaced by <OUT> before comparing.
Exit 0 when they agree; otherwise 1, with the first differing lines of each file.
    python3 scripts/compare_outputs.py /tmp/golden_before /tmp/golden_after
"""
import os
import re
import sys

TIMING = re.compile(r'"time_s"|_seconds"|calibration_time|wall|elapsed|\b\d+(\.\d+)? ?(ms|s)\b(?! ?\u03c3)')


def text_lines(path, root):
    with open(path, "rb") as f:
        data = f.read()
    if b"\0" in data:
        return None
    lines = data.decode("utf-8", "replace").replace(root, "<OUT>").splitlines()
    return [line for line in lines if not TIMING.search(line)]


def files(root):
    out = set()
    for d, _, names in os.walk(root):
        for n in names:
            out.add(os.path.relpath(os.path.join(d, n), root))
    return out


def main(a, b):
    a, b = os.path.realpath(a), os.path.realpath(b)
    fa, fb = files(a), files(b)
    bad = 0
    for name in sorted(fa ^ fb):
        print("only in %s: %s" % (a if name in fa else b, name))
        bad += 1
    compared = 0
    for name in sorted(fa & fb):
        la, lb = text_lines(os.path.join(a, name), a), text_lines(os.path.join(b, name), b)
        if la is None or lb is None:
            continue
        compared += 1
        if la == lb:
            continue
        bad += 1
        diffs = [(i, x, y) for i, (x, y) in enumerate(zip(la, lb)) if x != y]
        print("%s: %d vs %d lines, %d differ" % (name, len(la), len(lb), len(diffs)))
        for i, x, y in diffs[:3]:
            print("  line %d\n    - %s\n    + %s" % (i + 1, x[:200], y[:200]))
    print("%d text files compared, %d differ or are missing" % (compared, bad))
    return 1 if bad else 0


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    sys.exit(main(sys.argv[1], sys.argv[2]))
