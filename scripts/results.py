#!/usr/bin/env python3
"""src/docs/results.md is generated, so that a measured figure is stated once.

Its text is src/docs/results.md.in; its figures, written there as {{section.name}}, are in
src/docs/results_figures.json with the commit, date and command that measured them. Each figure
appears exactly once in the template; the numbers the template states itself are inputs (a
scene's settings, a test's bounds, the thesis's printed tables).

  python3 scripts/results.py measure [--bin build/bin/carmba]
      runs scripts/golden_outputs.sh (every shipped problem and scene, about 50 s on 2 cores)
      into a scratch directory and extracts the figures from its result files; runs two studies,
      the calibrations' mrcal and OpenCV cross-checks, the rigid flex scene and the clutter
      scene's pose NEES over seeds (about 70 s); runs the tests of
      TEST_RUNS (beside the binary: BUILD/tests/) and takes the figures they record
      (tests/figures.h); runs the marker recall test on every seed set of RECALL_RUNS (two at a
      time); runs BENCH_FILTER's benchmarks of BUILD/tests/carmba_bench on one core
      (it builds it: it is not in `all`); writes the figures file and results.md. 800 and 948 s
      in two runs on 2 cores (about 6 min of it the recall sets, development and unseen).
  python3 scripts/results.py render [--check]
      writes results.md from the template and the figures file; --check writes nothing and exits
      1 when results.md differs from that (a hand edit, or a template changed without a render)
"""
import argparse
import datetime
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import textwrap
from concurrent.futures import ThreadPoolExecutor
from xml.etree import ElementTree

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TEMPLATE = os.path.join(ROOT, "src/docs/results.md.in")
FIGURES = os.path.join(ROOT, "src/docs/results_figures.json")
RESULTS = os.path.join(ROOT, "src/docs/results.md")
# A figure in the template: {{section.name}}, or {{measured}} (the commit and date of the figures).
FIGURE_REF = re.compile(r"\{\{([a-z0-9_.]+)\}\}")


def load_json(path):
    with open(path) as f:
        return json.load(f)


def f(value, fmt):
    """A number as the template states it; '-' for a missing one."""
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else fmt % value


def sci(value):
    """1 significant decimal in scientific notation without exponent padding: 2.3e-3."""
    return re.sub(r"e([+-])0*(\d)", lambda m: "e" + m.group(1).replace("+", "") + m.group(2),
                  "%.1e" % value)


def csv_lines(path):
    """A CSV file's header and rows (lists of cells), '#' comment lines and blank lines left out."""
    with open(path) as fh:
        lines = [l.strip().split(",") for l in fh if l.strip() and not l.startswith("#")]
    return lines[0], lines[1:]


def slash_list(values, fmt):
    return " / ".join(f(v, fmt) for v in values)


# ---- The thesis's pose experiment ------------------------------------------------------------

def printed_thesis_angles():
    """Table 5.6 as printed: (a, b) -> (achieved, expected)."""
    rows = {}
    head, lines = csv_lines(os.path.join(ROOT, "data/thesis/validation_table_5_6.csv"))
    for line in lines:
        r = dict(zip(head, line))
        rows[(r["orientation_a_deg"], r["orientation_b_deg"])] = (float(r["achieved_deg"]),
                                                                  float(r["expected_deg"]))
    return rows


def printed_rotations():
    """Tables 5.3-5.5: orientation -> R (object -> camera)."""
    out = {}
    _, lines = csv_lines(os.path.join(ROOT, "data/thesis/posit_rotations_tables_5_3_to_5_5.csv"))
    for cells in lines:
        out[cells[0]] = [float(c) for c in cells[1:10]]  # row-major
    return out


def view_direction_angle_deg(Ra, Rb):
    """The thesis's metric: the angle between inv(R_a)(0,0,1) and inv(R_b)(0,0,1), i.e. between
    the third rows of the row-major R_a and R_b (the printed matrices are not orthonormal)."""
    va, vb = Ra[6:9], Rb[6:9]
    dot = sum(x * y for x, y in zip(va, vb))
    c = dot / math.sqrt(sum(x * x for x in va)) / math.sqrt(sum(x * x for x in vb))
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def thesis_figures(out):
    r = load_json(os.path.join(out, "thesis_pose_posit_ba_analytic/result.json"))
    legacy = r["comparison"]["legacy_posit"]
    cam = r["problem"]["camera"]
    printed = printed_thesis_angles()
    rows = ["| pair | expected | thesis | legacy POSIT (ours) | bundle adjustment, view "
            "directions +- 1 sigma | relative rotation |", "|---|---|---|---|---|---|"]
    for p, lp in zip(r["validation"], legacy["validation"]):
        achieved, expected = printed[(p["a"], p["b"])]
        rows.append("| %s-%s | %g | %.4f | %.4f | %.3f +- %.3f | %.3f +- %.3f |" % (
            p["a"], p["b"], expected, achieved, lp["angle_view_dirs_deg"],
            p["angle_view_dirs_deg"], p["sigma_view_dirs_deg"], p["relative_rotation_deg"],
            p["sigma_relative_rotation_deg"]))
    diff = {v["id"]: v["max_abs_diff_to_printed"] for v in legacy["views"]}
    R = printed_rotations()
    s = r["statistics"]
    return {
        "camera": "fx %.3f, fy %.3f, cx %.3f, cy %.3f px" % (cam["fx"], cam["fy"], cam["cx"],
                                                             cam["cy"]),
        "sigma_px": f(r["problem"]["sigma_px"], "%g"),
        "validation_table": "\n".join(rows),
        "rms_legacy": slash_list([v["rms_px"] for v in legacy["views"]], "%.2f"),
        "rms_ba": slash_list([v["rms_px"] for v in r["views"]], "%.2f"),
        "views": ", ".join(v["id"] for v in r["views"]),
        "chi2": "%.2f on %d degrees of freedom (P = %.2f)" % (s["chi2"], s["dof"],
                                                             s["chi2_p_value"]),
        "legacy_printed_10_30_50": sci(max(diff["10"], diff["30"], diff["50"])),
        "legacy_printed_0_90": sci(diff["0"]) + ", " + sci(diff["90"]),
        "printed_0_10_from_printed_r": "%.4f" % view_direction_angle_deg(R["0"], R["10"]),
        "handedness_rms": "RMS %.3f vs %.3f px" % (
            s["rms_px"], r["comparison"]["other_handedness"]["rms_px"]),
    }


# ---- The joint bundle adjustment -----------------------------------------------------------

def joint_figures(out):
    r = load_json(os.path.join(out, "joint_joint_radial/result.json"))
    truth = load_json(os.path.join(out, "out/sim/joint/truth.json"))["camera"]
    intr = r["intrinsics"]
    z_intr = [(intr[k] - truth[k]) / intr["sigmas"][k] for k in ("fx", "fy", "cx", "cy")]
    z_rot = [(p["relative_rotation_deg"] - p["true_relative_rotation_deg"]) /
             p["sigma_relative_rotation_deg"] for p in r["validation"]]
    s = r["statistics"]
    (plate,) = [g for g in r["variance_components"]["groups"] if g["group"] == "plate_pixels"]
    # configs/joint.yaml (`distortion: auto`) against joint_radial.yaml: what the recommended
    # tangential terms cost in the principal point's sigma, and how far every intrinsic is off
    auto = load_json(os.path.join(out, "joint_joint/result.json"))["intrinsics"]
    auto_z = [abs(auto[k] - truth[k]) / auto["sigmas"][k] for k in ("fx", "fy", "cx", "cy")]
    return {
        "auto_pp_sigmas": "from %.2f, %.2f px with p1, p2 held to %.1f, %.1f px" % (
            intr["sigmas"]["cx"], intr["sigmas"]["cy"], auto["sigmas"]["cx"],
            auto["sigmas"]["cy"]),
        "auto_max_z": "%.1f" % max(auto_z),
        "plate_factor": "f = %.3f +- %.3f" % (plate["factor"], plate["factor_sigma"]),
        "plate_factor_in_band": "inside its band" if not plate["outside_band"]
                                else "outside its band",
        "intrinsics_z": ", ".join("%.2f" % z for z in z_intr),
        "pairs": ", ".join("%s-%s" % (p["a"].split("_")[-1].lstrip("0") or "0",
                                      p["b"].split("_")[-1].lstrip("0") or "0")
                           for p in r["validation"]),
        "rotation_z": ", ".join("%.2f" % z for z in z_rot),
        "rms": "RMS %.3f px (plate) and %.2f px (object)" % (s["rms_plate_px"],
                                                             s["rms_object_px"]),
        "solve": "%d iterations, %.1f ms for solve + covariance" % (
            r["solver"]["iterations"], 1e3 * r["solver"]["time_s"]),
    }


