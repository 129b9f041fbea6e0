#!/usr/bin/env python3
"""Plot a joint solve's intrinsics against the C-arm's primary angle (issue 14: C-arm flex).

    python3 scripts/plot_intrinsics_vs_angle.py OUT/result.json OUT/intrinsics_vs_angle.png

Reads result.json as `carmba solve` writes it for a joint problem with C-arm angles: every view's
intrinsics with their covariance (views[].intrinsics), the model's curve along the primary angle
with its sigma (intrinsics_curve, one per plate secondary angle; shared or smooth models) and,
when the truth is known, every view's true intrinsics. Four panels (fx, fy, cx, cy): the curve
with 1- and 3-sigma bands, plate views as dots and object views as diamonds with 3-sigma bars,
the truth as crosses. `carmba solve` runs this script (embedded in the binary) and links the PNG
from report.md.
"""
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

NAMES = ["fx", "fy", "cx", "cy"]


def main(argv):
    if len(argv) != 3:
        sys.exit("usage: plot_intrinsics_vs_angle.py result.json out.png")
    with open(argv[1]) as f:
        r = json.load(f)
    views = [v for v in r.get("views", []) if "primary_deg" in v and "intrinsics" in v]
    if not views:
        sys.exit(argv[1] + ": no views with C-arm angles")
    model = r.get("intrinsics_model", {}).get("name", "?")
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharex=True)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    secs = sorted({v["secondary_deg"] for v in views})
    colour = {s: colours[k % len(colours)] for k, s in enumerate(secs)}
    for i, name in enumerate(NAMES):
        ax = axes[i // 2][i % 2]
        for curve in r.get("intrinsics_curve", []):
            s = curve["secondary_deg"]
            a = [p["primary_deg"] for p in curve["points"]]
            x = [p["fx_fy_cx_cy"][i] for p in curve["points"]]
            sg = [p["sigma"][i] for p in curve["points"]]
            c = colour.get(s, "grey")
            ax.plot(a, x, color=c, lw=1.2, label="model, secondary %+.0f deg" % s)
            ax.fill_between(a, [u - 3 * e for u, e in zip(x, sg)], [u + 3 * e for u, e in zip(x, sg)],
                            color=c, alpha=0.12, lw=0)
            ax.fill_between(a, [u - e for u, e in zip(x, sg)], [u + e for u, e in zip(x, sg)],
                            color=c, alpha=0.25, lw=0)
        for kind, marker in (("plate", "o"), ("object", "D")):
            vs = [v for v in views if v["kind"] == kind]
            for v in vs:
                cam = v["intrinsics"]
                value = cam[name]
                k = cam["covariance"]["names"].index(name)
                sigma = max(0.0, cam["covariance"]["matrix"][k][k]) ** 0.5
                c = colour.get(v["secondary_deg"], "black")
                ax.errorbar(v["primary_deg"], value, yerr=3 * sigma, fmt=marker, ms=4, color=c,
                            mfc="white" if kind == "object" else c, capsize=2, lw=0.8)
                if "true_intrinsics" in v:
                    ax.plot(v["primary_deg"], v["true_intrinsics"][i], "x", color="black", ms=6)
        ax.set_ylabel(name + " (px)")
        ax.grid(alpha=0.3)
        if i >= 2:
            ax.set_xlabel("primary angle (deg, LAO +)")
    handles, labels = axes[0][0].get_legend_handles_labels()
    handles += [plt.Line2D([], [], marker="o", ls="", color="grey", label="plate views (3 sigma bars)"),
                plt.Line2D([], [], marker="D", ls="", mfc="white", color="grey", label="object views"),
                plt.Line2D([], [], marker="x", ls="", color="black", label="truth")]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=8, frameon=False)
    fig.suptitle("Intrinsics against the C-arm angle: model %s (bands 1 and 3 sigma)" % model)
    fig.tight_layout(rect=(0, 0.08, 1, 0.96))
    fig.savefig(argv[2], dpi=110)


if __name__ == "__main__":
    main(sys.argv)
