"""single-85b: the compiled walks of :class:`~mitld_lp.solvers.topological.SingleLevels`
read the quotient's own CSR rows in place, each choice's self-loop skipped, where they
read a copy of the rows without it (``off_diagonal_entries``).

Independent routes: the NumPy walks on the copy (``compiled=False``) for the bits of
the bounds, values, picks and flow (the kernels run as Python here: no numba cache is
written); SciPy's ``linprog`` on the Bellman LP for the certified bracket; tracemalloc in
a child process for what the levels hold (the copy would add 12 bytes a kept entry)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog
from test_single_levels import layered_mdp

from mitld_lp.solvers import interval_iteration
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.topological import SingleLevels, blocks

lk = pytest.importorskip("mitld_lp.solvers.level_kernels")

_WALKS = ("single_bounds", "single_bounds_values", "single_values", "single_flow")


def _as_python(monkeypatch: pytest.MonkeyPatch) -> types.SimpleNamespace:
    """The single walks' kernels as plain Python (their ``py_func``s, their helpers' too)."""
    monkeypatch.setattr(lk, "_score", lk._score.py_func)
    monkeypatch.setattr(lk, "_row_sums", lk._row_sums.py_func)
    return types.SimpleNamespace(**{k: getattr(lk, k).py_func for k in _WALKS})


def _bits(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a, dtype=np.float64).tobytes()


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_view_walks_give_the_copys_bits(monkeypatch: pytest.MonkeyPatch, seed: int,
                                        sense: Sense) -> None:
    mdp, _, _ = layered_mdp(seed, depth=40, width=4)
    q, _ = analyse(mdp, mdp.target, sense=sense)
    b = blocks(q)
    plain = SingleLevels(q, b, compiled=False)
    view = SingleLevels(q, b, compiled=True)
    assert view.cols is None and plain.cols is not None
    view.kernels = _as_python(monkeypatch)
    m = q.matrix
    # the case has what the skip must handle: rows with a self-loop, rows without, and
    # empty rows (every move to the goal or the dead end)
    rows = plain.choices.astype(np.int64)
    owner = np.repeat(plain.states.astype(np.int64), np.diff(plain.state_choice))
    sizes = m.indptr[rows + 1] - m.indptr[rows]
    loops = np.array([owner[i] in m.indices[m.indptr[r]:m.indptr[r + 1]]
                      for i, r in enumerate(rows)])
    assert loops.any() and (~loops & (sizes > 0)).any() and (sizes == 0).any()
    # the iteration's bounds, two columns, from a start that is not the answer
    rng = np.random.default_rng(seed)
    rewards = rng.random((m.shape[0], 2)) * 0.1
    start = rng.random((q.n_states, 2))
    got, want = start.copy(), start.copy()
    view.solve(0, b.n_levels, rewards, got)
    plain.solve(0, b.n_levels, rewards, want)
    assert _bits(got) == _bits(want)
    # the LP's values and picks
    skip = np.zeros(q.n_states, dtype=bool)
    skip[rng.choice(q.n_states, size=q.n_states // 10, replace=False)] = True
    outs = []
    for sl in (view, plain):
        values, choice = np.zeros(q.n_states), np.full(q.n_states, -1, dtype=np.int64)
        weights = np.zeros(m.shape[0])
        sl.values(0, b.n_levels, q.to_target, skip, values, choice, weights)
        outs.append((values, choice, weights))
    assert _bits(outs[0][0]) == _bits(outs[1][0])
    assert np.array_equal(outs[0][1], outs[1][1]) and _bits(outs[0][2]) == _bits(outs[1][2])
    # the policy's flow, a randomised policy (each state's choices' weights sum to 1)
    w = rng.random(m.shape[0])
    w /= np.add.reduceat(w, q.row_groups[:-1])[np.repeat(np.arange(q.n_states),
                                                         np.diff(q.row_groups))]
    x0 = rng.random(q.n_states)
    fx = [x0.copy(), x0.copy()]
    view.flow(0, b.n_levels, b.self_loop, w, fx[0])
    plain.flow(0, b.n_levels, b.self_loop, w, fx[1])
    assert _bits(fx[0]) == _bits(fx[1])
    # the walk handed to the LP (bounds and one model's values in one pass)
    bv = start.copy()
    values = np.zeros((1, q.n_states))
    picks = np.empty((1, view.states.size), dtype=np.int64)
    view.kernels.single_bounds_values(
        0, view.states.size, view.state_choice, view.rows.indptr, view.states,
        view.choices, view.rows.indices, view.rows.data, view.leave, rewards, bv,
        sense is Sense.MIN, np.array([0]), skip[None, :], 1e-12, values, picks)
    assert _bits(bv) == _bits(want)
    lp_values, lp_choice, _ = outs[1]
    plain.values(0, b.n_levels, rewards[:, 0].copy(), skip, lp_values := np.zeros(q.n_states),
                 lp_choice := np.full(q.n_states, -1, dtype=np.int64), np.zeros(m.shape[0]))
    assert _bits(values[0]) == _bits(lp_values)
    live = ~skip[view.states]
    assert np.array_equal(picks[0][live], lp_choice[view.states[live]])
    assert (picks[0][~live] == -1).all()


def _lp_optimum(exact: list, goal: int, sense: Sense) -> np.ndarray:
    """The reachability values by SciPy's LP: for a maximum the least ``x`` with ``x_s
    >= P(c) x + P(c, goal)`` for every choice (the most for a minimum, ``<=``); every
    choice leaves with positive mass, so the fixed point is unique."""
    n = goal
    a, rhs = [], []
    for s, choices in enumerate(exact):
        for row in choices:
            line = np.zeros(n)
            line[s] -= 1.0
            for t, p in row.items():
                if t < n:
                    line[t] += p
            sign = 1.0 if sense is Sense.MAX else -1.0
            a.append(sign * line)
            rhs.append(-sign * row.get(goal, 0.0))
    c = np.ones(n) if sense is Sense.MAX else -np.ones(n)
    res = linprog(c, A_ub=sp.csr_array(np.array(a)), b_ub=np.array(rhs),
                  bounds=[(0.0, 1.0)] * n, method="highs")
    assert res.status == 0, res.message
    return res.x


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", [3, 4, 5])
def test_compiled_bracket_holds_scipys_lp_optimum(seed: int, sense: Sense) -> None:
    mdp, exact, goal = layered_mdp(seed, depth=25, width=4)
    want = _lp_optimum(exact, goal, sense)
    r = interval_iteration(mdp, mdp.target, sense=sense, gap="max", compiled=True,
                           progress=False)
    lower, upper = np.asarray(r.lower)[:goal], np.asarray(r.upper)[:goal]
    slack = 1e-9  # HiGHS's feasibility tolerance
    assert np.all(lower <= want + slack) and np.all(want <= upper + slack)
    assert float(np.max(upper - lower)) < 1e-6


_CHILD = """
import json, sys, tracemalloc
import numpy as np
sys.path.insert(0, sys.argv[1])
from test_single_levels import layered_mdp
from mitld_lp.solvers import rows
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.topological import SingleLevels, blocks