def mrcal_figures(out):
    """mrcal 2.2 against carmba's engine on the joint scene, for configs/joint.yaml and
    configs/joint_radial.yaml (result.json's mrcal_crosscheck)."""
    figures = {}
    for config in ("joint", "joint_radial"):
        m = load_json(os.path.join(out, "joint_%s/result.json" % config))["mrcal_crosscheck"]
        ours, theirs = m["carmba"]["intrinsics"], m["mrcal"]["intrinsics"]
        # the distortion terms solved (not held at 0) on both sides
        distortion = [abs(a - b) / abs(a) for a, b in zip(ours[4:], theirs[4:]) if a != 0]
        rms = m["rms_px_carmba_in_mrcal"]
        figures.update({
            config + ".held": m["what"].split(", ")[1].split(" (")[0],
            config + ".rel": sci(m["max_relative_difference_fx_fy_cx_cy"]),
            config + ".sigma": sci(m["max_difference_in_sigmas"]),
            config + ".distortion_rel": sci(max(distortion)) if distortion else "0",
            config + ".rms_rel": sci(abs(rms - m["rms_px_mrcal"]) / rms),
            config + ".rms_diff": sci(abs(rms - m["rms_px_mrcal"])),
            config + ".seeded_sigma": sci(m["max_move_in_sigmas_of_mrcal_seeded_at_carmba"]),
            config + ".seeded_rel": sci(m["max_relative_move_of_mrcal_seeded_at_carmba"]),
        })
    return figures


# ---- Real radiographs: beads tracked through frames --------------------------------------------

def track_figures(out):
    j = load_json(os.path.join(out, "track_wrist/rigid_bodies.json"))
    c = j["checks"]
    beads = sum(len(b["points"]) for b in j["bodies"])
    return {
        "bodies": "%d beads in %d bodies" % (beads, len(j["bodies"])),
        "beads_per_frame": "%d beads per frame" % c["min_beads_per_frame"],
        "rms": "RMS %.3f px" % c["rms_px"],
        "max_change": "%.2f sigma" % c["max_change_sigmas"],
        "variance_factor": "%.1f" % c["pixel_sigma_scale"] ** 2,
        "sigma_scale": "%.1fx" % c["pixel_sigma_scale"],
        "max_change_stated": "%.2f sigma" % c["max_change_sigmas_stated"],
        "max_spread": "%.3f mm" % c["max_spread_mm"],
        "rms_spread": "%.3f mm" % c["rms_spread_mm"],
        "distance_chi2": "%.1f on %d dof" % (c["distance_chi2"], c["distance_dof"]),
        "predicted_max_spread": "%.3f mm" % c["predicted_max_spread_mm"],
    }


# ---- Relative poses, TRE and triangulation on the rendered joint scene -----------------------

def mahalanobis(e, C):
    return math.sqrt(sum(a * b for a, b in zip(e, solve_linear(C, e))))


def tre_figures(out):
    r = load_json(os.path.join(out, "joint_tre/result.json"))
    pairs = r["relative_poses"]
    t = r["tre"]
    truth = {m["id"]: [m["x_mm"], m["y_mm"], m["z_mm"]]
             for m in load_json(os.path.join(out, "out/sim/joint/truth.json"))["ct_markers"]}
    points = load_json(os.path.join(out, "triangulate_joint/triangulation.json"))["points"]
    errors = [[a - b for a, b in zip(p["p_in_ct_mm"], truth[int(p["id"])])] for p in points]
    sigmas = [mahalanobis(e, p["covariance_mm2"]) for e, p in zip(errors, points)]
    rms = math.sqrt(sum(sum(x * x for x in e) for e in errors) / len(errors))
    return {
        "relative_rotations": "all %d relative rotations within %.2f sigma of the truth (3-dof "
                              "Mahalanobis; angle errors within %.2f sigma), mean NEES / 6 = %.2f"
                              % (len(pairs), max(p["rotation_error_sigma"] for p in pairs),
                                 max(abs(p["angle_error_sigma"]) for p in pairs),
                                 sum(p["nees"] for p in pairs) / 6 / len(pairs)),
        "tre": "leave-one-out TRE RMS %.3f mm measured, %.3f mm predicted, %.3f mm by "
               "Fitzpatrick's formula (mean e^T C^-1 e / 3 = %.2f on this one scene)"
               % (t["rms_error_mm"], t["rms_predicted_mm"], t["rms_fitzpatrick_mm"],
                  t["mean_mahalanobis2_per_dof"]),
        "triangulated": "the %d markers triangulated by `carmba triangulate` from the object "
                        "views' pixels within %.2f sigma of their true positions (3-dof "
                        "Mahalanobis; RMS error %.3f mm)" % (len(points), max(sigmas), rms),
    }


# ---- Calibration from simulated images against their truth ------------------------------------

def against_truth(report_path):
    """From a calibration report's section "Against the truth": the intrinsics' errors in sigmas
    (name -> z) and the whole image's largest projection difference over its sigma."""
    with open(report_path) as fh:
        text = fh.read()
    line = re.search(r"^Intrinsics against the truth: (.*)$", text, re.M).group(1)
    z = {m.group(1): float(m.group(2)) for m in re.finditer(r"(\w+) (-?[\d.]+) sigma", line)}
    row = re.search(r"^\| whole image \|([^\n]*)$", text, re.M).group(1).split("|")
    return z, float(row[3])


def calib_figures(out):
    scenes = [("thesis scene", "calibration_calib_free"),
              ("7x6 pincushion scene", "calibration_pincushion_calib_free")]
    intr, proj = [], []
    for name, run in scenes:
        z, worst = against_truth(os.path.join(out, run, "report.md"))
        intr.append((max(abs(z[k]) for k in ("fx", "fy", "cx", "cy")), name))
        proj.append("%.2f" % worst)
    return {
        "intrinsics": "fx, fy, cx, cy within %.2f sigma of the truth on the %s and within %.2f "
                      "sigma on the %s" % (intr[0] + intr[1]),
        "projection": "the true projection within %s sigma over the image" % " / ".join(proj),
        # configs/calib.yaml (`distortion: auto`): the pixel sigma from the full model's residuals
        "auto_sigma_px": "%.4f" % load_json(os.path.join(out, "calibration_calib/camera.json"))
        ["sigma_px"],
    }


# ---- Metal spheres in a real CT ----------------------------------------------------------------

def read_fiducials(path):
    """The centres (mm) and covariances (mm^2) of a `carmba ct-fiducials` CSV, by id."""
    head, lines = csv_lines(path)
    out = {}
    for line in lines:
        r = dict(zip(head, line))
        c = {k: float(r["cov_" + k]) for k in ("xx", "xy", "xz", "yy", "yz", "zz")}
        out[r["id"]] = ([float(r[k]) for k in ("x_mm", "y_mm", "z_mm")],
                        [[c["xx"], c["xy"], c["xz"]], [c["xy"], c["yy"], c["yz"]],
                         [c["xz"], c["yz"], c["zz"]]])
    return out


