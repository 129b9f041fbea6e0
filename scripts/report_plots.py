#!/usr/bin/python3
# The plots of carmba's HTML reports (report.html of `carmba calibrate`, `carmba solve` and
# `carmba study`, <stem>.html of `carmba ct-fiducials`), drawn with matplotlib (Agg backend, no
# display needed).
#
#   /usr/bin/python3 scripts/report_plots.py IN.json OUT.json
#
# IN.json is written by the command (src/report/plots.h) and holds the data, never a file name:
#   kind                     "calibration" | "pose" | "joint" | "study" | "ct_fiducials"
#   image_size               [width, height] px
#   residual_views           [{id, kind, rms_px, u[], v[], du[], dv[]}]   du = projected - observed
#   cameras                  [{name, intrinsics[9]}]  (fx fy cx cy k1 k2 p1 p2 k3, px)
#   projection_uncertainty   [{name, distance_mm, definition, nx, ny, u[], v[], worst_px[]}]
#   budget                   {rows: [{quantity, unit, value, sigma, shares[]}], sources[]}
#   scenes                   [{name, frame, points[[x,y,z]], sources[{id, p[3], kind}]}]
#   markers                  {frame, items: [{id, p[3], cov[3][3]}]}
#   study                    {configs[], problems[], groups[{problem, config, sweep{}, metrics[],
#                             residuals[], budget[[entry, sigma]]}]}
#   intrinsics_vs_angle      {model, views[{id, kind, primary_deg, secondary_deg, intrinsics
#                             (camera.json), true_intrinsics[9]?}], curves[{secondary_deg,
#                             points[{primary_deg, fx_fy_cx_cy[4], sigma[4]}]}]}  (C-arm flex)
# Every key is optional; a plot whose data are missing is not drawn, and a note says why.
# OUT.json: {plots: [{id, title, caption, png_base64}], notes: [...], errors: [...]}; a plot that
# raises is listed in errors and the others are still drawn. Exit status 3 (with one line on
# stderr) when matplotlib or numpy cannot be imported: the report is then written without plots.
import base64
import io
import json
import math
import sys
import traceback

try:
    import numpy as np
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import colors as mcolors
except Exception as e:  # ImportError, or a broken installation
    sys.stderr.write("matplotlib is not available to %s (%s)\n" % (sys.executable, e))
    sys.exit(3)

DPI = 100
PALETTE = plt.rcParams["axes.prop_cycle"].by_key()["color"]
plt.rcParams.update({"font.size": 9, "axes.titlesize": 10, "axes.labelsize": 9,
                     "legend.fontsize": 8, "figure.dpi": DPI})


def slug(name):
    return "".join(c if c.isalnum() else "-" for c in name.lower()).strip("-")


def png(fig):
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


# ------------------------------------------------------------------------------------------------
# Camera model (mrcal LENSMODEL_OPENCV5, as src/camera/camera_model.h)

def distort(intr, x, y):
    fx, fy, cx, cy, k1, k2, p1, p2, k3 = intr
    r2 = x * x + y * y
    a = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * a + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * a + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return xd, yd


def distortion_displacement(intr, U, V):
    """Where distortion moves the point that the pinhole model puts at pixel (U, V), px."""
    fx, fy, cx, cy = intr[:4]
    x, y = (U - cx) / fx, (V - cy) / fy
    xd, yd = distort(intr, x, y)
    return fx * (xd - x), fy * (yd - y)


def image_axes(ax, size, title):
    w, h = size
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)  # image rows grow downwards
    ax.set_aspect("equal")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    ax.set_title(title)


def nice_scale(target):
    """1, 2 or 5 times a power of ten, at most `target`."""
    if not (target > 0) or not math.isfinite(target):
        return 1.0
    e = math.floor(math.log10(target))
    for m in (5, 2, 1):
        if m * 10 ** e <= target:
            return m * 10 ** e
    return 10 ** e


# ------------------------------------------------------------------------------------------------
# Residuals

