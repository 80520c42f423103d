"""experiments/bench_qvbs.py's own cases (``--cases grid sensed``, ``--quick``): the
201x201 grid's ``F[0,10] goal`` and the smallest sensed bus case are rows of the QVBS
table, in its CSV, its ratios and its target check, each answer checked against an
independent value: the grid's against a plain dynamic program over the grid written
here (and Storm's run on the PRISM file), the sensed case's against Storm's sound check
of the exported product.

The script runs as a user runs it, in a subprocess, without a QVBS checkout (the cases
alone); no wall-clock assertion: the times are what the script reports.
"""

from __future__ import annotations

import csv
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("stormpy") is None, reason="needs stormpy: pip install -e '.[prism]'"
)

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "experiments" / "bench_qvbs.py"


def _bench(*argv: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    return subprocess.run([sys.executable, str(SCRIPT), *argv], capture_output=True,
                          text=True, timeout=300, env=env, cwd=ROOT)


def grid_reach(n: int, goal: tuple[int, int], steps: int, slip: float = 0.1) -> float:
    """The best probability of being at ``goal`` within ``steps`` moves from (0, 0) on
    an n x n grid whose four moves stay put with probability ``slip`` (a move off the
    grid is not offered): backward induction over the whole grid."""
    v = np.zeros((n, n))
    v[goal] = 1.0
    for _ in range(steps):
        best = np.zeros((n, n))  # every cell of a grid with n > 1 has some move
        for axis, shift in ((0, 1), (0, -1), (1, 1), (1, -1)):
            moved = np.full((n, n), -1.0)  # -1: the move is not offered there
            src = [slice(None), slice(None)]
            dst = [slice(None), slice(None)]
            src[axis] = slice(1, None) if shift == 1 else slice(0, -1)
            dst[axis] = slice(0, -1) if shift == 1 else slice(1, None)
            moved[tuple(dst)] = (1 - slip) * v[tuple(src)] + slip * v[tuple(dst)]
            best = np.maximum(best, moved)
        best[goal] = 1.0
        v = best
    return float(v[0, 0])


def test_the_dynamic_program_by_hand():
    # a 2 x 2 grid, the goal one move away: reached within k moves with 1 - 0.1^k
    assert grid_reach(2, (1, 0), 1) == pytest.approx(0.9, abs=1e-15)
    assert grid_reach(2, (1, 0), 3) == pytest.approx(1 - 0.1**3, abs=1e-15)
    assert grid_reach(3, (2, 2), 3) == 0.0  # four moves away


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("cases")
    done = _bench("--quick", "--cases", "grid", "sensed", "--out", str(out))
    assert done.returncode == 0, done.stdout + done.stderr
    with (out / "bench_qvbs.csv").open(newline="", encoding="utf-8") as f:
        rows = {r["case"]: r for r in csv.DictReader(f)}
    return rows, (out / "bench_qvbs.md").read_text(), done.stdout


def test_both_cases_are_rows_of_the_table(quick):
    rows, text, printed = quick
    assert set(rows) == {"grid", "sensed"}
    for row in rows.values():
        assert row["certified"] == "True" and row["storm_agrees"] == "True"
        assert row["degenerate"] == "False" and not row["trivial"]
        assert f"| {row['instance']} |" in text  # in the table
        assert f"instance={row['instance']} " in printed  # printed with its times
    assert rows["grid"]["instance"].startswith("grid.201x201.")


def test_the_grid_answer_is_the_dynamic_programs(quick):
    rows, _, _ = quick
    grid = rows["grid"]
    exact = grid_reach(201, (4, 3), 10)
    assert 0.5 < exact < 1
    assert float(grid["value"]) - 1e-9 <= exact <= float(grid["upper"]) + 1e-9
    assert float(grid["storm_prism_value"]) == pytest.approx(exact, abs=1e-9)
    assert int(grid["storm_prism_states"]) == 201 * 201  # Storm's whole PRISM world
    assert grid["storm_prism_inside"] == "True"


def test_the_sensed_answer_is_storms_on_the_product(quick):
    rows, _, _ = quick
    sensed = rows["sensed"]
    lower, upper = float(sensed["value"]), float(sensed["upper"])
    assert 0 < lower <= upper < 1
    # Storm's sound check of our exported product: the lower model's optimum, which the
    # controller's value (our lower) and the certified upper bound bracket
    assert lower - 1e-9 <= float(sensed["storm_value"]) <= upper + 1e-9
    assert int(sensed["storm_states"]) == int(sensed["states"])


def test_both_cases_count_in_the_ratios_and_the_targets(quick):
    rows, text, _ = quick
    for row in rows.values():
        ratio = float(row["solve_over_storm_check"])
        assert ratio == pytest.approx(float(row["solve_cpu"]) / float(row["storm_check_cpu"]))
    grid = rows["grid"]
    assert float(grid["process_over_storm_process"]) == pytest.approx(
        float(grid["process_cpu"]) / float(grid["storm_process_cpu"]))
    # the sensed build has no Storm peer: no process ratio, the reason said
    assert rows["sensed"]["process_over_storm_process"] == ""
    assert f"{rows['sensed']['instance']}: process ratio left out: no Storm peer" in text
    assert "no such instance was run" not in text  # the cases are checked, small or not
    assert "on the non-trivial cases" in text


def test_no_qvbs_and_no_cases_is_refused(tmp_path):
    done = _bench("--quick", "--no-cases", "--out", str(tmp_path))
    assert done.returncode == 2
    assert "--qvbs is required unless a case runs" in done.stderr