def simct_figures(out):
    """`carmba ct-fiducials` on the simulated joint scene's CT against the scene's truth."""
    found = read_fiducials(os.path.join(out, "out/sim/joint/fiducials.csv"))
    truth = {str(m["id"]): [m["x_mm"], m["y_mm"], m["z_mm"]]
             for m in load_json(os.path.join(out, "out/sim/joint/truth.json"))["ct_markers"]}
    errors = {k: [a - b for a, b in zip(p, truth[k])] for k, (p, _) in found.items()}
    nees = [mahalanobis(errors[k], C) ** 2 / 3 for k, (_, C) in found.items()]
    return {
        "centres": "the %d centres within %.4f mm of the truth, mean e^T C^-1 e / 3 = %.2f"
                   % (len(found), max(math.sqrt(sum(x * x for x in e)) for e in errors.values()),
                      sum(nees) / len(nees)),
    }


def realct_figures(out):
    ref = read_fiducials(os.path.join(out, "real_ct/fiducials_6mm.csv"))
    sigmas = [math.sqrt((C[0][0] + C[1][1] + C[2][2]) / 3) for _, C in ref.values()]
    moved = 0.0
    for d in (5, 7, 8):
        other = read_fiducials(os.path.join(out, "real_ct/fiducials_%dmm.csv" % d))
        for p, _ in other.values():
            moved = max(moved, min(math.dist(p, q) for q, _ in ref.values()))
    return {
        "found": "%d of 4 spheres found" % len(ref),
        "sigma": "centre sigma %.2f-%.2f mm (RMS per axis)" % (min(sigmas), max(sigmas)),
        "rough_diameters": "nominal 5, 7 or 8 mm give the same centres within %.3f mm" % moved,
    }


# ---- C-arm flex: the rendered flexing scene ------------------------------------------------------

def solve_linear(A, b):
    """x with A x = b (Gaussian elimination with partial pivoting; small dense systems)."""
    n = len(b)
    M = [list(map(float, row)) + [float(b[i])] for i, row in enumerate(A)]
    for i in range(n):
        p = max(range(i, n), key=lambda r: abs(M[r][i]))
        M[i], M[p] = M[p], M[i]
        for r in range(n):
            if r != i:
                k = M[r][i] / M[i][i]
                for c in range(i, n + 1):
                    M[r][c] -= k * M[i][c]
    return [M[i][n] / M[i][i] for i in range(n)]


def pose_nees(view):
    """d^T C^-1 d of an object view's pose parameters [rvec, t] against its truth."""
    e, t = view["cam_from_object"], view["truth"]
    d = [a - b for a, b in zip(e["rvec"] + e["t_mm"], t["rvec"] + t["t_mm"])]
    x = solve_linear(view["covariance_6x6"], d)
    return sum(a * b for a, b in zip(d, x))


def flex_figures(out):
    runs = {m: load_json(os.path.join(out, "flex_%s/result.json" % m))
            for m in ("shared", "per_group", "smooth")}
    figures = held_out_d2(runs["smooth"]["model_selection"])
    for m in ("shared", "smooth"):
        nees = [pose_nees(v) for v in runs[m]["views"] if v["kind"] == "object" and "truth" in v]
        figures["pose_nees_" + m] = "%.1f / %.1f" % (sum(nees) / len(nees), max(nees))
        figures["num_object_views"] = "%d views" % len(nees)
    worst = [max(abs(x) for x in v["intrinsics_error_sigma"].values())
             for v in runs["smooth"]["views"] if "intrinsics_error_sigma" in v]
    figures["worst_intrinsics_smooth"] = "%.2f" % max(worst)
    figures["num_views"] = "%d views" % len(worst)
    return figures


def clutter_pose_figures(out):
    """`carmba pose` on the clutter scene: the cone-beam shadow offsets it evaluated."""
    s = load_json(os.path.join(out, "pose_clutter/result.json"))["shadow_correction"]
    return {"shadow": "at most %s px (%.2f sigma): %s" % (
        sci(s["max_px"]), s["max_sigma"],
        "subtracted" if s["applied"] else "evaluated, not applied")}


SECTIONS = {"thesis": thesis_figures, "clutterpose": clutter_pose_figures,
            "joint": joint_figures, "mrcal": mrcal_figures,
            "tre": tre_figures,
            "calib": calib_figures, "track": track_figures, "simct": simct_figures,
            "realct": realct_figures, "flex": flex_figures}


# ---- Figures the tests measure -----------------------------------------------------------------

# (test executable, gtest filter): each test records its figures as properties named
# "figure.SECTION.NAME" (tests/figures.h), read here from its XML output.
TEST_RUNS = [("carmba_ba_test",
              "Consider.*:Whitening2x2.*:*VarianceComponentsMonteCarlo.*:BaMonteCarlo.*:"
              "SphereShadow*:ShadowCorrection.*"),
             ("carmba_analysis_test",
              "RelativePose*:Triangulation*:LeaveOne*:LensModels.*:FlexMonteCarlo.*"),
             ("carmba_joint_test", "JointTwoStep.*"),
             ("carmba_core_test", "PoseSolver.MonteCarlo*"),
             ("carmba_calib_test", "SceneMonteCarlo.*:CalibrateTest.PlateSphereShadows*"),
             ("carmba_ct_test", "RealCt.*:SaturatedMarker.*:MarkerDetection.ThesisCt*:"
              "SkullBeads.Default*:SkullBeads.MetalStreaks*"),
             ("carmba_detect_test", "ShadowCentre*:MarkerBlobs.CovarianceAgreesWithMonteCarlo:"
              "MarkerBlobs.TheBlurPullOnASlopingBackgroundIsRemoved:"
              "SimulatedSceneDetection.SystematicErrorWellBelowTheNoise:DetectionRecall.*:"
              "EdgeAccuracy.*:MarkerViews.ClutterScene*:MarkerViews.MultiFrame*:"
              "MarkerCorrespondence.TwoSpurious*"),
             ("carmba_io_test", "DicomXray.ReadTimeOf512x512Frame:DicomXray.GdcmExample*"),
             ("carmba_track_test", "Track.Synthetic*"),
             ("carmba_export_test", "RtkGeometry.*:PlastimatchGeometry.*:Undistort.*"),
             ("carmba_cli_test", "TriangulateCli.ThesisMarkersInTheCtFrame:DrrExportE2e.*:"
              "PoseCli.WritesObservationsOverlaysAndTheBundleAdjustment")]


# The same tests again on other seeds (the environment variable each test reads; seeds never
# used while writing the test, unless the template says otherwise), their figures under another
# section: (executable, filter, environment, section the test records, section in the template).
UNSEEN_TEST_RUNS = [("carmba_ba_test", "*VarianceComponentsMonteCarlo.*",
                     {"CARMBA_VC_SEED": "777000", "CARMBA_VC_TRIALS": "1000"}, "vc", "vc_unseen"),
                    ("carmba_analysis_test", "LensModels.RecommendedModelIsWithinThreeSigmaOverSeeds",
                     {"CARMBA_LENS_SEED": "880000"}, "lens", "lens_unseen"),
                    ("carmba_detect_test", "ShadowCentre*",
                     {"CARMBA_SHADOW_SEED": "123456", "CARMBA_SHADOW_SPHERES": "100"}, "shadow",
                     "shadow_unseen"),
                    ("carmba_detect_test", "DetectionRecall.*", {"CARMBA_RECALL_SEED": "50000"},
                     "detrecall", "detrecall_unseen"),
                    ("carmba_ct_test", "SaturatedMarker.FoundWith*",
                     {"CARMBA_SATURATED_SEED": "1234", "CARMBA_SATURATED_NOISE_SEED": "90000"},
                     "saturated", "saturated_unseen"),
                    ("carmba_track_test", "Track.Synthetic*",
                     {"CARMBA_TRACK_SEED": "901", "CARMBA_TRACK_TRIALS": "200"}, "tracksyn",
                     "tracksyn_unseen"),
                    # Seeds 7-24 were run by hand while the bead detector was developed.
                    ("carmba_ct_test", "SkullBeads.Default*:SkullBeads.MetalStreaks*",
                     {"CARMBA_SKULL_SEEDS": ",".join(str(k) for k in range(7, 25))}, "skull",
                     "skull_more")]