def residuals_per_view(d, out, notes):
    views = [v for v in d.get("residual_views", []) if len(v.get("du", []))]
    if not views:
        notes.append("No residuals to plot.")
        return
    n = len(views)
    fig, ax = plt.subplots(figsize=(max(6.4, min(16, 0.28 * n + 2)), 3.6))
    kinds = sorted(set(v.get("kind", "") for v in views))
    for i, v in enumerate(views):
        r = np.hypot(np.asarray(v["du"], float), np.asarray(v["dv"], float))
        color = PALETTE[kinds.index(v.get("kind", "")) % len(PALETTE)]
        jitter = (np.arange(len(r)) % 7 - 3) * 0.05
        ax.plot(i + jitter, r, ".", ms=2.5, color=color, alpha=0.5)
        ax.plot([i - 0.35, i + 0.35], [v["rms_px"]] * 2, "-", color="k", lw=1.5)
    ax.set_xticks(range(n))
    labels = [str(v["id"]) for v in views]
    ax.set_xticklabels(labels, rotation=90 if n > 8 or max(len(s) for s in labels) > 8 else 0,
                       fontsize=7 if n > 30 else 8)
    ax.set_xlim(-0.7, n - 0.3)
    ax.set_ylim(bottom=0)
    ax.set_xlabel("view")
    ax.set_ylabel("residual length |projected - observed| (px)")
    ax.set_title("Residuals per view")
    handles = [plt.Line2D([], [], ls="", marker=".", color=PALETTE[k % len(PALETTE)],
                          label=(kinds[k] + " view points") if kinds[k] else "points")
               for k in range(len(kinds))]
    handles.append(plt.Line2D([], [], color="k", lw=1.5, label="RMS per coordinate"))
    ax.legend(handles=handles, loc="upper right", ncol=len(handles))
    ax.grid(axis="y", alpha=0.3)
    out.append(("residuals-per-view", "Residuals per view", png(fig),
                "Each dot is one observed point's residual length (px); the black bar is the "
                "view's RMS per coordinate, sqrt(SSR / 2N)."))


def residual_field(d, out, notes):
    size = d.get("image_size")
    views = [v for v in d.get("residual_views", []) if len(v.get("du", []))]
    if not views or not size or not size[0]:
        return
    kinds = []
    for v in views:
        if v.get("kind", "") not in kinds:
            kinds.append(v.get("kind", ""))
    fig, axes = plt.subplots(1, len(kinds), figsize=(6.4 * len(kinds), 5.0), squeeze=False)
    for ax, kind in zip(axes[0], kinds):
        sel = [v for v in views if v.get("kind", "") == kind]
        u = np.concatenate([np.asarray(v["u"], float) for v in sel])
        vv = np.concatenate([np.asarray(v["v"], float) for v in sel])
        du = np.concatenate([np.asarray(v["du"], float) for v in sel])
        dv = np.concatenate([np.asarray(v["dv"], float) for v in sel])
        norm = np.hypot(du, dv)
        # Arrows magnified so that the 95th percentile residual is ~4 % of the image width.
        p95 = float(np.percentile(norm, 95)) if len(norm) else 0.0
        mag = nice_scale(0.04 * size[0] / p95) if p95 > 0 else 1.0
        q = ax.quiver(u, vv, du * mag, dv * mag, norm, angles="xy", scale_units="xy", scale=1,
                      cmap="viridis", width=0.0025)
        cb = fig.colorbar(q, ax=ax, shrink=0.85)
        cb.set_label("residual length (px)")
        image_axes(ax, size, "Residuals over the image%s, arrows x%g"
                   % ((" (" + kind + " views)") if kind else "", mag))
    out.append(("residual-field", "Residuals over the image", png(fig),
                "Residual vectors (projected - observed) at the observed pixels of all views, "
                "magnified by the factor in the title; colour is the length in px. A pattern "
                "(swirl, radial flow) rather than noise points at a model error."))


# ------------------------------------------------------------------------------------------------
# Camera

