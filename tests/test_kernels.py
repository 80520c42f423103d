"""The block sweeps (compiled Gauss--Seidel and NumPy Jacobi, each self-loop solved
exactly) against the value LP solved by HiGHS (scipy.optimize.linprog)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog

from mitld_lp import load_model, synthesize
from mitld_lp.mdp import MDP
from mitld_lp.solvers import Status, interval_iteration
from mitld_lp.solvers import kernels as kernels_module
from mitld_lp.testing import random_mdp


def _pmax(mdp) -> np.ndarray:
    """Pmax(F target) of every state by the value LP: the least ``v >= 0`` with
    ``v(s) >= sum_s' P(c, s') v(s')`` for every choice and ``v = 1`` on the target
    (minimising the sum of ``v`` picks the least one, end components or not)."""
    n = mdp.n_states
    p = sp.csr_array(mdp.matrix)
    owner = mdp.choice_state()
    # P v - v(owner) <= 0  ->  (P - E) v <= 0
    a = sp.csr_array(p - sp.csr_array((np.ones(owner.size), (np.arange(owner.size), owner)),
                                      shape=p.shape))
    bounds = [(1.0, 1.0) if t else (0.0, 1.0) for t in mdp.target]
    res = linprog(np.ones(n), A_ub=a, b_ub=np.zeros(owner.size), bounds=bounds,
                  method="highs")
    assert res.status == 0
    return res.x


def _paths() -> list[bool]:
    return [False, True] if kernels_module.compiled_kernel() is not None else [False]


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_both_sweeps_bracket_the_optimum(seed: int) -> None:
    # locality: long chains, so the quotient has large cyclic blocks to sweep
    mdp = random_mdp(300, seed=seed, locality=6, target_fraction=0.03, sink_fraction=0.03)
    exact = _pmax(mdp)
    for compiled in _paths():
        r = interval_iteration(mdp, mdp.target, gap="max", progress=False, compiled=compiled)
        assert r.status == Status.OPTIMAL, compiled
        assert np.all(r.lower <= exact + 1e-9) and np.all(exact <= r.upper + 1e-9), compiled
        assert float(np.max(r.upper - r.lower)) < 1e-9
        np.testing.assert_allclose(r.lower, exact, atol=2e-9)


@pytest.mark.parametrize("compiled", [False, True])
def test_a_sweep_budget_stops_with_a_sound_bracket(compiled: bool) -> None:
    if compiled and kernels_module.compiled_kernel() is None:
        pytest.skip("numba is not installed")
    mdp = random_mdp(300, seed=5, locality=4, target_fraction=0.02, sink_fraction=0.02)
    exact = _pmax(mdp)
    r = interval_iteration(mdp, mdp.target, gap="max", progress=False, compiled=compiled,
                           max_iterations=3)
    assert r.status == Status.MAX_ITERATIONS and r.iterations == 3
    assert np.all(r.lower <= exact + 1e-12) and np.all(exact <= r.upper + 1e-12)
    assert float(np.max(r.upper - r.lower)) > 1e-6  # three sweeps do not close it


def test_compiled_and_numpy_routes_give_the_same_certified_bracket(monkeypatch) -> None:
    if kernels_module.compiled_kernel() is None:
        pytest.skip("numba is not installed")
    model = load_model("models/bus_puddle.toml")
    answers = {}
    for threshold in (10**12, 0):  # never / always compiled
        monkeypatch.setattr(kernels_module, "COMPILED_MIN_ENTRIES", threshold)
        monkeypatch.setattr(kernels_module, "COMPILED_MIN_BLOCK_ENTRIES", threshold)
        r = synthesize(model)
        assert r.certified
        answers[threshold] = (r.lower, r.upper)
    (lo_np, hi_np), (lo_c, hi_c) = answers[10**12], answers[0]
    # the same bracket to the solver's tolerance (1e-9): the sweeps' bounds prune the
    # block LPs' columns, and among choices tied within it either path may keep another
    assert lo_np == pytest.approx(lo_c, abs=1e-9) and hi_np == pytest.approx(hi_c, abs=1e-9)
    assert lo_np == pytest.approx(0.5902931, abs=5e-8)  # the bundled model's optimum


@pytest.mark.parametrize(("product", "block", "loads"), [
    (0, 0, True),  # every block compiled
    (0, 10**12, False),  # a large product whose blocks are all small
    (10**12, 0, False),  # a small product
])
def test_numba_is_loaded_only_for_a_block_worth_it(monkeypatch, product: int, block: int,
                                                   loads: bool) -> None:
    asked: list[int] = []
    real = kernels_module.compiled_kernel

    def counting():  # stands for the import of numba and the kernel's load
        asked.append(1)
        return real()

    monkeypatch.setattr(kernels_module, "compiled_kernel", counting)
    monkeypatch.setattr(kernels_module, "COMPILED_MIN_ENTRIES", product)
    monkeypatch.setattr(kernels_module, "COMPILED_MIN_BLOCK_ENTRIES", block)
    mdp = random_mdp(300, seed=1, locality=6, target_fraction=0.03, sink_fraction=0.03)
    exact = _pmax(mdp)
    r = interval_iteration(mdp, mdp.target, gap="max", progress=False)
    assert bool(asked) is loads
    assert r.status == Status.OPTIMAL
    assert np.all(r.lower <= exact + 1e-9) and np.all(exact <= r.upper + 1e-9)


def _ping_pong() -> MDP:
    """Two states passing the run back and forth with probability 0.999, each leaving
    to the target or to a sink a little: Gauss--Seidel closes the gap by about 0.998 a
    sweep, so sweeping to 1e-9 would take some 10,000 sweeps."""
    rows = [0, 0, 0, 1, 1, 1, 2, 3]
    cols = [1, 2, 3, 0, 2, 3, 2, 3]
    vals = [0.999, 0.0005, 0.0005, 0.999, 0.0004, 0.0006, 1.0, 1.0]
    no = np.zeros(4, dtype=bool)
    return MDP(matrix=sp.csr_array((vals, (rows, cols)), shape=(4, 4)),
               row_groups=np.arange(5), choice_actions=np.array([0, 0, -1, -1], dtype=np.int32),
               action_names=("go",), initial=0, target=np.array([False, False, True, False]),
               sink=np.array([False, False, False, True]), truncated=no, states=(0, 1, 2, 3))


def test_a_block_the_sweeps_cannot_close_is_jumped_before_the_sweep_limit(monkeypatch) -> None:
    if kernels_module.compiled_kernel() is None:
        pytest.skip("numba is not installed")
    from mitld_lp.solvers import iteration

    mdp = _ping_pong()
    # the early jump's cost, from the block's structure (tests/test_jump_cost.py): two
    # states, a round of some 900 entries against sweeps of 6 entries, 968 of them saved
    # by hand: a = 0.0005 + 0.999 b, b = 0.0004 + 0.999 a
    a = (0.0005 + 0.999 * 0.0004) / (1 - 0.999 ** 2)
    sweeps = {}
    for optimistic in (False, True):
        monkeypatch.setattr(kernels_module, "OPTIMISTIC", optimistic)
        r = interval_iteration(mdp, mdp.target, gap="max", progress=False, compiled=True)
        assert r.status == Status.OPTIMAL
        assert r.lower[0] <= a + 1e-15 and a <= r.upper[0] + 1e-15
        assert float(np.max(r.upper - r.lower)) < 1e-9
        sweeps[optimistic] = r.iterations
    # plain sweeps: the early look (from 32) gave up on them, the jump within its budget
    assert iteration._EARLY[0] <= sweeps[False] < iteration._FORECAST_FROM
    # with guesses (kernels' module docs) the sweeps close it before the forecast looks
    assert sweeps[True] < iteration._FORECAST_FROM


@pytest.mark.parametrize(("rate", "at", "hopeless"), [
    # by hand: the sweeps still needed are log(1e-9 / 1e-2) / log(rate), the sweeps left
    # to the limit of 1000 are 1000 - at
    (0.9, 192, False),  # 153 needed, 2 x 808 left
    (0.999, 192, True),  # 16,110 needed
    (0.999, 176, False),  # too early to judge
    (1.0, 960, True),  # the gap does not shrink
    (0.99, 960, True),  # 1,604 needed, 2 x 40 left
    (0.5, 960, False),  # 23 needed, 2 x 40 left
])
def test_the_sweep_forecast(rate: float, at: int, hopeless: bool) -> None:
    from mitld_lp.solvers.iteration import _hopeless

    # what the sweeps report: the gap over its threshold (here tol = 1e-9 alone)
    seen = [(k, 1e-2 * rate ** (k - at) / 1e-9) for k in range(16, at + 1, 16)]
    assert _hopeless(seen, 1000) is hopeless


@pytest.mark.parametrize(("rate", "at", "hopeless"), [
    # the NumPy sweeps' forecast: from 32 sweeps, over the last 16, to their limit of 100
    (1.0, 32, True),  # the gap does not shrink
    (1.0, 16, False),  # too early to judge
    (0.8, 32, False),  # 72 needed, 2 x 68 left
    (0.7, 32, False),  # 45 needed
    (0.9, 32, True),  # 153 needed, 2 x 68 left
])
def test_the_numpy_sweeps_forecast(rate: float, at: int, hopeless: bool) -> None:
    from mitld_lp.solvers.iteration import (
        _NUMPY_FORECAST_FROM,
        _NUMPY_FORECAST_WINDOW,
        _SWEEPS_BEFORE_POLICY,
        _hopeless,
    )

    seen = [(k, 1e-2 * rate ** (k - at) / 1e-9) for k in range(16, at + 1, 16)]
    assert _hopeless(seen, _SWEEPS_BEFORE_POLICY, _NUMPY_FORECAST_FROM,
                     _NUMPY_FORECAST_WINDOW) is hopeless


def _chain(n: int) -> MDP:
    """States 0 .. n-1 explored forward from 0, each moving to the next; the last reaches
    the target with 1/2, a sink with 1/4 and state 0 with 1/4 (so the chain is one
    strongly connected block).  By hand every state's value is v = 1/2 + v/4 = 2/3."""
    rows = [*range(n - 1), n - 1, n - 1, n - 1, n, n + 1]
    cols = [*range(1, n), n, n + 1, 0, n, n + 1]
    vals = [1.0] * (n - 1) + [0.5, 0.25, 0.25, 1.0, 1.0]
    target = np.zeros(n + 2, dtype=bool)
    target[n] = True
    sink = np.zeros(n + 2, dtype=bool)
    sink[n + 1] = True
    return MDP(matrix=sp.csr_array((vals, (rows, cols)), shape=(n + 2, n + 2)),
               row_groups=np.arange(n + 3),
               choice_actions=np.array([0] * n + [-1, -1], dtype=np.int32),
               action_names=("go",), initial=0, target=target, sink=sink,
               truncated=np.zeros(n + 2, dtype=bool), states=tuple(range(n + 2)))


def test_the_sweeps_run_backward_over_a_block_explored_forward(monkeypatch) -> None:
    """A value entering the chain at its end reaches its start in one backward sweep,
    so both bounds' gap is 4^-k everywhere after k sweeps (the last state's update
    ``1/2 + v(0)/4`` from bounds 0 and 1): 15 sweeps bring it below 1e-9 (4^-15 =
    9.3e-10, 4^-14 = 3.7e-9).  The forward order moves it one state a sweep: state 0
    keeps its gap of 1 for n - 1 sweeps.  (The plain sweeps, without the guesses that
    can save a sweep or two here: tests/test_solve_kernels_optimistic.py.)"""
    if kernels_module.compiled_kernel() is None:
        pytest.skip("numba is not installed")
    monkeypatch.setattr(kernels_module, "OPTIMISTIC", False)
    n = 200
    inner = sp.csr_array(([1.0] * (n - 1) + [0.25], ([*range(n - 1), n - 1], [*range(1, n), 0])),
                         shape=(n, n))
    exits = np.zeros((n, 2))
    exits[n - 1] = 0.5
    counts = {}
    for name, order in (("chosen", None), ("forward", np.arange(n, dtype=np.int64))):
        prep = kernels_module.Prepared(inner, np.arange(n + 1))
        if order is not None:
            prep.order = order
        local = np.column_stack([np.zeros(n), np.ones(n)])
        counts[name], over = kernels_module.compiled_sweeps(prep, exits, local, 1e-9, 10**6)
        assert over < 1.0
        assert np.all(local[:, 0] <= 2 / 3) and np.all(2 / 3 <= local[:, 1])
    assert counts["chosen"] == 15
    assert counts["forward"] >= n

    mdp = _chain(n)  # the same through interval iteration: the product's order is kept
    r = interval_iteration(mdp, mdp.target, gap="max", precision=None, progress=False,
                           compiled=True)
    assert r.status == Status.OPTIMAL and r.iterations == 15
    assert r.lower[0] <= 2 / 3 <= r.upper[0]