def run_test_figures(tests_dir, tmp, exe, gfilter, env=None):
    """The figures one test executable records under `gfilter` (with `env` added), and the names
    of its tests that failed."""
    xml = os.path.join(tmp, exe + ".xml")
    subprocess.run([os.path.join(tests_dir, exe), "--gtest_filter=" + gfilter,
                    "--gtest_output=xml:" + xml], stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL, env=dict(os.environ, **(env or {})))
    if not os.path.exists(xml):
        sys.exit("results.py: %s --gtest_filter='%s' wrote no results" % (exe, gfilter))
    figures, failed = {}, []
    root = ElementTree.parse(xml)
    for prop in root.iter("property"):
        name = prop.get("name")
        if name.startswith("figure."):
            figures[name[len("figure."):]] = prop.get("value")
    for case in root.iter("testcase"):
        if case.find("failure") is not None:
            failed.append("%s.%s" % (case.get("classname"), case.get("name")))
    return figures, failed


def test_figures(tests_dir, tmp):
    """The tests' figures. A test of TEST_RUNS that fails stops the measurement; one of
    UNSEEN_TEST_RUNS says in its section's `verdict` whether the test's own bounds held there."""
    figures = {}
    for exe, gfilter in TEST_RUNS:
        found, failed = run_test_figures(tests_dir, tmp, exe, gfilter)
        if failed:
            sys.exit("results.py: %s failed: %s" % (exe, ", ".join(failed)))
        figures.update(found)
    for exe, gfilter, env, section, renamed in UNSEEN_TEST_RUNS:
        found, failed = run_test_figures(tests_dir, tmp, exe, gfilter, env)
        for key, value in found.items():
            if key.startswith(section + "."):
                figures[renamed + key[len(section):]] = value
        figures[renamed + ".verdict"] = (
            "the test's own bounds hold there" if not failed else
            "the test's own bounds do NOT hold there (%s)" % ", ".join(failed))
    return figures


# ---- Marker recall on randomised scenes: every seed set, two processes at a time -------------

RECALL_SCENES = 16
# The sets the detector and the labelling were developed on, then the sets never used while
# changing them (the same scenes' generator, other seeds).
RECALL_RUNS = (("xa", "MarkerRecall.XaFrame*", range(1, 9)),
               ("realct", "MarkerRecall.RealCt*", range(1, 17)),
               ("xa_unseen", "MarkerRecall.XaFrame*", range(9, 17)),
               ("realct_unseen", "MarkerRecall.RealCt*", range(17, 33)),
               ("realct_positioner", "MarkerRecall.RealCt*", range(1, 33)))
# The real-CT sets again with the C-arm positioner's error the DICOM angles do not record.
RECALL_POSITIONER = {"CARMBA_MARKER_RECALL_POSITIONER_MM": "2",
                     "CARMBA_MARKER_RECALL_POSITIONER_DEG": "0.5"}
RECALL_COMMAND = ("CARMBA_MARKER_RECALL_SEED=S CARMBA_MARKER_RECALL_SCENES=%d "
                  "build/tests/carmba_detect_test --gtest_filter='MarkerRecall.XaFrame*' (or "
                  "'MarkerRecall.RealCt*')" % RECALL_SCENES)
RECALL_FIELDS = ("scenes", "views", "views_skipped", "expected", "correct", "wrong", "beads",
                 "overlap_labelled", "overlapping", "off_centre", "views_lost")