def distortion_field(d, out, notes):
    size = d.get("image_size")
    cams = d.get("cameras", [])
    if not cams or not size or not size[0]:
        return
    for cam in cams:
        intr = [float(x) for x in cam["intrinsics"]]
        if all(x == 0 for x in intr[4:]):
            notes.append("No distortion plot for %s: its distortion coefficients are all 0."
                         % cam["name"])
            continue
        w, h = size
        cx, cy = intr[2:4]
        U, V = np.meshgrid(np.linspace(0, w - 1, 17), np.linspace(0, h - 1, 13))
        du, dv = distortion_displacement(intr, U, V)
        norm = np.hypot(du, dv)
        fig, ax = plt.subplots(figsize=(6.6, 5.0))
        Uf, Vf = np.meshgrid(np.linspace(0, w - 1, 120), np.linspace(0, h - 1, 90))
        cs = ax.contourf(Uf, Vf, np.hypot(*distortion_displacement(intr, Uf, Vf)), levels=12,
                         cmap="Blues")
        cb = fig.colorbar(cs, ax=ax, shrink=0.85)
        cb.set_label("distortion displacement (px)")
        top = float(np.max(norm))
        # The longest arrow about 1.5 grid spacings.
        mag = nice_scale(1.5 * (w / 16.0) / top) if top > 0 else 1.0
        ax.quiver(U, V, du * mag, dv * mag, angles="xy", scale_units="xy", scale=1, width=0.002,
                  color="k")
        ax.plot([cx], [cy], "r+", ms=10, mew=1.5)
        image_axes(ax, size, "Distortion of %s, arrows x%g (largest %.3g px)"
                   % (cam["name"], mag, top))
        out.append(("distortion-" + slug(cam["name"]), "Distortion field of " + cam["name"], png(fig),
                    "Where distortion moves a point that the distortion-free (pinhole) model "
                    "puts at each pixel: arrows magnified by the factor in the title, colour the "
                    "displacement in px. Red cross: principal point (cx, cy)."))


def projection_uncertainty(d, out, notes):
    size = d.get("image_size")
    items = d.get("projection_uncertainty", [])
    if not items:
        return
    pts = [v for v in d.get("residual_views", []) if v.get("kind") in ("plate", "")]
    for it in items:
        nx, ny = int(it["nx"]), int(it["ny"])
        u = np.asarray(it["u"], float).reshape(ny, nx)
        v = np.asarray(it["v"], float).reshape(ny, nx)
        s = np.asarray([np.nan if x is None else x for x in it["worst_px"]], float).reshape(ny, nx)
        if not np.any(np.isfinite(s)):
            notes.append("No projection-uncertainty plot for %s: no pixel could be evaluated."
                         % it["name"])
            continue
        fig, ax = plt.subplots(figsize=(6.6, 5.0))
        finite = s[np.isfinite(s)]
        # Log-spaced colours: the uncertainty grows by orders of magnitude away from the data.
        hi = float(np.percentile(finite, 98))
        lo = max(float(np.min(finite)), 1e-12)
        if not hi > lo * 1.01:
            hi = lo * 1.01
        levels = np.geomspace(lo, hi, 13)
        cs = ax.contourf(u, v, np.clip(s, lo, hi), levels=levels, cmap="magma_r",
                         norm=mcolors.LogNorm(lo, hi))
        cl = ax.contour(u, v, s, levels=levels[2::4], colors="w", linewidths=0.6,
                        norm=mcolors.LogNorm(lo, hi))
        ax.clabel(cl, fmt="%.2g", fontsize=7)
        cb = fig.colorbar(cs, ax=ax, shrink=0.85)
        cb.set_label("1-sigma projection uncertainty, worst direction (px, log scale)")
        cb.set_ticks(levels[::2])
        cb.set_ticklabels(["%.2g" % x for x in levels[::2]])
        if pts:
            uu = np.concatenate([np.asarray(p["u"], float) for p in pts])
            vv = np.concatenate([np.asarray(p["v"], float) for p in pts])
            ax.plot(uu, vv, ".", color="c", ms=1.5, alpha=0.7)
        if size and size[0]:
            image_axes(ax, size, "")
        ax.set_title("Projection uncertainty of %s at %.0f mm" % (it["name"], it["distance_mm"]))
        out.append(("projection-uncertainty-" + slug(it["name"]),
                    "Projection uncertainty of " + it["name"], png(fig),
                    it["definition"] + (" Cyan dots: the observed calibration points."
                                        if pts else "")))


