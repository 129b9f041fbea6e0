"""carmba.solve on the demo's pose problem (problems/thesis_pose.yaml with
configs/posit_ba_analytic.yaml, scripts/demo.sh step 1) against `carmba solve`'s result.json:
poses, covariances, cross-covariances, relative poses, budget, statistics, to_json(); triangulate,
tre and export_geometry against `carmba triangulate` and `carmba export-geometry`."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import (CARMBA_BIN, POSE_CONFIG, POSE_PROBLEM, PYTHON_DIR, assert_rel, read_json,
                      run_cli, source)


@pytest.fixture(scope="module")
def result(carmba):
    return carmba.solve(POSE_PROBLEM, POSE_CONFIG)


@pytest.fixture(scope="module")
def cli(pose_cli):
    return read_json(pose_cli / "result.json")


def without_times(j):
    """result.json without its wall-clock times (the only values two runs do not share)."""
    if isinstance(j, dict):
        return {k: without_times(v) for k, v in j.items() if k != "time_s"}
    if isinstance(j, list):
        return [without_times(v) for v in j]
    return j


def test_to_json_equals_the_commands_result_json(result, cli):
    mine = json.loads(result.to_json())
    assert without_times(mine) == without_times(cli)
    assert "time_s" in mine["solver"]


def test_views_poses_and_covariances(result, cli):
    views = result.views
    assert [v.id for v in views] == [v["id"] for v in cli["views"]]
    for v, c in zip(views, cli["views"]):
        assert_rel(v.rvec, c["cam_from_object"]["rvec"], what=f"view {v.id} rvec")
        assert_rel(v.t_mm, c["cam_from_object"]["t_mm"], what=f"view {v.id} t")
        assert_rel(v.pose, c["cam_from_object"]["rvec"] + c["cam_from_object"]["t_mm"], what="pose")
        assert v.covariance_6x6.shape == (6, 6)
        assert_rel(v.covariance_6x6, c["covariance_6x6"], what=f"view {v.id} covariance")
        assert_rel(v.sigma_rotation_deg, c["sigma_rotation_deg"], what=f"view {v.id} sigma rot")
        assert_rel(v.sigma_translation_mm, c["sigma_translation_mm"], what=f"view {v.id} sigma t")
        assert v.rms_px == c["rms_px"] and v.num_observations == c["num_observations"]


def test_cross_covariance_is_the_joint_covariance(result, cli):
    """covariance(a, b) against result.json's 6V x 6V joint_covariance, every pair of views,
    both orders: rows over a's [rx ry rz tx ty tz], columns over b's."""
    J = np.array(cli["joint_covariance"])
    ids = [v["id"] for v in cli["views"]]
    for i, a in enumerate(ids):
        assert result.block_parameters("view " + a) == ["rx", "ry", "rz", "tx", "ty", "tz"]
        for k, b in enumerate(ids):
            C = result.covariance("view " + a, "view " + b)
            assert_rel(C, J[6 * i:6 * i + 6, 6 * k:6 * k + 6], what=f"Cov({a}, {b})")
    assert_rel(result.covariance("view " + ids[0]), J[:6, :6], what="marginal")


def test_marker_blocks(result, cli):
    for m in cli["markers"]:
        C = result.covariance(f"marker {m['id']}")
        assert C.shape == (3, 3)
        assert np.all(np.linalg.eigvalsh(C) > 0)
    assert "intrinsics" in result.blocks


def test_unknown_block_is_a_carmba_error(carmba, result):
    with pytest.raises(carmba.Error, match=r"block 'view 7': no such parameter block \(blocks: "):
        result.covariance("view 7")


def test_relative_poses(result, cli):
    rel = result.relative_poses
    assert [(r["a"], r["b"]) for r in rel] == [(r["a"], r["b"]) for r in cli["relative_poses"]]
    for r, c in zip(rel, cli["relative_poses"]):
        assert_rel(r["cam_b_from_cam_a"], c["cam_b_from_cam_a"]["rvec"] + c["cam_b_from_cam_a"]["t_mm"],
                   what=f"{r['a']}->{r['b']}")
        assert_rel(r["covariance_6x6"], c["covariance_6x6"], what=f"{r['a']}->{r['b']} cov")
        assert_rel(r["angle_deg"], c["angle_deg"], what="angle")
        assert_rel(r["sigma_angle_deg"], c["sigma_angle_deg"], what="sigma angle")
        assert_rel(r["baseline_mm"], c["baseline_mm"], what="baseline")
        assert_rel(r["sigma_rotation_deg"], c["sigma_rotation_deg"], what="sigma rotation")
        assert_rel(r["sigma_translation_mm"], c["sigma_translation_mm"], what="sigma translation")
        if "covariance_calibration_6x6" in c:
            assert_rel(r["covariance_calibration_6x6"], c["covariance_calibration_6x6"],
                       what=f"{r['a']}->{r['b']} calibration part")


def test_statistics(result, cli):
    s = result.statistics
    for k, v in cli["statistics"].items():
        assert s[k] == v, k
    assert s["iterations"] == cli["solver"]["iterations"]
    assert s["termination"] == cli["solver"]["termination"]


def test_error_budget_matches_the_view_sigmas(result, cli):
    """The budget's pose rows are the reported sigmas (the same covariance through the same
    SO(3) left Jacobian), and the sources add up."""
    rows = {r["quantity"]: r for r in result.error_budget}
    for v in cli["views"]:
        for a, axis in enumerate("xyz"):
            r = rows[f"view {v['id']} rot {axis}"]
            assert abs(r["sigma"] - v["sigma_rotation_deg"][a]) <= 1e-9 * r["sigma"]
            r = rows[f"view {v['id']} t{axis}"]
            assert abs(r["sigma"] - v["sigma_translation_mm"][a]) <= 1e-9 * r["sigma"]
    for r in rows.values():
        if r["sigma"] == 0:  # a quantity of the held intrinsics only: no variance to share
            assert not any(r["share_by_source"].values())
            continue
        assert abs(sum(r["share_by_source"].values()) - 1) < 1e-12
        total = sum(s * s for s in r["sigma_by_source"].values())
        assert abs(total - r["sigma"] ** 2) <= 1e-9 * r["sigma"] ** 2
    for p in cli["validation"]:
        r = rows[f"pair {p['a']}/{p['b']} relative rotation"]
        assert abs(r["sigma"] - p["sigma_relative_rotation_deg"]) <= 1e-9 * r["sigma"]


def test_intrinsics_are_the_held_camera(carmba, result):
    (i,) = result.intrinsics
    assert i.names == list(carmba.INTRINSIC_NAMES)
    assert_rel(i.values, carmba.read_camera(source("data", "thesis", "camera.json")).intrinsics)
    assert i.covariance is None  # camera.json has none: said in `uncertainty`
    assert "leave the calibration's uncertainty out" in i.uncertainty


def test_geometry_equals_the_commands(result, pose_cli):
    assert result.geometry() == (pose_cli / "geometry.json").read_text()


def test_triangulate_equals_the_command(carmba, result, tmp_path):
    pixels = {"0": (160.0, 200.0), "30": (190.0, 205.0), "90": (170.0, 210.0)}
    out = tmp_path / "tri"
    spec = ";".join(f"{k}={u},{v}" for k, (u, v) in pixels.items())
    run_cli("triangulate", "--problem", POSE_PROBLEM, "--config", POSE_CONFIG, "--pixels", spec,
            "--out", str(out))
    (c,) = read_json(out / "triangulation.json")["points"]
    t = carmba.triangulate(result, pixels)
    assert_rel(t["p_in_ct_mm"], c["p_in_ct_mm"], what="point")
    assert_rel(t["covariance_mm2"], c["covariance_mm2"], what="covariance")
    assert_rel(t["covariance_pixels_mm2"], c["covariance_pixels_mm2"], what="pixels part")
    assert_rel(t["covariance_solve_mm2"], c["covariance_solve_mm2"], what="solve part")
    assert_rel(t["residual_px"], [v["residual_px"] for v in c["views"]], what="residuals")
    for k, v in c["variance_by_source_mm2"].items():
        assert t["variance_by_source_mm2"][k] == v, k
    assert_rel(t["covariance_calibration_mm2"], c["covariance_calibration_mm2"], what="calibration part")
    assert t["rejected"] == [v["rejected"] for v in c["views"]]
    assert (t["chi2"], t["dof"], t["chi2_p_value"]) == (c["chi2"], c["dof"], c["chi2_p_value"])
    assert t["warnings"] == c["warnings"]
    with pytest.raises(carmba.Error, match="view '45' is not an object view"):
        carmba.triangulate(result, {"0": (1.0, 2.0), "45": (3.0, 4.0)})


def test_tre_equals_the_commands(carmba, result, tmp_path):
    """carmba.tre on a solve without tre against `carmba solve` with tre: true."""
    config = tmp_path / "config.yaml"
    config.write_text(open(POSE_CONFIG).read() + "tre: true\n")
    out = tmp_path / "out"
    run_cli("solve", "--problem", POSE_PROBLEM, "--config", str(config), "--no-plots", "--out",
            str(out))
    cli = read_json(out / "result.json")["tre"]
    assert result.tre is None
    mine = carmba.tre(result)
    assert without_times(mine) == without_times(cli)
    assert carmba.solve(POSE_PROBLEM, str(config)).tre is not None


def tree(out):
    return {os.path.relpath(os.path.join(d, f), out): open(os.path.join(d, f)).read()
            for d, _, fs in os.walk(out) for f in fs}


def test_export_geometry_equals_the_command(carmba, result, pose_cli, tmp_path):
    """A mirrored pose problem exports as geometry.json only (RTK and plastimatch cannot carry
    the reflection: the same error as the command's); tests/python/test_solve_joint.py compares
    all formats."""
    out = tmp_path / "export"
    run_cli("export-geometry", "--result", str(pose_cli), "--format", "json", "--out", str(out))
    assert carmba.export_geometry(result, format="json") == tree(out)
    mine = tmp_path / "mine"
    carmba.export_geometry(str(pose_cli), out=str(mine), format="json")
    assert tree(mine) == tree(out)
    with pytest.raises(carmba.Error, match="holds a previous result"):
        carmba.export_geometry(result, out=str(mine), format="json")
    with pytest.raises(carmba.Error, match="format: expected rtk, plastimatch, json or all"):
        carmba.export_geometry(result, format="xml")
    r = run_cli("export-geometry", "--result", str(pose_cli), "--out", str(tmp_path / "rtk"),
                check=False)
    prefix = "carmba export-geometry: error: "
    line = [l for l in r.stderr.splitlines() if l.startswith(prefix)][0]
    with pytest.raises(carmba.Error) as e:
        carmba.export_geometry(str(pose_cli))
    assert str(e.value) == line[len(prefix):]
    assert "cannot carry a reflection" in str(e.value)


def test_errors_carry_the_commands_message(carmba, tmp_path):
    bad = tmp_path / "problem.yaml"
    text = open(POSE_PROBLEM).read().replace("../data/", source("data") + "/")
    bad.write_text(text.replace("sigma_px: 1.0", "sigma_pix: 1.0"))
    r = run_cli("solve", "--problem", str(bad), "--config", POSE_CONFIG, "--out",
                str(tmp_path / "out"), check=False)
    assert r.returncode != 0
    prefix = "carmba solve: error: "
    line = [l for l in r.stderr.splitlines() if l.startswith(prefix)][0]
    with pytest.raises(carmba.Error) as e:
        carmba.solve(str(bad), POSE_CONFIG)
    assert str(e.value) == line[len(prefix):]
    assert str(bad) in str(e.value) and "sigma_px" in str(e.value)
    with pytest.raises(carmba.Error, match="no_such.yaml"):
        carmba.solve(str(tmp_path / "no_such.yaml"), POSE_CONFIG)


def test_import_is_fast_and_starts_no_subprocess():
    """`import carmba` in a fresh interpreter under a second; importing it and solving a pose
    problem starts no child process (RUSAGE_CHILDREN stays empty; the joint test shows it
    counts the mrcal cross-check's)."""
    code = (
        "import resource, sys, time\n"
        f"sys.path.insert(0, {PYTHON_DIR!r})\n"
        "t = time.perf_counter()\n"
        "import carmba\n"
        "dt = time.perf_counter() - t\n"
        f"carmba.solve({POSE_PROBLEM!r}, {POSE_CONFIG!r})\n"
        "ru = resource.getrusage(resource.RUSAGE_CHILDREN)\n"
        "print(dt, ru.ru_maxrss, ru.ru_utime + ru.ru_stime, 'matplotlib' in sys.modules)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    dt, maxrss, cpu, mpl = r.stdout.split()
    print("import carmba:", dt, "s")
    assert float(dt) < 1.0
    assert int(maxrss) == 0 and float(cpu) == 0.0
    assert mpl == "False"


def test_variance_components_and_warnings(result, cli):
    # The self-check is the command's, value for value.
    assert result.variance_components == cli["variance_components"]
    assert result.warnings == cli["warnings"]
    groups = {g["group"]: g for g in result.variance_components["groups"]}
    assert "object_pixels" in groups and "ct" in groups
    assert abs(sum(g["redundancy"] for g in groups.values()) - cli["statistics"]["dof"]) < 1e-6
