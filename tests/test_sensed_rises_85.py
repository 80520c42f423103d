"""experiments/sensed_solve_rises.py runs as a user runs it (``--quick``, a subprocess) and
its table holds what it claims: the bracket of each solve, below the full-information
optimum that Storm gives for the exact model, the peak at least the size at the start, and
only rises of at least the threshold asked for."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

# Storm (stormpy 2.0), Pmax=? [F "target"] on the DRN export of bus_grid's exact product,
# where the robot sees every bus (tests/test_experiments.py's STORM): no policy that acts
# on a camera's reports can do better
FULL_INFORMATION = 0.9244053


@pytest.mark.skipif(not Path("/proc/self/statm").exists(), reason="reads /proc (Linux)")
def test_rises_quick(tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    done = subprocess.run(
        [sys.executable, str(ROOT / "experiments" / "sensed_solve_rises.py"), "--quick",
         "--out", str(tmp_path), "--solves", "2", "--min-rise", "2.5"],
        capture_output=True, text=True, timeout=600, env=env, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    text = (tmp_path / "sensed_solve_rises.md").read_text(encoding="utf-8")
    brackets = re.findall(r"bracket \[([0-9.e-]+), ([0-9.e-]+)\], certified True", text)
    assert len(brackets) == 2 and brackets[0] == brackets[1]
    lower, upper = map(float, brackets[0])
    assert 0.5 < lower <= FULL_INFORMATION
    assert upper - lower <= 0.01 + 1e-9  # the case's epsilon
    sizes = re.findall(r"resident at its start ([0-9.]+), peak ([0-9.]+) B/t", text)
    assert len(sizes) == 2 and all(float(p) >= float(s) for s, p in sizes)
    rises = [float(x) for x in re.findall(r"^\| \+([0-9.]+) \|", text, re.M)]
    assert rises and min(rises) >= 2.5


def test_rises_refuses_no_solve(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, str(ROOT / "experiments" / "sensed_solve_rises.py"), "--quick",
         "--out", str(tmp_path), "--solves", "0"],
        capture_output=True, text=True, timeout=120, env=env, cwd=ROOT)
    assert done.returncode != 0 and "--solves: at least 1, got 0" in done.stderr