# ------------------------------------------------------------------------------------------------
# Error budget

def error_budget(d, out, notes):
    b = d.get("budget")
    if not b or not b.get("rows"):
        return
    sources = b["sources"]
    rows = [r for r in b["rows"] if r.get("sigma") is not None and r["sigma"] > 0]
    if not rows:
        notes.append("No error-budget plot: no quantity has a non-zero sigma.")
        return
    n = len(rows)
    fig, ax = plt.subplots(figsize=(8.0, 0.24 * n + 1.4))
    left = np.zeros(n)
    y = np.arange(n)
    for k, src in enumerate(sources):
        share = np.array([100 * (r["shares"][k] or 0) for r in rows])
        if not np.any(share > 0):
            continue
        ax.barh(y, share, left=left, color=PALETTE[k % len(PALETTE)], label=src, height=0.75)
        left += share
    labels = ["%s (sigma %.3g%s)" % (r["quantity"], r["sigma"], " " + r["unit"] if r["unit"] else "")
              for r in rows]
    ax.set_yticks(y)
    ax.set_yticklabels(labels, fontsize=7 if n > 25 else 8)
    ax.set_ylim(n - 0.5, -0.5)  # first row on top, no empty margin
    ax.set_xlim(0, 100)
    ax.set_xlabel("share of the variance (%)")
    ax.set_title("Error budget: where each quantity's uncertainty comes from", pad=24)
    ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=len(sources), frameon=False)
    out.append(("error-budget", "Error budget", png(fig),
                "Each bar splits one quantity's variance into the independent noise sources "
                "(first order; the shares add up to 100 %). The label gives the quantity's total "
                "1-sigma uncertainty."))


# ------------------------------------------------------------------------------------------------
# 3-D

def equal_3d(ax, pts):
    pts = np.asarray(pts, float)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    c, r = (lo + hi) / 2, max(float(np.max(hi - lo)) / 2, 1e-6)
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_zlim(c[2] - r, c[2] + r)
    ax.set_box_aspect((1, 1, 1), zoom=0.82)  # room for the z label


def scenes_3d(d, out, notes):
    for sc in d.get("scenes", []):
        points = np.asarray(sc.get("points", []), float).reshape(-1, 3)
        sources = sc.get("sources", [])
        if not sources:
            continue
        fig = plt.figure(figsize=(6.4, 5.6))
        ax = fig.add_subplot(projection="3d")
        if len(points):
            ax.scatter(points[:, 0], points[:, 1], points[:, 2], s=6, c="0.35",
                       label=sc.get("points_label", "points"), depthshade=False)
            centre = points.mean(axis=0)
        else:
            centre = np.zeros(3)
        S = np.asarray([s["p"] for s in sources], float)
        ax.scatter(S[:, 0], S[:, 1], S[:, 2], s=28, c=PALETTE[3], marker="^",
                   label="X-ray source", depthshade=False)
        for s in sources:
            p = np.asarray(s["p"], float)
            ax.plot(*zip(p, centre), color=PALETTE[3], lw=0.6, alpha=0.5)
        if len(sources) <= 16:
            for s in sources:
                ax.text(s["p"][0], s["p"][1], s["p"][2], " " + str(s["id"]), fontsize=7)
        equal_3d(ax, np.vstack([S, points, centre[None]]) if len(points) else S)
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_zlabel("z (mm)")
        ax.set_title("Source positions in the %s frame" % sc["frame"])
        ax.legend(loc="upper left")
        out.append(("poses-" + slug(sc["name"]), "Source positions (" + sc["name"] + ")", png(fig),
                    "The X-ray source of each %s view (the camera centre, -R^T t of %s) in the %s "
                    "frame, with a line to the centre of the %s; mm."
                    % (sc["name"], sc.get("pose_name", "the pose"), sc["frame"],
                       sc.get("points_label", "points"))))


