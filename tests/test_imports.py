"""``import mitld_lp`` (and the command line's module) loads no solver stack -- cvxpy,
Clarabel, HiGHS, scipy's (sparse) linear algebra, ``mitld_lp.solvers`` -- until a solve
needs it.  Checked in fresh interpreters, where nothing was imported before."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
HEAVY = ("cvxpy", "clarabel", "highspy", "scipy.sparse.linalg", "scipy.linalg",
         "mitld_lp.solvers")


def _loaded_after(code: str) -> list[str]:
    probe = (f"import sys, json\n{code}\n"
             f"heavy = {HEAVY!r}\n"
             "print(json.dumps(sorted(m for m in sys.modules\n"
             "      if any(m == h or m.startswith(h + '.') for h in heavy))))")
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         cwd=ROOT, timeout=120, check=True)
    return json.loads(run.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("module", ["mitld_lp", "mitld_lp.cli"])
def test_import_loads_no_solver_stack(module):
    assert _loaded_after(f"import {module}") == []


def test_the_probe_sees_the_stack_once_a_solve_needed_it():
    # the same probe after a solve: the check above could fail
    loaded = _loaded_after(
        "from mitld_lp import load_model, synthesize\n"
        "synthesize(load_model('models/bus_grid.toml'))")
    assert {"clarabel", "mitld_lp.solvers.lp", "scipy.sparse.linalg"} <= set(loaded)
