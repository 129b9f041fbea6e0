"""src/docs/python_example.py runs from the top level and prints what it says."""
import os
import subprocess
import sys

from conftest import PYTHON_DIR, SOURCE_DIR, source


def test_example_runs():
    env = dict(os.environ, CARMBA_SOURCE_DIR=SOURCE_DIR, CARMBA_PYTHON_DIR=PYTHON_DIR)
    r = subprocess.run([sys.executable, source("src", "docs", "python_example.py")],
                       capture_output=True, text=True, cwd=SOURCE_DIR, env=env)
    assert r.returncode == 0, r.stderr
    out = r.stdout
    assert "carmba.Result(pose, 5 views)" in out
    assert "['rx', 'ry', 'rz', 'tx', 'ty', 'tz'] (6, 6)" in out
    assert "0 -> 10:" in out
    assert "carmba.Error:" in out and "no_such.yaml" in out
    assert "['geometry.json']" in out