def markers_3d(d, out, notes):
    m = d.get("markers")
    if not m or not m.get("items"):
        return
    items = m["items"]
    P = np.asarray([it["p"] for it in items], float)
    covs = [np.asarray(it["cov"], float) for it in items]
    sig_max = max(math.sqrt(max(np.linalg.eigvalsh(c).max(), 0)) for c in covs)
    spread = float(np.max(P.max(axis=0) - P.min(axis=0))) if len(P) > 1 else 10.0
    # 3-sigma ellipsoids, magnified so that the largest spans ~6 % of the marker spread.
    mag = nice_scale(0.06 * spread / (3 * sig_max)) if sig_max > 0 else 1.0
    mag = max(mag, 1.0)
    fig = plt.figure(figsize=(6.4, 5.6))
    ax = fig.add_subplot(projection="3d")
    ax.scatter(P[:, 0], P[:, 1], P[:, 2], s=8, c="k", depthshade=False)
    t = np.linspace(0, 2 * np.pi, 24)
    ph = np.linspace(0, np.pi, 12)
    sphere = np.stack([np.outer(np.cos(t), np.sin(ph)), np.outer(np.sin(t), np.sin(ph)),
                       np.outer(np.ones_like(t), np.cos(ph))], axis=-1)
    for it, c, p in zip(items, covs, P):
        w, V = np.linalg.eigh(c)
        A = V.dot(np.diag(3 * mag * np.sqrt(np.clip(w, 0, None))))
        E = sphere.dot(A.T) + p
        ax.plot_wireframe(E[..., 0], E[..., 1], E[..., 2], color=PALETTE[0], lw=0.4, alpha=0.6)
        ax.text(p[0], p[1], p[2] + 1.2 * float(np.max(np.abs(E[..., 2] - p[2]))), "%s" % it["id"],
                fontsize=7, ha="center", va="bottom")
    equal_3d(ax, P)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    ax.set_title("Markers in the %s frame, 3-sigma ellipsoids x%g" % (m["frame"], mag))
    out.append(("markers", "Markers with covariance ellipsoids", png(fig),
                "Estimated marker centres (mm) with their 3-sigma covariance ellipsoids, "
                "magnified %g times (the largest 1-sigma semi-axis is %.3g mm). %s"
                % (mag, sig_max, m.get("note", ""))))


# ------------------------------------------------------------------------------------------------
# Study

def metric(g, kind, name):
    for m in g["metrics"]:
        if m["kind"] == kind and m["name"] == name:
            return m
    return None