mdp, _, _ = layered_mdp(7, depth=3000, width=6)
q, _ = analyse(mdp, mdp.target, sense=Sense.MAX)
b = blocks(q)
SingleLevels(q, b, compiled=True)  # modules imported untraced
tracemalloc.start()
sl = SingleLevels(q, b, compiled=True)
held, peak = tracemalloc.get_traced_memory()
tracemalloc.stop()
_, cols, vals = rows.off_diagonal_entries(q.matrix, sl.choices,
                                          np.repeat(sl.states, np.diff(sl.state_choice)))
own = sum(a.nbytes for a in (sl.states, sl.choices, sl.leave, sl.level_state,
                             sl.state_choice))
print(json.dumps(dict(held=held, peak=peak, own=own, copy=cols.nbytes + vals.nbytes,
                      choices=int(sl.choices.size))))
"""


def test_compiled_levels_hold_no_copy_of_the_rows(tmp_path: Path) -> None:
    """In a child process (its own numba cache; no kernel is run): what the compiled
    walks' levels hold and their build's traced peak are their per-state and per-choice
    arrays and a few of their temporaries, under the copy of the rows they no longer
    make (with it restored, ``held`` is ``own + copy`` and fails the first bound)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path), MITLD_LP_KERNEL_LOADER="0")
    out = subprocess.run([sys.executable, "-c", _CHILD, str(Path(__file__).parent)],
                         capture_output=True, text=True, env=env, timeout=300, check=True)
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["copy"] > 100_000  # the bound below can see it
    assert got["held"] <= got["own"] + 4096, got
    assert got["peak"] < got["own"] + got["copy"], got
