"""Shared fixtures of the Python module's tests: the module on sys.path, the built command, the
shipped data, and the command's own outputs on the shipped problems to compare the bindings with.

ctest sets CARMBA_PYTHON_DIR, CARMBA_BIN and CARMBA_SOURCE_DIR (tests/python/CMakeLists.txt); run
by hand from the top level they default to build/python, build/bin/carmba and the checkout.
"""
import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

SOURCE_DIR = os.environ.get(
    "CARMBA_SOURCE_DIR", os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
PYTHON_DIR = os.environ.get("CARMBA_PYTHON_DIR", os.path.join(SOURCE_DIR, "build", "python"))
CARMBA_BIN = os.environ.get("CARMBA_BIN", os.path.join(SOURCE_DIR, "build", "bin", "carmba"))
sys.path.insert(0, PYTHON_DIR)

# Bindings call the same library functions as the command: equal to the last digit in practice;
# 1e-12 relative to the largest entry of the compared array is the bar.
REL = 1e-12


def assert_rel(actual, expected, rel=REL, what="", per_entry=True):
    """Elementwise |a - e| <= rel * scale. A covariance (square, positive diagonal) is compared
    entry by entry at sqrt(e_ii e_jj), so a rotation block in rad^2 is held to 1e-12 of itself,
    not of the mm^2 block beside it; other arrays entry by entry at |e| (at least 1e-9 of the
    array's largest entry, for the zeros among them). per_entry=False: every entry at the
    array's largest (finite differences, whose error is absolute)."""
    a = np.asarray(actual, dtype=float)
    e = np.asarray(expected, dtype=float)
    assert a.shape == e.shape, f"{what}: shape {a.shape} != {e.shape}"
    if not e.size:
        return
    d = np.diag(e) if e.ndim == 2 and e.shape[0] == e.shape[1] else None
    if not per_entry:
        scale = np.full(e.shape, np.max(np.abs(e)))
    elif d is not None and np.all(d > 0):
        scale = np.sqrt(np.outer(d, d))
    else:
        scale = np.maximum(np.abs(e), 1e-9 * np.max(np.abs(e)))
    ratio = np.abs(a - e) / np.where(scale > 0, scale, 1.0)
    worst = np.unravel_index(np.argmax(ratio), ratio.shape)
    assert ratio[worst] <= rel, (f"{what}: entry {tuple(int(i) for i in worst)} differs by "
                                 f"{ratio[worst]:.3g} of its scale (> {rel:g})")


def source(*parts):
    return os.path.join(SOURCE_DIR, *parts)


def run_cli(*args, check=True):
    r = subprocess.run([CARMBA_BIN, *args], capture_output=True, text=True)
    if check:
        assert r.returncode == 0, f"carmba {' '.join(args)}: {r.stderr}"
    return r


def read_json(path):
    with open(path) as f:
        return json.load(f)


@pytest.fixture(scope="session")
def carmba():
    import carmba as module
    return module


POSE_PROBLEM = source("problems", "thesis_pose.yaml")
POSE_CONFIG = source("configs", "posit_ba_analytic.yaml")  # as in scripts/demo.sh


@pytest.fixture(scope="session")
def pose_cli(tmp_path_factory):
    """`carmba solve` on the demo's pose problem: its output directory."""
    out = tmp_path_factory.mktemp("pose") / "out"
    run_cli("solve", "--problem", POSE_PROBLEM, "--config", POSE_CONFIG, "--no-plots", "--out",
            str(out))
    return out


def simulate_joint_scene(tmp):
    """The demo's joint scene (scripts/demo.sh step 4) with its CT fiducials, and the shipped
    problems/thesis_joint.yaml pointed at it (as tests/cli/joint_cli_test.cc does), under `tmp`.
    Under ctest the scene is the fixture cli_scenes's, read only; otherwise the fixture's script
    (tests/cli/simulate_scenes.sh) renders it under `tmp`."""
    fixture = os.environ.get("CARMBA_TEST_SCENES")
    scene = pathlib.Path(fixture, "thesis_joint") if fixture else None
    if scene is None or not (scene / "fiducials.csv").exists():
        subprocess.run(["bash", source("tests", "cli", "simulate_scenes.sh"), CARMBA_BIN,
                        SOURCE_DIR, str(tmp), "thesis_joint"], check=True,
                       stdout=subprocess.DEVNULL)
        scene = tmp / "thesis_joint"
    with open(source("problems", "thesis_joint.yaml")) as f:
        text = f.read().replace("../out/sim/joint", str(scene))
    problem = tmp / "thesis_joint.yaml"
    problem.write_text(text)
    return scene, problem