def study_plots(d, out, notes):
    st = d.get("study")
    if not st:
        return
    groups, configs, problems = st["groups"], st["configs"], st["problems"]
    color = {c: PALETTE[i % len(PALETTE)] for i, c in enumerate(configs)}
    errors = sorted({m["name"] for g in groups for m in g["metrics"] if m["kind"] == "error"})
    pref = [e for e in ("rotation_deg", "translation_mm", "tre_mm") if e in errors]
    errors = (pref + [e for e in errors if e not in pref])[:4]
    sweeps = []
    for g in groups:
        for k in g["sweep"]:
            if k not in sweeps:
                sweeps.append(k)
    # Error against each swept variable with >= 2 values (others held at their first value).
    drawn = 0
    for var in sweeps:
        values = sorted({g["sweep"][var] for g in groups if var in g["sweep"]})
        if len(values) < 2:
            continue
        base = {}
        for g in groups:
            for k, v in g["sweep"].items():
                if k != var and k not in base:
                    base[k] = v
        held = ", ".join("%s = %g" % kv for kv in base.items())
        for problem in problems:
            for e in errors:
                fig, ax = plt.subplots(figsize=(6.0, 3.8))
                any_line = False
                for c in configs:
                    xs, med, p95 = [], [], []
                    for g in groups:
                        if g["problem"] != problem or g["config"] != c or var not in g["sweep"]:
                            continue
                        if any(g["sweep"].get(k) != v for k, v in base.items()):
                            continue
                        m = metric(g, "error", e)
                        if not m or not m["n"]:
                            continue
                        xs.append(g["sweep"][var])
                        med.append(m["median"])
                        p95.append(m["p95"])
                    if not xs:
                        continue
                    o = np.argsort(xs)
                    xs, med, p95 = np.asarray(xs)[o], np.asarray(med)[o], np.asarray(p95)[o]
                    ax.plot(xs, med, "-o", color=color[c], ms=4, label=c + " median")
                    ax.plot(xs, p95, "--", color=color[c], lw=1, label=c + " p95")
                    any_line = True
                if not any_line:
                    plt.close(fig)
                    continue
                if values[0] > 0 and values[-1] / values[0] >= 10:
                    ax.set_xscale("log")
                    ax.set_xticks(values)
                    ax.set_xticklabels(["%g" % v for v in values])
                    ax.minorticks_off()
                ax.set_xlabel(var)
                ax.set_ylabel(e)
                ax.set_ylim(bottom=0)
                ax.grid(alpha=0.3)
                ax.set_title("%s: %s against %s" % (problem, e, var))
                ax.legend(ncol=2)
                drawn += 1
                out.append(("error-vs-noise-%d" % drawn, "%s vs %s" % (e, var), png(fig),
                            "Median (solid) and 95th percentile (dashed) of %s over the trials "
                            "against %s%s." % (e, var, " (held: " + held + ")" if held else "")))
    if not drawn:
        notes.append("No swept variable has two or more values: no error-vs-noise plot.")
    # Reported sigma against the empirical spread.
    pts = [(g, m) for g in groups for m in g["metrics"]
           if m["kind"] == "signed" and m.get("has_sigma") and (m.get("pred_sigma") or 0) > 0
           and (m.get("emp_sigma") or 0) > 0]
    if pts:
        fig, ax = plt.subplots(figsize=(5.2, 4.6))
        for c in configs:
            sel = [(g, m) for g, m in pts if g["config"] == c]
            if sel:
                ax.loglog([m["pred_sigma"] for _, m in sel], [m["emp_sigma"] for _, m in sel],
                          "o", color=color[c], ms=4, label=c)
        vals = [m["pred_sigma"] for _, m in pts] + [m["emp_sigma"] for _, m in pts]
        lo, hi = min(vals) / 1.5, max(vals) * 1.5
        ax.plot([lo, hi], [lo, hi], "--", color="0.5", label="y = x (honest)")
        ax.set_xlim(lo, hi)
        ax.set_ylim(lo, hi)
        ax.set_aspect("equal")
        ax.set_xlabel("reported sigma (RMS over trials)")
        ax.set_ylabel("empirical sigma (std over trials)")
        ax.set_title("Reported sigma against empirical spread")
        ax.grid(alpha=0.3, which="both")
        ax.legend()
        out.append(("sigma-consistency", "Reported vs empirical sigma", png(fig),
                    "Each dot is one parameter of one problem x config x sweep point, in that "
                    "parameter's unit. On the dashed line the reported uncertainty is honest; "
                    "above it the solver is overconfident."))
    else:
        notes.append("No run reported sigmas with two or more trials: no sigma-consistency plot.")
    # Residual histograms per problem x config.
    drawn = 0
    for problem in problems:
        for c in configs:
            r = np.concatenate([np.asarray(g.get("residuals", []), float) for g in groups
                                if g["problem"] == problem and g["config"] == c] or [np.zeros(0)])
            if len(r) < 2:
                continue
            half = float(np.max(np.abs(np.percentile(r, [0.5, 99.5])))) or 1.0
            inside = r[np.abs(r) <= half]
            fig, ax = plt.subplots(figsize=(5.2, 3.4))
            ax.hist(inside, bins=40, range=(-half, half), color=color[c])
            ax.set_xlabel("residual (px)")
            ax.set_ylabel("count")
            ax.set_title("%s / %s: residuals" % (problem, c))
            drawn += 1
            out.append(("residual-histogram-%d" % drawn, "Residuals %s / %s" % (problem, c),
                        png(fig), "%d residuals pooled over the trials and sweep points%s." %
                        (len(r), ", %d outside the plotted range" % (len(r) - len(inside))
                         if len(r) > len(inside) else "")))
    if not drawn:
        notes.append("No run reported residuals: no residual histogram.")
    # Error budget: per problem and quantity, a bar per config x sweep point (the group), its
    # height the total predicted sigma (mean variance over the trials), split by each source's
    # share of the variance.
    drawn = 0
    for problem in problems:
        sel = [g for g in groups if g["problem"] == problem and g.get("budget")]
        if not sel:
            continue
        quantities, sources, var = [], [], []
        for g in sel:
            v = {}
            for entry, sig in g["budget"]:
                q, _, src = entry.rpartition(".")
                if not q:
                    q, src = src, "total"
                if q not in quantities:
                    quantities.append(q)
                if src not in sources:
                    sources.append(src)
                v[(q, src)] = sig * sig
            var.append(v)
        one_config = len({g["config"] for g in sel}) == 1
        labels = []
        sweep_names = {k for g in sel for k in g["sweep"]}
        single = len(sweep_names) == 1 and one_config
        for g in sel:
            sw = ", ".join(("%g" % v) if single else ("%s %g" % (k, v))
                           for k, v in g["sweep"].items())
            labels.append(sw if one_config and sw else (g["config"] + ("\n" + sw if sw else "")))
        x = np.arange(len(sel))
        width = max(5.0, min(16.0, 0.45 * len(sel) * len(quantities) + 1.5))
        fig, axes = plt.subplots(1, len(quantities), figsize=(width, 3.8), squeeze=False)
        for ax, q in zip(axes[0], quantities):
            bottom = np.zeros(len(sel))
            for k, src in enumerate(sources):
                part = np.array([math.sqrt(max(v.get((q, src), 0.0), 0.0)) for v in var])
                total = np.array([math.sqrt(sum(val for (qq, _), val in v.items() if qq == q))
                                  for v in var])
                # Each segment's height: the source's share of the variance times the total.
                seg = np.where(total > 0, part ** 2 / np.where(total > 0, total, 1), 0.0)
                ax.bar(x, seg, bottom=bottom, color=PALETTE[k % len(PALETTE)],
                       label=src if ax is axes[0][0] else None, width=0.7)
                bottom += seg
            ax.set_xticks(x)
            ax.set_xticklabels(labels, rotation=0 if single or len(sel) <= 4 else 90, fontsize=7)
            if single:
                ax.set_xlabel(next(iter(sweep_names)))
            ax.set_title(q, fontsize=9)
            ax.set_ylabel("predicted 1-sigma")
        fig.suptitle("%s: predicted error budget per %s" %
                     (problem, "sweep point" if one_config else "config and sweep point"))
        fig.tight_layout()
        fig.legend(loc="upper center", ncol=min(5, len(sources)), bbox_to_anchor=(0.5, 0.0),
                   frameon=False)
        drawn += 1
        out.append(("error-budget-%d" % drawn, "Error budget " + problem, png(fig),
                    "Bar height: a quantity's predicted 1-sigma uncertainty (the runs' budget, "
                    "mean over the trials); the colours split it by each noise source's share of "
                    "the variance."))


