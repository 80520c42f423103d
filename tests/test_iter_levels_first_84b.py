"""The interval iteration builds the levels it walks before its per-choice arrays
(:func:`mitld_lp.solvers.iteration.interval_iterations`) and lets its exit rewards go
before the records' columns are copied.

Independent routes: backward induction over an acyclic MDP written here (its optimum
exact up to rounding: every state's value is one max or min over its choices of
already-known values) for the brackets; the same pass with the levels built where they
were before (the call ahead of the arrays skipped) for the bits; tracemalloc, in a child
process, for the pass's peak with and without the levels built first.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import build_mdp

from mitld_lp.solvers import iteration, shared_levels
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense

ROOT = Path(__file__).resolve().parents[1]


def _layered(n: int, seed: int) -> tuple[list, int]:
    """States 0..n-1, each with 1-3 choices to later states (within 5), the goal (n) or
    the sink (n + 1), the sink from every choice (no state of value 1 or, but those
    reaching only the sink, 0): acyclic, so every state is a level of its own."""
    rng = np.random.default_rng(seed)
    goal = n
    rows = []
    for s in range(n):
        rs = []
        for _ in range(int(rng.integers(1, 4))):
            succ = {int(t) for t in rng.integers(s + 1, s + 6, size=3)}
            succ = {min(t, goal) for t in succ} | {goal + 1}  # the sink always: no 1s
            if rng.random() < 0.3:
                succ.add(goal)
            w = rng.random(len(succ)) + 0.05
            rs.append(dict(zip(sorted(succ), (w / w.sum()).tolist(), strict=True)))
        rows.append(rs)
    return rows, goal


def _induction(rows: list, goal: int, sense: Sense) -> np.ndarray:
    value = {goal: 1.0, goal + 1: 0.0}
    for s in range(len(rows) - 1, -1, -1):
        got = [sum(p * value[t] for t, p in r.items()) for r in rows[s]]
        value[s] = max(got) if sense is Sense.MAX else min(got)
    return np.array([value[s] for s in range(len(rows))])


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(3))
def test_levels_first_same_bits_and_brackets_hold_the_optimum(monkeypatch, sense, seed):
    rows, goal = _layered(60, seed)
    choices = [[(f"a{i}", r) for i, r in enumerate(rs)] for rs in rows] + [[], []]
    mdp = build_mdp(choices, target=[goal], sink=[goal + 1])
    got = []
    for old in (False, True):
        shared_levels._KEPT.clear()
        calls: list = []
        real = iteration.shared_levels

        def seen(q, b, _old=old, _calls=calls, _real=real, **kw):
            caller = sys._getframe(1).f_code.co_name
            # old: the levels built where the pass built them before (in its walk)
            out = None if _old and caller == "interval_iterations" else _real(q, b, **kw)
            _calls.append((caller, out))
            return out
        monkeypatch.setattr(iteration, "shared_levels", seen)
        q, _ = analyse(mdp, mdp.target, sense=sense)
        assert q.order.n_levels >= iteration.RUNS_MIN_LEVELS  # the levels are walked
        (it,) = iteration.interval_iterations(mdp, [q], progress=False, gap="max")
        monkeypatch.undo()
        built = [out for _, out in calls if out is not None]
        assert built and all(out is built[0] for out in built)  # one build, read after
        first = next(caller for caller, out in calls if out is not None)
        assert (first == "interval_iterations") is not old  # built ahead, or in the walk
        got.append(it)
    want = _induction(rows, goal, sense)
    for it in got:
        lower, upper = np.asarray(it.lower)[:goal], np.asarray(it.upper)[:goal]
        assert np.all(lower <= want + 1e-12) and np.all(want <= upper + 1e-12)
        assert np.max(upper - lower) <= 1e-6
    new, old = got
    for a, b in ((new.lower, old.lower), (new.upper, old.upper), (new.policy, old.policy)):
        assert np.array_equal(np.asarray(a).view(np.int64), np.asarray(b).view(np.int64))


_CHILD = r"""
import json, sys, tracemalloc
import numpy as np
sys.path.insert(0, "tests")
from mitld_lp.solvers import iteration, shared_levels
from mitld_lp.solvers.analysis import analyse
from conftest import build_mdp
from test_iter_levels_first_84b import _layered

rows, goal = _layered(30_000, 4)
mdp = build_mdp([[(f"a{i}", r) for i, r in enumerate(rs)] for rs in rows] + [[], []],
                target=[goal], sink=[goal + 1])
real = iteration.shared_levels
iteration.interval_iterations(mdp, [analyse(mdp, mdp.target)[0]], progress=False, gap="max")
out = {}  # above: a first pass, untraced (what a process loads once is not the pass's)
for old in (True, False):
    shared_levels._KEPT.clear()
    q, _ = analyse(mdp, mdp.target)
    if old:
        iteration.shared_levels = lambda q, b, **kw: (
            None if sys._getframe(1).f_code.co_name == "interval_iterations"
            else real(q, b, **kw))
    tracemalloc.start()
    start = tracemalloc.get_traced_memory()[0]
    (it,) = iteration.interval_iterations(mdp, [q], progress=False, gap="max")
    out["old" if old else "new"] = tracemalloc.get_traced_memory()[1] - start
    tracemalloc.stop()
    iteration.shared_levels = real
    out["levels"] = q.order.n_levels
    out["choices"] = int(q.matrix.shape[0])
    out["states"] = int(q.n_states)
print(json.dumps(out))
"""


def test_the_pass_peaks_no_higher_with_the_levels_built_first(tmp_path):
    run = subprocess.run([sys.executable, "-c", _CHILD], cwd=ROOT, capture_output=True,
                         text=True, check=True, env={"PATH": "", "PYTHONPATH": str(ROOT),
                                                     "NUMBA_CACHE_DIR": str(tmp_path)})
    got = json.loads(run.stdout)
    assert got["levels"] >= iteration.RUNS_MIN_LEVELS
    # the exit rewards (two floats a choice) and the bounds (two a state) were alive
    # through the levels' build, which copied the rows; since single-85b the compiled
    # walks' levels copy no row (their build is no longer the pass's peak: 6.73 -> 4.26
    # MB here), so built first they only must not raise it
    assert got["new"] <= got["old"], got
