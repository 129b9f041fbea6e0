#!/usr/bin/env python3
"""Compares two directories written by scripts/golden_outputs.sh, file by file and line by line.

Every text file must be the same to the last printed digit. Two things are ignored: timings and
dates (the lines that hold "time_s", "..._seconds", OpenCV's calibration_time, or a figure in s or
ms) and each directory's own path, which is replaced by <OUT> before comparing.
Exit 0 when they agree; otherwise 1, with the first differing lines of each file.
    python3 scripts/compare_outputs.py /tmp/golden_before /tmp/golden_after
With --rel-tol X, a line whose text is the same and whose numbers differ by at most X relative
(|a - b| <= X max(|a|, |b|)) is counted apart, as agreeing within X, with the largest relative
difference per file: for a change that re-orders floating-point operations on purpose.
    python3 scripts/compare_outputs.py --rel-tol 1e-12 /tmp/golden_before /tmp/golden_after
A .json file whose lines differ is also compared as JSON: when every value of A is in B, equal
(or within --rel-tol), and B only adds keys, it is counted apart with the keys B adds.
--ignore KEY (repeatable) leaves a JSON key out of that comparison, for a change on purpose.
"""
import json
import os
import re
import sys

NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
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


def within(x, y, rel_tol):
    """The largest relative difference of the numbers of two lines that differ only in numbers
    (None when their text differs or a number differs by more than rel_tol)."""
    if NUMBER.sub("#", x) != NUMBER.sub("#", y):
        return None
    worst = 0.0
    for u, v in zip(NUMBER.findall(x), NUMBER.findall(y)):
        u, v = float(u), float(v)
        scale = max(abs(u), abs(v))
        rel = abs(u - v) / scale if scale > 0 else 0.0
        if rel > rel_tol:
            return None
        worst = max(worst, rel)
    return worst


def json_added_keys(pa, pb, root_a, root_b, rel_tol, ignore=()):
    """The keys B adds (paths such as views[].initial) when every value of A is in B and equal
    (numbers within rel_tol when given, timings ignored); None when they differ otherwise."""
    try:
        with open(pa) as fa, open(pb) as fb:
            a = json.loads(fa.read().replace(root_a, "<OUT>"))
            b = json.loads(fb.read().replace(root_b, "<OUT>"))
    except ValueError:
        return None
    added = set()

    def same(x, y, path):
        if isinstance(x, dict):
            if not isinstance(y, dict):
                return False
            added.update(path + "." + k for k in set(y) - set(x))
            return all(k in ignore or (k in y and same(x[k], y[k], path + "." + k)) for k in x)
        if isinstance(x, list):
            return isinstance(y, list) and len(x) == len(y) and all(
                same(u, v, path + "[]") for u, v in zip(x, y))
        if x == y or TIMING.search('"' + path.rsplit(".", 1)[-1] + '"'):
            return True
        if rel_tol is not None and isinstance(x, float) and isinstance(y, (int, float)):
            return abs(x - y) <= rel_tol * max(abs(x), abs(y))
        return False

    return sorted(k.lstrip(".") for k in added) if same(a, b, "") else None


def main(a, b, rel_tol=None, ignore=()):
    a, b = os.path.realpath(a), os.path.realpath(b)
    fa, fb = files(a), files(b)
    bad = 0
    for name in sorted(fa ^ fb):
        print("only in %s: %s" % (a if name in fa else b, name))
        bad += 1
    compared = 0
    close = 0
    for name in sorted(fa & fb):
        la, lb = text_lines(os.path.join(a, name), a), text_lines(os.path.join(b, name), b)
        if la is None or lb is None:
            continue
        compared += 1
        if la == lb:
            continue
        diffs = [(i, x, y) for i, (x, y) in enumerate(zip(la, lb)) if x != y]
        if name.endswith(".json"):
            keys = json_added_keys(os.path.join(a, name), os.path.join(b, name), a, b, rel_tol,
                                   ignore)
            if keys:
                close += 1
                print("%s: the same values%s; B adds %s"
                      % (name, " (ignoring %s)" % ", ".join(ignore) if ignore else "",
                         ", ".join(keys)))
                continue
        if rel_tol is not None and len(la) == len(lb):
            rels = [within(x, y, rel_tol) for _, x, y in diffs]
            if None not in rels:
                close += 1
                print("%s: %d lines differ, all within %.3g relative (largest %.3g)"
                      % (name, len(diffs), rel_tol, max(rels)))
                continue
        bad += 1
        print("%s: %d vs %d lines, %d differ" % (name, len(la), len(lb), len(diffs)))
        for i, x, y in diffs[:3]:
            print("  line %d\n    - %s\n    + %s" % (i + 1, x[:200], y[:200]))
    within_text = ", %d agree apart (within --rel-tol or with added JSON keys)" % close
    print("%d text files compared, %d differ or are missing%s" % (compared, bad, within_text))
    return 1 if bad else 0


if __name__ == "__main__":
    args = sys.argv[1:]
    tol = None
    ignored = []
    while len(args) > 2 and args[0] in ("--rel-tol", "--ignore"):
        if args[0] == "--rel-tol":
            tol = float(args[1])
        else:
            ignored.append(args[1])
        args = args[2:]
    if len(args) != 2:
        sys.exit(__doc__)
    sys.exit(main(args[0], args[1], tol, tuple(ignored)))