# ------------------------------------------------------------------------------------------------
# Intrinsics against the C-arm angle (C-arm flex, issue 14)

def intrinsics_vs_angle(d, out, notes):
    data = d.get("intrinsics_vs_angle")
    if not data or not data.get("views"):
        return
    views = data["views"]
    names = ["fx", "fy", "cx", "cy"]
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharex=True)
    secs = sorted({v["secondary_deg"] for v in views})
    colour = {s: PALETTE[k % len(PALETTE)] for k, s in enumerate(secs)}
    for i, name in enumerate(names):
        ax = axes[i // 2][i % 2]
        for curve in data.get("curves", []):
            s = curve["secondary_deg"]
            a = [p["primary_deg"] for p in curve["points"]]
            x = np.asarray([np.nan if p["fx_fy_cx_cy"][i] is None else p["fx_fy_cx_cy"][i]
                            for p in curve["points"]], float)
            sg = np.asarray([np.nan if p["sigma"][i] is None else p["sigma"][i]
                             for p in curve["points"]], float)
            c = colour.get(s, "grey")
            ax.plot(a, x, color=c, lw=1.2, label="model, secondary %+.0f deg" % s)
            ax.fill_between(a, x - 3 * sg, x + 3 * sg, color=c, alpha=0.12, lw=0)
            ax.fill_between(a, x - sg, x + sg, color=c, alpha=0.25, lw=0)
        for kind, marker in (("plate", "o"), ("object", "D")):
            for v in (v for v in views if v["kind"] == kind):
                cam = v["intrinsics"]
                k = cam["covariance"]["names"].index(name)
                var = cam["covariance"]["matrix"][k][k]
                sigma = max(0.0, var if var is not None else 0.0) ** 0.5
                c = colour.get(v["secondary_deg"], "black")
                ax.errorbar(v["primary_deg"], cam[name], yerr=3 * sigma, fmt=marker, ms=4, color=c,
                            mfc="white" if kind == "object" else c, capsize=2, lw=0.8)
                if "true_intrinsics" in v:
                    ax.plot(v["primary_deg"], v["true_intrinsics"][i], "x", color="black", ms=6)
        ax.set_ylabel(name + " (px)")
        ax.grid(alpha=0.3)
        if i >= 2:
            ax.set_xlabel("primary angle (deg, LAO +)")
    handles, _ = axes[0][0].get_legend_handles_labels()
    handles += [plt.Line2D([], [], marker="o", ls="", color="grey", label="plate views (3 sigma bars)"),
                plt.Line2D([], [], marker="D", ls="", mfc="white", color="grey", label="object views"),
                plt.Line2D([], [], marker="x", ls="", color="black", label="truth")]
    fig.legend(handles=handles, loc="lower center", ncol=3, frameon=False)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    out.append(("intrinsics-vs-angle",
                "Intrinsics against the C-arm angle (model %s)" % data.get("model", "?"), png(fig),
                "fx, fy, cx, cy of every view at its C-arm angles with 3-sigma bars (plate views "
                "filled, object views open), the model's curve along the primary angle at each plate "
                "secondary angle with 1- and 3-sigma bands, and the truth (crosses) when known."))


# ------------------------------------------------------------------------------------------------

PLOTS = {
    "calibration": [residuals_per_view, residual_field, distortion_field, projection_uncertainty,
                    scenes_3d],
    "pose": [residuals_per_view, residual_field, error_budget, scenes_3d, markers_3d,
             distortion_field],
    "joint": [residuals_per_view, residual_field, distortion_field, projection_uncertainty,
              error_budget, scenes_3d, markers_3d, intrinsics_vs_angle],
    "study": [study_plots],
    "ct_fiducials": [markers_3d],
}


def main():
    if len(sys.argv) != 3:
        sys.stderr.write("usage: report_plots.py IN.json OUT.json\n")
        return 2
    with open(sys.argv[1]) as f:
        d = json.load(f)
    out, notes, errors = [], [], []
    for fn in PLOTS.get(d.get("kind"), []):
        try:
            fn(d, out, notes)
        except Exception:
            errors.append("%s: %s" % (fn.__name__, traceback.format_exc().strip().splitlines()[-1]))
            plt.close("all")
    res = {"plots": [{"id": i, "title": t, "png_base64": p, "caption": c} for i, t, p, c in out],
           "notes": notes, "errors": errors}
    with open(sys.argv[2], "w") as f:
        json.dump(res, f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
