#!/usr/bin/env python3
"""Compares the estimates of two directories written by scripts/golden_outputs.sh in their own
sigmas: for every error-budget row (each estimated quantity: intrinsics, view poses, relative
rotations) of every result.json, how far the value moved in sigmas, |b - a| / sigma_a, and how
much the sigma changed, |sigma_b / sigma_a - 1|. For a change that moves results on purpose (a
solver tolerance, a warm start): compare_outputs.py says which lines differ, this says by how
much in the units that matter. Prints the largest of each per file and overall; exit 0.
    python3 scripts/compare_budgets.py /tmp/golden_before /tmp/golden_after
"""
import glob
import json
import os
import sys


def rows(path):
    with open(path) as f:
        return {r["quantity"]: r for r in json.load(f).get("error_budget", [])}


def main(a, b):
    worst_value, worst_sigma = (0.0, ""), (0.0, "")
    for fa in sorted(glob.glob(os.path.join(a, "*", "result.json"))):
        name = os.path.relpath(fa, a)
        fb = os.path.join(b, name)
        if not os.path.exists(fb):
            print(f"{name}: missing in {b}")
            continue
        ra, rb = rows(fa), rows(fb)
        if not ra:
            continue
        file_value = file_sigma = 0.0
        for q, r in ra.items():
            if q not in rb or not r["sigma"]:
                continue
            dv = abs(rb[q]["value"] - r["value"]) / r["sigma"]
            ds = abs(rb[q]["sigma"] / r["sigma"] - 1)
            file_value, file_sigma = max(file_value, dv), max(file_sigma, ds)
            worst_value = max(worst_value, (dv, f"{name} {q}"))
            worst_sigma = max(worst_sigma, (ds, f"{name} {q}"))
        print(f"{name:45s} {len(ra):4d} rows; value moved <= {file_value:.2e} sigma, "
              f"sigma changed <= {file_sigma:.2e}")
    print(f"largest value move: {worst_value[0]:.2e} sigma ({worst_value[1]})")
    print(f"largest sigma change: {worst_sigma[0]:.2e} relative ({worst_sigma[1]})")
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: compare_budgets.py DIR_A DIR_B")
    sys.exit(main(sys.argv[1], sys.argv[2]))
