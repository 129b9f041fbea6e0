"""Shared fixtures of the Python module's tests: the module on sys.path, the built command, the
shipped data, and the command's own outputs on the shipped problems to compare the bindings with.

ctest sets CARMBA_PYTHON_DIR, CARMBA_BIN and CARMBA_SOURCE_DIR (tests/python/CMakeLists.txt); run
by hand from the top level they default to build/python, build/bin/carmba and the checkout.
"""
import json
import os
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


def assert_rel(actual, expected, rel=REL, what=""):
    """Elementwise |a - e| <= rel * max|e| (a covariance's small off-diagonal terms are compared
    at the scale of the matrix)."""
    a = np.asarray(actual, dtype=float)
    e = np.asarray(expected, dtype=float)
    assert a.shape == e.shape, f"{what}: shape {a.shape} != {e.shape}"
    scale = np.max(np.abs(e)) if e.size else 0.0
    err = np.max(np.abs(a - e)) if e.size else 0.0
    assert err <= rel * scale, f"{what}: max |diff| {err:.3g} > {rel:g} * {scale:.3g}"


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
    run_cli("solve", "--problem", POSE_PROBLEM, "--config", POSE_CONFIG, "--out", str(out))
    return out


def simulate_joint_scene(tmp):
    """The demo's joint scene (scripts/demo.sh step 4) under `tmp`, and the shipped
    problems/thesis_joint.yaml pointed at it (as tests/cli/joint_cli_test.cc does)."""
    scene = tmp / "scene"
    run_cli("simulate", "--scene", source("configs", "scenes", "thesis_joint.yaml"),
            "--out", str(scene))
    run_cli("ct-fiducials", "--dicom", str(scene / "ct"),
            "--model", source("data", "thesis", "markers_table_5_1.csv"),
            "--model-columns", "x_o,y_o,z_o", "--diameter-mm", "2", "--expected", "9",
            "--out", str(scene / "fiducials.csv"))
    with open(source("problems", "thesis_joint.yaml")) as f:
        text = f.read().replace("../out/sim/joint", str(scene))
    problem = tmp / "thesis_joint.yaml"
    problem.write_text(text)
    return scene, problem