def recall_run(tests_dir, tmp, kind, gfilter, seed_set):
    """The figures one set's run records (the test fails when a set misses its bar: kept)."""
    xml = os.path.join(tmp, "recall_%s_%d.xml" % (kind, seed_set))
    env = dict(os.environ, CARMBA_MARKER_RECALL_SEED=str(seed_set),
               CARMBA_MARKER_RECALL_SCENES=str(RECALL_SCENES),
               **(RECALL_POSITIONER if kind.endswith("_positioner") else {}))
    subprocess.run([os.path.join(tests_dir, "carmba_detect_test"), "--gtest_filter=" + gfilter,
                    "--gtest_output=xml:" + xml], env=env, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    props = {p.get("name"): p.get("value") for p in ElementTree.parse(xml).iter("property")}
    key = "figure.recall.%s.set%d" % (kind.split("_")[0], seed_set)  # the test's anatomy name
    if key not in props:
        sys.exit("results.py: the recall run of %s set %d recorded no figures" % (kind, seed_set))
    counts = dict(zip(RECALL_FIELDS, map(int, props[key].split())))
    missed = {}
    for item in filter(None, props.get(key + ".missed", "").split(";")):
        why, n = item.rsplit(":", 1)
        missed[why] = int(n)
    if key + ".nees" not in props:
        sys.exit("results.py: the recall run of %s set %d recorded no NEES" % (kind, seed_set))
    (n, m2_sum, beyond, radial_sum, radial_sum2, widened_n,
     widened_sum) = map(float, props[key + ".nees"].split())
    counts.update(nees_n=int(n), nees_sum=m2_sum, nees_beyond=int(beyond),
                  radial_sum=radial_sum, radial_sum2=radial_sum2, nees_widened_n=int(widened_n),
                  nees_widened_sum=widened_sum)
    return counts, missed


def centre_errors(rows):
    """The labelled centres' NEES per dof, share beyond chi2(2) at 1e-3, mean radial error with
    its standard error, and the NEES of the centres widened for their core-to-whole shift against
    the others', over the sets' counts."""
    n = sum(c["nees_n"] for _, c in rows)
    if n < 2:
        return "-", "-", "-", "-"
    total = lambda key: sum(c[key] for _, c in rows)
    mean = total("radial_sum") / n
    var = max(0.0, total("radial_sum2") / n - mean * mean)
    wn, ws = total("nees_widened_n"), total("nees_widened_sum")
    split = "%.2f over the %d widened (%s), %.2f over the others" % (
        ws / (2.0 * wn) if wn else 0.0, wn, pct(wn, n),
        (total("nees_sum") - ws) / (2.0 * (n - wn)) if n > wn else 0.0)
    return ("%.2f over %d centres" % (total("nees_sum") / (2.0 * n), n),
            "%.2f %%" % (100.0 * total("nees_beyond") / n),
            "%+.4f +- %.4f px" % (mean, math.sqrt(var / (n - 1))), split)


def pct(part, whole):
    return "%.1f %%" % (100.0 * part / whole) if whole else "-"


def recall_table(rows):
    """rows: [(set, counts)] -> the markdown table with a row for all sets together, and the
    totals."""
    lines = ["| seed set | labelled correctly | wrong labels | centres off their covariance | "
             "beads labelled | overlapped markers labelled | views skipped (with >= 4 markers "
             "apart) |",
             "|---|---|---|---|---|---|---|"]
    total = {k: sum(c[k] for _, c in rows) for k in RECALL_FIELDS}
    for seed_set, c in rows + [("**all**", total)]:
        lines.append("| %s | %d of %d (%s) | %d | %d | %d | %d of %d | %d of %d (%d) |" % (
            seed_set, c["correct"], c["expected"], pct(c["correct"], c["expected"]), c["wrong"],
            c["off_centre"], c["beads"], c["overlap_labelled"], c["overlapping"],
            c["views_skipped"], c["views"], c["views_lost"]))
    return "\n".join("  " + line for line in lines), total  # indented: inside a list item


def recall_figures(tests_dir, tmp):
    jobs = [(kind, gfilter, s) for kind, gfilter, sets in RECALL_RUNS for s in sets]
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = list(pool.map(lambda j: recall_run(tests_dir, tmp, *j), jobs))
    fig = {"command": "`%s`" % RECALL_COMMAND, "scenes": str(RECALL_SCENES)}
    for kind, _, sets in RECALL_RUNS:
        rows, missed = [], {}
        for (k, _, s), (counts, why) in zip(jobs, results):
            if k == kind:
                rows.append((s, counts))
                for w, n in why.items():
                    missed[w] = missed.get(w, 0) + n
        table, total = recall_table(rows)
        summary = (
            "%d of %d (%s) labelled correctly, %d wrong, %d beads labelled, %d of %d views skipped "
            "(%d of them with >= 4 markers apart)" % (
                total["correct"], total["expected"], pct(total["correct"], total["expected"]),
                total["wrong"], total["beads"], total["views_skipped"], total["views"],
                total["views_lost"]))
        if kind.startswith("realct"):
            fig[kind + "_summary"] = summary
        if kind.endswith("_positioner"):  # results.md gives the summary only
            continue
        fig[kind + "_sets"] = "%d-%d" % (min(sets), max(sets))
        fig[kind + "_table"] = table
        fig[kind + "_pct"] = pct(total["correct"], total["expected"])
        fig[kind + "_at_99"] = str(sum(1 for _, c in rows if c["correct"] >= 0.99 * c["expected"]))
        fig[kind + "_lost"] = "%d of %d" % (total["views_lost"], total["views_skipped"])
        (fig[kind + "_nees"], fig[kind + "_beyond"], fig[kind + "_radial"],
         fig[kind + "_nees_split"]) = centre_errors(rows)
        fig[kind + "_missed"] = "; ".join(
            "%s %d" % (w, n) for w, n in sorted(missed.items(), key=lambda wn: (-wn[1], wn[0])))
    return {"recall." + k: v for k, v in fig.items()}


# ---- Benchmarks: carmba_bench on one core, medians of 3, in one run ----------------------------

# The benchmarks results.md states, with the reference tools run in the same process and run
# (mrcal's C API). Not BM_CalibOpenCv (more than a minute at 200 views).
BENCH_FILTER = ("BM_Calib(Carmba|MrcalC|Engine)|BM_Joint|BM_EngineOneView|BM_Detect|BM_Track|"
                "BM_Marker|BM_Ct")
BENCH_REPETITIONS = 3
BENCH_ARGS = ["--benchmark_filter=" + BENCH_FILTER,
              "--benchmark_repetitions=%d" % BENCH_REPETITIONS]
# BENCH_ARGS as a reader types them (results.md states it).
BENCH_COMMAND = ("taskset -c 0 build/tests/carmba_bench --benchmark_filter='%s' "
                 "--benchmark_repetitions=%d" % (BENCH_FILTER, BENCH_REPETITIONS))
UNIT_S = {"ns": 1e-9, "us": 1e-6, "ms": 1e-3, "s": 1.0}


def bench_medians(tests_dir, tmp):
    """{benchmark name: (median CPU time in s, its counters)}."""
    out = os.path.join(tmp, "bench.json")
    exe = os.path.join(tests_dir, "carmba_bench")
    # Built here: carmba_bench is not in `all`, and a stale one measured the sources of an older
    # commit (and hid that it no longer compiled).
    build_dir = os.path.dirname(os.path.abspath(tests_dir))
    if subprocess.run(["cmake", "--build", build_dir, "--target", "carmba_bench"],
                      stdout=subprocess.DEVNULL).returncode != 0 or not os.path.exists(exe):
        sys.exit("results.py: building %s failed (cmake --build %s --target carmba_bench)"
                 % (exe, build_dir))
    subprocess.run(["taskset", "-c", "0", exe] + BENCH_ARGS +
                   ["--benchmark_report_aggregates_only=true", "--benchmark_out=" + out,
                    "--benchmark_out_format=json"],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    medians = {}
    for b in load_json(out)["benchmarks"]:
        if b.get("aggregate_name") == "median":
            medians[b["run_name"]] = (b["cpu_time"] * UNIT_S[b["time_unit"]], b)
    return medians


def ms(seconds):
    """Milliseconds to 3 significant digits (0.0123 s -> 12.3)."""
    v = seconds * 1e3
    return "%.3g" % v if v < 1000 else "%.0f" % v


def bench_figures(tests_dir, tmp):
    m = bench_medians(tests_dir, tmp)
    t = lambda name: m[name][0]
    fig = {"command": "`%s`" % BENCH_COMMAND}
    for n in (16, 200, 1000):
        mrcal = t("BM_CalibMrcalC/%d" % n)
        fig["mrcal_%d" % n] = ms(mrcal)
        for key, name in (("engine_lm", "BM_CalibEngine/%d/1"), ("engine_ceres", "BM_CalibEngine/%d/0"),
                          ("calibrate_lm", "BM_CalibCarmba/%d/0"),
                          ("calibrate_ceres", "BM_CalibCarmba/%d/1")):
            fig["%s_%d" % (key, n)] = ms(t(name % n))
            fig["%s_%d_ratio" % (key, n)] = "%.2fx" % (t(name % n) / mrcal)
    fig["joint_solve"] = ms(t("BM_JointSolveCovarianceBudget"))
    apriori = t("BM_JointSelfChecks/0")
    fig["joint_apriori"] = ms(apriori)
    for arg, key in ((1, "per_group"), (2, "per_group_distortion")):
        v = t("BM_JointSelfChecks/%d" % arg)
        fig["joint_%s" % key] = ms(v)
        fig["joint_%s_ratio" % key] = "%.2fx" % (v / apriori)
    fig["joint_distortion_selection"] = ms(t("BM_JointDistortionSelection"))
    fig["engine_one_view_us"] = "%.0f" % (t("BM_EngineOneView") * 1e6)
    fig["detect_thesis"] = ms(t("BM_DetectThesis408x408"))
    fig["detect_pincushion"] = ms(t("BM_DetectPincushion512x512x16bit"))
    fig["marker_detect_label"] = ms(t("BM_MarkerDetectAndLabel"))
    fig["marker_detect_only"] = ms(t("BM_MarkerDetectOnly"))
    fig["ct_simulate"] = "%.1f s" % t("BM_CtSimulateThesis512x512x120/iterations:3")
    fig["ct_read_segment"] = ms(t("BM_CtReadAndSegmentThesis512x512x120/iterations:5"))
    track_s, track = m["BM_TrackWrist"]
    fig["track_s"] = "%.2f" % track_s
    for key in ("detect_s", "match_s", "ba_s"):
        share = track[key] / track_s
        fig["track_" + key[:-2]] = "%s ms (%.1f %%)" % (ms(track[key]), 100 * share)
    return {"bench." + k: v for k, v in fig.items()}


# ---- Runs beyond the golden outputs: two studies, calibrations with the mrcal and OpenCV
# cross-checks, the rendered rigid C-arm, the clutter scene's pose NEES over seeds --------------

def run_carmba(binary, *args):
    subprocess.run([binary] + list(args), check=True, cwd=ROOT, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)


def run_study(binary, tmp, name):
    """`carmba study` on configs/studies/NAME.yaml; its output directory."""
    out = os.path.join(tmp, "study_" + name)
    run_carmba(binary, "study", "--study", os.path.join(ROOT, "configs/studies/%s.yaml" % name),
               "--out", out, "--no-plots")
    return out


# A row of a study summary's error budget: | problem | config | sweep value | quantity | cells |
STUDY_BUDGET_ROW = re.compile(r"\| \w+ \| \w+ \| (\d+) \| (v0_\w+) \| (.*) \|$")


def plate_views_figures(binary, tmp):
    """configs/studies/joint_plate_views.yaml: the first object view's variance shares per source
    (summary.md's error budget) against the number of plate views."""
    shares = {}
    with open(os.path.join(run_study(binary, tmp, "joint_plate_views"), "summary.md")) as fh:
        for line in fh:
            m = STUDY_BUDGET_ROW.match(line.strip())
            if m:
                shares[(m.group(2), int(m.group(1)))] = {
                    s: int(p) for s, p in re.findall(r"(\w+) [-\d.e+]+ \((\d+) %\)", m.group(3))}
    views = sorted({v for _, v in shares})
    t = lambda v: shares[("v0_translation_mm", v)]
    r = lambda v: shares[("v0_rotation_deg", v)]
    rows = ["  | plate views | %s |" % " | ".join(str(v) for v in views),
            "  |---|%s" % ("---|" * len(views)),
            "  | plate pixels | %s |" % " | ".join("%d %%" % t(v)["plate_pixels"] for v in views),
            "  | CT localisation | %s |" % " | ".join("%d %%" % t(v)["ct"] for v in views)]
    # The rotation: the first number of plate views from which the CT is its largest source.
    ct_first = lambda v: r(v)["ct"] == max(r(v).values())
    start = next(i for i in range(len(views)) if all(ct_first(v) for v in views[i:]))
    ct_rot = [r(v)["ct"] for v in views[start:]]
    cross = next(i for i, v in enumerate(views) if t(v)["ct"] > t(v)["plate_pixels"])
    return {"jpv.table": "\n".join(rows),
            "jpv.rotation_ct": "from %d plate views on (%d-%d %%)" % (views[start], min(ct_rot),
                                                                       max(ct_rot)),
            "jpv.crossover": "between %d and %d" % (views[cross - 1], views[cross])}


FLEX_MODELS = ("shared", "per_group", "smooth")


def flex_study_figures(binary, tmp):
    """configs/studies/flex.yaml: the rows of results.md's flex table that the study measures."""
    head, lines = csv_lines(os.path.join(run_study(binary, tmp, "flex"), "summary.csv"))
    v = {}
    for line in lines:
        r = dict(zip(head, line))
        if r["kind"] == "value":
            v[(r["problem"], float(r["flex_scale"]), r["metric"])] = float(r["mean"])
    def row(label, cell):
        return "| %s | %s |" % (label, " | ".join(cell(m) for m in FLEX_MODELS))
    flexing = lambda metric, fmt: lambda m: fmt % v[(m, 1.0, metric)]
    picks = lambda scale: lambda m: "%.0f %%" % (100 * v[("selection", scale,
                                                          "recommended_" + m)])
    rows = [
        row("per-view intrinsics NEES (fx fy cx cy; 4 if honest), calibrated angles, study",
            flexing("intrinsics_nees_calibrated", "%.2f")),
        row("per-view intrinsics NEES, in-between object views, study",
            flexing("intrinsics_nees_between", "%.2f")),
        row("per-view fx..cy within 3 sigma, study",
            lambda m: "%.1f %%" % (100 * v[(m, 1.0, "intrinsics_within_3_sigma")])),
        row("object pose NEES (6 if honest), at calibrated angles, study",
            flexing("pose_nees_at", "%.2f")),
        row("object pose NEES, in-between angles, study", flexing("pose_nees_between", "%.2f")),
        row("rigid C-arm: intrinsics NEES calibrated / pose NEES in-between, study",
            lambda m: "%.2f / %.2f" % (v[(m, 0.0, "intrinsics_nees_calibrated")],
                                       v[(m, 0.0, "pose_nees_between")])),
        row("selection picks it, flexing (20 seeded scenes)", picks(1.0)),
        row("selection picks it, rigid (20 seeded scenes)", picks(0.0))]
    return {"flexstudy.rows": "\n".join(rows)}


def held_out_d2(selection):
    """Each intrinsics model's mean held-out Mahalanobis d2, the recommended one marked."""
    d2 = {sc["model"]: sc["held_out_mahalanobis_d2_mean"] for sc in selection["scores"]}
    return {"d2_" + m: "%.2f%s" % (d2[m], " (recommended)" if selection["recommended"] == m
                                   else "") for m in FLEX_MODELS}


def rigid_flex_figures(binary, tmp):
    """configs/scenes/flex_joint_rigid.yaml rendered, its CT localised, solved as
    problems/flex_joint_smooth.yaml reads it (the problem file's paths, in a scratch tree)."""
    root = os.path.join(tmp, "rigid")
    sim = os.path.join(root, "out/sim/flex")
    os.makedirs(os.path.join(root, "problems"))
    run_carmba(binary, "simulate", "--scene", "configs/scenes/flex_joint_rigid.yaml", "--out", sim)
    run_carmba(binary, "ct-fiducials", "--dicom", os.path.join(sim, "ct"), "--model",
               "data/thesis/markers_table_5_1.csv", "--model-columns", "x_o,y_o,z_o",
               "--diameter-mm", "2", "--expected", "9", "--out",
               os.path.join(sim, "fiducials.csv"))
    problem = os.path.join(root, "problems/flex_joint_smooth.yaml")
    shutil.copyfile(os.path.join(ROOT, "problems/flex_joint_smooth.yaml"), problem)
    out = os.path.join(root, "solve")
    run_carmba(binary, "solve", "--problem", problem, "--config", "configs/joint_radial.yaml",
               "--out", out, "--no-plots", "--no-mrcal")
    selection = load_json(os.path.join(out, "result.json"))["model_selection"]
    return {"flexrigid." + k: v for k, v in held_out_d2(selection).items()}


# Rows of a calibration report's cross-check tables (report/calibration_report.cc).
CROSS_RMS = re.compile(r"^\| RMS carmba vs mrcal \| \S+ vs \S+ px \(([-\d.]+) %\)")
CROSS_PROJ = re.compile(r"^\| projection difference \(rms / max[^|]*no transform\) \| "
                        r"([\d.]+) / ([\d.]+) px")
CROSS_FIT = re.compile(r"^\| projection difference after mrcal's fitted rotation \([^|]*: "
                       r"([\d.]+) px\) \| ([\d.]+) / ([\d.]+) px")
CROSS_SIGMA = re.compile(r"^\| sigma (?:fx|fy|cx|cy) carmba vs mrcal \| \S+ vs \S+ \(([-\d.]+) %\)")


def cross_check_tables(report):
    """The mrcal cross-check tables of a calibration report, in order (like with like first when
    the config holds intrinsics, then all nine free): [{rms, proj, proj_max, fit, fit_max,
    floor, sigma}]."""
    tables = []
    with open(report) as fh:
        for line in fh:
            if CROSS_RMS.match(line):
                tables.append({"rms": CROSS_RMS.match(line).group(1), "sigma": 0.0})
            elif tables and CROSS_PROJ.match(line):
                tables[-1]["proj"], tables[-1]["proj_max"] = CROSS_PROJ.match(line).groups()
            elif tables and CROSS_FIT.match(line):
                (tables[-1]["floor"], tables[-1]["fit"],
                 tables[-1]["fit_max"]) = CROSS_FIT.match(line).groups()
            elif tables and CROSS_SIGMA.match(line):
                tables[-1]["sigma"] = max(tables[-1]["sigma"],
                                          abs(float(CROSS_SIGMA.match(line).group(1))))
    return tables


def cross_check_text(t):
    return ("RMS %s %%, projection difference %s px in the shared frame (%s px after mrcal's "
            "fitted rotation, whose own floor is %s px), the sigmas of fx, fy, cx, cy within "
            "%.2f %%" % (t["rms"].lstrip("-"), t["proj"], t["fit"], t["floor"], t["sigma"]))


OPENCV_LINE = re.compile(r"Projection difference carmba vs OpenCV \(same frame, no transform\): "
                         r"rms ([\d.]+) px, max ([\d.]+) px")


def calib_cross_check_figures(binary, tmp):
    """`carmba calibrate` with its mrcal cross-check on the demo's simulated plate (three configs),
    and with mrcal and OpenCV on OpenCV's chessboard photos (problems/calib_opencv_left.yaml)."""
    sim = os.path.join(tmp, "calibration_sim")
    run_carmba(binary, "simulate", "--scene", "configs/scenes/thesis_calibration.yaml", "--out",
               sim)
    figures = {}
    for config in ("calib_radial", "calib_thesis", "calib_free"):
        out = os.path.join(tmp, "cross_" + config)
        run_carmba(binary, "calibrate", "--images", os.path.join(sim, "*.png"), "--pattern",
                   "circles", "--rows", "5", "--cols", "5", "--spacing-mm", "20",
                   "--sphere-diameter-mm", "3.06", "--config", "configs/%s.yaml" % config,
                   "--out", out, "--no-plots", "--no-opencv")
        tables = cross_check_tables(os.path.join(out, "report.md"))
        figures["calibx." + config] = cross_check_text(tables[0])
        if len(tables) > 1:
            figures["calibx.%s_all_free" % config] = "%s px" % tables[1]["proj"]
    out = os.path.join(tmp, "cross_opencv_left")
    run_carmba(binary, "calibrate", "--problem", "problems/calib_opencv_left.yaml", "--config",
               "configs/calib_free.yaml", "--out", out, "--no-plots")
    with open(os.path.join(out, "report.md")) as fh:
        report = fh.read()
    m = OPENCV_LINE.search(report)
    if not m:
        sys.exit("results.py: the OpenCV cross-check of calib_opencv_left printed no projection "
                 "difference")
    mrcal = cross_check_tables(os.path.join(out, "report.md"))[0]
    figures["calibx.opencv_left"] = (
        "carmba and mrcal: projection difference %s px, RMS %s %%; carmba and "
        "`cv::calibrateCamera`: projection difference %s px (largest %s px)" % (
            mrcal["proj"], mrcal["rms"].lstrip("-"), m.group(1), m.group(2)))
    return figures


CLUTTER_SEEDS = "1,2,3,4,5,6,7,8"
# The randomised variant: anatomy and geometry drawn per seed, on 32 seeds.
CLUTTER_RANDOM_SEEDS = ",".join(str(s) for s in range(1, 33))
CLUTTER_NEES = re.compile(r"full: pose NEES per dof ([\d.]+) over (\d+) views \((\d+) seeds\), "
                          r"mean sigma0 ([\d.]+)")
CLUTTER_ISOTROPIC = re.compile(r"isotropic: pose NEES per dof ([\d.]+)")
CLUTTER_APRIORI = re.compile(r"apriori: pose NEES per dof ([\d.]+)")
CLUTTER_MEANS = re.compile(r"all views: (.*)")
CLUTTER_RMS = re.compile(r"full: RMS error over the views: rotation ([\d.]+) deg, translation "
                         r"([\d.]+) mm")


def run_clutter_script(binary, out, seeds, modes=None):
    """scripts/clutter_pose_nees.py's printout over `seeds` (with its modes, if any)."""
    args = [sys.executable, os.path.join(ROOT, "scripts/clutter_pose_nees.py"), binary, ROOT, out,
            seeds] + ([modes] if modes else [])
    text = subprocess.run(args, check=True, capture_output=True, text=True).stdout
    found = [r.search(text) for r in (CLUTTER_NEES, CLUTTER_ISOTROPIC, CLUTTER_APRIORI,
                                      CLUTTER_MEANS, CLUTTER_RMS)]
    if not all(found):
        sys.exit("results.py: scripts/clutter_pose_nees.py printed no figures")
    return found


def clutter_figures(binary, tmp):
    """scripts/clutter_pose_nees.py over the clutter scene's seeds: the pose NEES of `carmba pose`'s
    observations solved with their full 2x2 covariances, on the shipped scene and with its anatomy
    and geometry drawn per seed."""
    m, iso, apriori, means, rms = run_clutter_script(
        binary, os.path.join(tmp, "clutter_nees"), CLUTTER_SEEDS)
    z = dict(zip(means.group(1).split()[0::2], means.group(1).split()[1::2]))
    rm, _, rapriori, _, rrms = run_clutter_script(
        binary, os.path.join(tmp, "clutter_random"), CLUTTER_RANDOM_SEEDS,
        "random-anatomy,random-geometry")
    return {"clutter.command": "`python3 scripts/clutter_pose_nees.py build/bin/carmba . /tmp/cn "
                               "%s`" % CLUTTER_SEEDS,
            "clutter.nees": "%s over %s views (%s seeds)" % m.groups()[:3],
            "clutter.sigma0": m.group(4),
            "clutter.isotropic": iso.group(1),
            "clutter.apriori": apriori.group(1),
            "clutter.means": "tz %s and rx %s" % (z["tz"], z["rx"]),
            "clutter.rms": "%s deg in rotation and %s mm in translation" % rms.groups(),
            "clutter.random_command": "`python3 scripts/clutter_pose_nees.py build/bin/carmba . "
                                      "/tmp/cnr 1,2,...,32 random-anatomy,random-geometry`",
            "clutter.random_nees": "%s over %s views (%s seeds)" % rm.groups()[:3],
            "clutter.random_sigma0": rm.group(4),
            "clutter.random_apriori": rapriori.group(1),
            "clutter.random_rms": "%s deg in rotation and %s mm in translation" % rrms.groups()}


# ---- Measure and render ---------------------------------------------------------------------

# ---- The calibration plate detector's radial bias against the simulator's truth ---------------

# (scene, what the table says of it); the intensifier scene also with its anatomy cut from other
# places of the XA frame (imaging.background.crop_center) and without it.
PLATE_BIAS_SCENES = (("thesis_calibration", "3.06 mm, barrel"),
                     ("calib_7x6_pincushion", "2.5 mm, pincushion"),
                     ("calib_7x6_intensifier", "2.5 mm, pincushion, intensifier effects"))
INTENSIFIER_CROPS = ((0.3, 0.4), (0.6, 0.6), (0.45, 0.7), (0.7, 0.35))
PLATE_BIAS_LINE = re.compile(r"(\d+) centres: mean radial error ([-+][\d.]+) \+- ([\d.]+) px; "
                             r"predicted shadow offset ([-+][\d.]+) .*left after subtracting it "
                             r"([-+][\d.]+) \+- ([\d.]+) px")


def plate_bias(binary, scene_yaml, tmp, name):
    """scripts/plate_radial_bias.py on `carmba simulate` + `carmba detect` of a scene file."""
    import yaml  # here, not at the top: only `measure` needs it, `render --check` does not
    with open(scene_yaml) as fh:
        plate = yaml.safe_load(fh)["plate"]
    sim, obs = os.path.join(tmp, "bias_" + name), os.path.join(tmp, "bias_" + name + ".csv")
    run_carmba(binary, "simulate", "--scene", scene_yaml, "--out", sim)
    run_carmba(binary, "detect", "--images", sim, "--rows", str(plate["rows"]), "--cols",
               str(plate["cols"]), "--spacing-mm", str(plate["pitch_mm"]), "--out", obs)
    text = subprocess.run([sys.executable, os.path.join(ROOT, "scripts/plate_radial_bias.py"), sim,
                           obs, str(plate["sphere_diameter_mm"] / 2)], check=True,
                          capture_output=True, text=True).stdout
    m = PLATE_BIAS_LINE.search(text)
    if not m:
        sys.exit("results.py: plate_radial_bias.py printed no figures for " + name)
    n, err, err_se, offset, left, left_se = m.groups()
    return {"n": n, "err": "%s +- %s px" % (err, err_se), "offset": offset + " px",
            "left": float(left), "left_text": "%s +- %s px" % (left, left_se)}


def plate_bias_figures(binary, tmp):
    rows = ["  | scene (spheres) | centres | radial error | predicted offset | left |",
            "  |---|---|---|---|---|"]
    for scene, what in PLATE_BIAS_SCENES:
        b = plate_bias(binary, os.path.join(ROOT, "configs/scenes", scene + ".yaml"), tmp, scene)
        rows.append("  | `%s` (%s) | %s | %s | %s | %s |" % (scene, what, b["n"], b["err"],
                                                              b["offset"], b["left_text"]))
        if scene == "calib_7x6_intensifier":
            shipped = b
    with open(os.path.join(ROOT, "configs/scenes/calib_7x6_intensifier.yaml")) as fh:
        scene_text = fh.read()
    crop = "crop: 0.6}"
    if crop not in scene_text:
        sys.exit("results.py: calib_7x6_intensifier.yaml's background no longer says '%s'" % crop)
    lefts = [shipped["left"]]
    crops = []
    for k, (u, v) in enumerate(INTENSIFIER_CROPS):
        path = os.path.join(tmp, "intensifier_crop%d.yaml" % k)
        with open(path, "w") as fh:
            fh.write(scene_text.replace(crop, "crop: 0.6, crop_center: [%g, %g]}" % (u, v)))
        b = plate_bias(binary, path, tmp, "intensifier_crop%d" % k)
        lefts.append(b["left"])
        crops.append("[%g, %g]: %s" % (u, v, b["left_text"]))
    path = os.path.join(tmp, "intensifier_nobg.yaml")
    with open(path, "w") as fh:
        fh.write("\n".join(l for l in scene_text.split("\n")
                           if not l.strip().startswith("background:")))
    nobg = plate_bias(binary, path, tmp, "intensifier_nobg")
    mean = sum(lefts) / len(lefts)
    spread = (sum((x - mean) ** 2 for x in lefts) / (len(lefts) - 1)) ** 0.5
    return {"platebias.table": "\n".join(rows),
            "platebias.intensifier_crops": "; ".join(crops),
            "platebias.intensifier_mean": "%+.4f px (spread %.4f px), %s the goal of 0.003 px" % (
                mean, spread, "within" if abs(mean) < 0.003 else "NOT within"),
            "platebias.intensifier_nobg": nobg["left_text"]}


def measure(binary):
    with tempfile.TemporaryDirectory(prefix="carmba_results_") as tmp:
        out = os.path.join(tmp, "golden")
        subprocess.run(["bash", os.path.join(ROOT, "scripts/golden_outputs.sh"), binary, out],
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        figures = {}
        for name, fn in SECTIONS.items():
            for key, value in fn(out).items():
                figures[name + "." + key] = value
        tests_dir = os.path.join(os.path.dirname(os.path.dirname(binary)), "tests")
        figures.update(test_figures(tests_dir, tmp))
        figures.update(recall_figures(tests_dir, tmp))
        figures.update(bench_figures(tests_dir, tmp))
        figures.update(plate_bias_figures(binary, tmp))
        for fn in (plate_views_figures, flex_study_figures, rigid_flex_figures,
                   calib_cross_check_figures, clutter_figures):
            figures.update(fn(binary, tmp))
    commit = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True).stdout.strip()
    doc = {"measured": {"commit": commit,
                        "date": datetime.date.today().isoformat(),
                        "command": "python3 scripts/results.py measure (scripts/golden_outputs.sh "
                                   "with --bin " + os.path.relpath(binary, ROOT) + ")"},
           "figures": figures}
    with open(FIGURES, "w") as fh:
        json.dump(doc, fh, indent=1, sort_keys=True)
        fh.write("\n")


def render_text():
    with open(TEMPLATE) as fh:
        template = fh.read()
    doc = load_json(FIGURES)
    figures = doc["figures"]
    used = [k for k in FIGURE_REF.findall(template) if k != "measured"]
    unknown = sorted(set(used) - set(figures))
    unused = sorted(set(figures) - set(used))
    twice = sorted({k for k in used if used.count(k) > 1})
    for what, keys in (("not in %s" % os.path.relpath(FIGURES, ROOT), unknown),
                       ("never used in the template", unused),
                       ("stated more than once in the template", twice)):
        if keys:
            sys.exit("results.py: figures %s: %s" % (what, ", ".join(keys)))
    m = doc["measured"]
    figures = dict(figures, measured="commit %s on %s" % (m["commit"], m["date"]))
    out = []
    for kind, lines in units(template.split("\n")):
        text = "\n".join(lines)
        filled = FIGURE_REF.sub(lambda mo: figures[mo.group(1)], text)
        if filled != text and kind in ("paragraph", "item", "indented"):
            first = {"item": "- ", "indented": "  ", "paragraph": ""}[kind]
            body = " ".join(filled.split())[len(first.strip()):].lstrip()
            filled = textwrap.fill(body, width=100, initial_indent=first,
                                   subsequent_indent=" " * len(first), break_long_words=False,
                                   break_on_hyphens=False)
        out.append(filled)
    return "\n".join(out)


def units(lines):
    """The template's lines as (kind, lines): "item" (a list item with its indented continuation
    lines), "indented" (indented lines after a list item's table: the item's text goes on),
    "paragraph" (plain lines up to a blank line or another kind), or "other" (one line of a
    table, indented or not, heading, comment or code block, a figure alone on its line (a table),
    or a blank line), so that a unit whose figures are filled in is reflowed to 100 columns and
    nothing else moves."""
    result, fence = [], False
    for line in lines:
        if line.startswith("```"):
            fence = not fence
            result.append(["other", [line]])
        elif (fence or not line.strip() or re.match(r"\s*\||[#<]|\d+\. ", line)
              or FIGURE_REF.fullmatch(line)):
            result.append(["other", [line]])
        elif line.startswith("- "):
            result.append(["item", [line]])
        elif line.startswith("  ") and result and result[-1][0] in ("item", "indented"):
            result[-1][1].append(line)
        elif line.startswith("  "):
            result.append(["indented", [line]])
        elif result and result[-1][0] == "paragraph":
            result[-1][1].append(line)
        else:
            result.append(["paragraph", [line]])
    return result


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    me = sub.add_parser("measure")
    me.add_argument("--bin", default=os.path.join(ROOT, "build/bin/carmba"))
    re_ = sub.add_parser("render")
    re_.add_argument("--check", action="store_true")
    a = ap.parse_args()
    if a.cmd == "measure":
        measure(os.path.abspath(a.bin))
    text = render_text()
    if a.cmd == "render" and a.check:
        with open(RESULTS) as fh:
            if fh.read() != text:
                sys.exit("results.py: src/docs/results.md is not what src/docs/results.md.in and "
                         "src/docs/results_figures.json give: edit the template and run "
                         "`python3 scripts/results.py render` (or `measure`)")
        return
    with open(RESULTS, "w") as fh:
        fh.write(text)


if __name__ == "__main__":
    main()
