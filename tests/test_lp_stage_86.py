"""lp-86: the chain kernels' one- and two-column loops
(mitld_lp.solvers.level_kernels.chain_solve / chain_flow), the held values' gather
(mitld_lp.solvers.result.Lifted.__getitem__), and the LP stage through them (its
greedy blocks' chains walked by the compiled kernels) against scipy linprog's optimum
on small random MDPs, maximum and minimum."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import chain_levels, greedy_block, lp_blocks, topological
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.result import Lifted

numba = pytest.importorskip("numba")
from scipy.optimize import linprog  # noqa: E402
from test_greedy_block import linprog_max, tied_mdp  # noqa: E402

from mitld_lp.solvers import level_kernels  # noqa: E402  (needs numba)


def _dag_chain(n: int, seed: int) -> sp.csr_array:
    """A sub-stochastic chain whose states ``0..n-1`` each move only to lower states
    (and to themselves), with several entries a row, some in unsorted order."""
    rng = np.random.default_rng(seed)
    rows, cols, vals = [], [], []
    for s in range(n):
        k = int(rng.integers(0, 4)) if s else 0
        succ = rng.choice(s, size=min(k, s), replace=False) if s else np.zeros(0, int)
        w = rng.random(succ.size + 1)
        w *= rng.uniform(0.3, 0.95) / w.sum()
        rows += [s] * (succ.size + 1)
        cols += [*succ.tolist(), s]
        vals += w.tolist()
    m = sp.csr_array((vals, (rows, cols)), shape=(n, n))
    # rows' entries shuffled in place (the kernels read them in their stored order)
    for s in range(n):
        lo, hi = m.indptr[s], m.indptr[s + 1]
        p = rng.permutation(hi - lo) + lo
        m.indices[lo:hi], m.data[lo:hi] = m.indices[p], m.data[p]
    return m


def _solve_reference(m: sp.csr_array, rhs: np.ndarray) -> np.ndarray:
    """``x = rhs + Q x`` column by column in plain Python, downstream first (state 0
    up), each state's sum from 0 in its entries' stored order, its own entry reading 0."""
    n, k = rhs.shape
    x = np.zeros((n, k))
    diag = m.diagonal()
    for j in range(k):
        for s in range(n):
            acc = 0.0
            for e in range(m.indptr[s], m.indptr[s + 1]):
                acc += float(m.data[e]) * float(x[m.indices[e], j])
            x[s, j] = (float(rhs[s, j]) + acc) / (1.0 - float(diag[s]))
    return x


def _flow_reference(m: sp.csr_array, rhs: np.ndarray) -> np.ndarray:
    """``x = rhs + Q^T x`` column by column in plain Python, upstream first (state
    n-1 down), each state's flow divided by its self-loop's complement and pushed along
    its other entries in their stored order."""
    n, k = rhs.shape
    x = np.array(rhs, dtype=np.float64)
    diag = m.diagonal()
    for j in range(k):
        for s in range(n - 1, -1, -1):
            x[s, j] = float(x[s, j]) / (1.0 - float(diag[s]))
            for e in range(m.indptr[s], m.indptr[s + 1]):
                t = int(m.indices[e])
                if t != s:
                    x[t, j] = float(x[t, j]) + float(m.data[e]) * float(x[s, j])
    return x


@pytest.mark.parametrize("transposed", [False, True])
@pytest.mark.parametrize("k", [1, 2, 3])
@pytest.mark.parametrize("seed", range(3))
def test_chain_kernels_columns_match_the_reference_to_the_bit(transposed: bool, k: int,
                                                              seed: int) -> None:
    """chain_solve (downstream first) and chain_flow (upstream first), compiled and
    their py_func, against the plain Python walks, to the bit; the walks against a
    dense solve of ``I - Q`` (or its transpose)."""
    n = 300
    m = _dag_chain(n, seed)
    rhs = np.random.default_rng(seed + 10).random((n, k))
    q = m.toarray().T if transposed else m.toarray()
    want = (_flow_reference if transposed else _solve_reference)(m, rhs)
    np.testing.assert_allclose(want, np.linalg.solve(np.eye(n) - q, rhs), rtol=1e-12)
    kernel = level_kernels.chain_flow if transposed else level_kernels.chain_solve
    for run in (kernel, kernel.py_func):
        if transposed:
            x = rhs.copy()
            run(np.arange(n - 1, -1, -1, dtype=np.int64), m.indptr, m.indices, m.data,
                m.diagonal(), x)
        else:
            x = np.zeros((n, k))
            run(np.arange(n, dtype=np.int64), m.indptr, m.indices, m.data, m.diagonal(),
                rhs, x)
        assert x.tobytes() == want.tobytes()


def _lifted(seed: int, forced: bool) -> Lifted:
    rng = np.random.default_rng(seed)
    n, r = 200, 120
    state_map = np.full(n, -1, dtype=np.int32)
    kept = rng.choice(n, size=150, replace=False)
    state_map[kept] = rng.integers(0, r, size=kept.size)
    one = rng.random(n) < 0.2
    return Lifted.of(rng.random(r), state_map, one, forced)


@pytest.mark.parametrize("forced", [False, True])
@pytest.mark.parametrize("seed", range(3))
def test_held_values_gathered_as_the_hand_lift(forced: bool, seed: int) -> None:
    v = _lifted(seed, forced)
    n = v.state_map.size
    # the product's vector by hand: a removed state 1 on ``one`` else 0, a kept one its
    # reduced value, or 1 where forced and on ``one``
    hand = np.array([
        (1.0 if v.one[s] else 0.0) if v.state_map[s] < 0
        else 1.0 if (forced and v.one[s]) else float(v.reduced[v.state_map[s]])
        for s in range(n)])
    rng = np.random.default_rng(seed + 5)
    mask = rng.random(n) < 0.4
    idx = rng.integers(0, n, size=90)
    kept_only = np.flatnonzero(v.state_map >= 0)
    for index in (mask, idx, idx.astype(np.int32), kept_only, slice(10, 150, 3),
                  np.zeros(n, dtype=bool), np.zeros(0, dtype=np.int64)):
        got = v[index]
        assert got.dtype == np.float64
        assert got.tobytes() == hand[index].tobytes()
        assert got.tobytes() == v.lift()[index].tobytes()


def test_nothing_kept_gathers_the_ones() -> None:
    one = np.array([True, False, True, False])
    v = Lifted.of(np.zeros(0), np.full(4, -1, dtype=np.int32), one)
    assert v[np.array([True, True, False, True])].tolist() == [1.0, 0.0, 0.0]
    assert v[np.array([2, 3])].tolist() == [1.0, 0.0]


@pytest.fixture
def _walked_chains(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every block greedy-checked, its policy's chain walked over its components by the
    compiled kernels however small (the package does so from 32,768 states)."""
    monkeypatch.setattr(lp_blocks, "GREEDY_MIN_CHOICES", 0)
    monkeypatch.setattr(chain_levels, "WALK_MIN_STATES", 8)
    compiled = topological.level_kernels(1, 1, compiled=True)
    assert compiled is level_kernels
    monkeypatch.setattr(chain_levels, "level_kernels", lambda *a: compiled)
    monkeypatch.setattr(greedy_block, "KERNEL_MIN_CHOICES", 0)


@pytest.mark.usefixtures("_walked_chains")
@pytest.mark.parametrize("seed", range(4))
def test_lp_stage_policy_value_is_linprogs_maximum(seed: int) -> None:
    mdp = tied_mdp(seed, n=40)
    want = linprog_max(mdp)
    it = interval_iteration(mdp, mdp.target, gap="max", progress=False)
    got = solve_lp(mdp, mdp.target, everywhere=True, bounds=(it.lower, it.upper))
    assert got.status.value == "optimal" and got.values is not None
    np.testing.assert_allclose(got.values, want, atol=1e-8)
    assert abs(got.value - want[mdp.initial]) <= 1e-8


def _min_by_linprog(mdp) -> np.ndarray:
    """Pmin by scipy's LP over the states that cannot avoid the target: those with
    some policy staying away from it for ever found first (a state is dropped from the
    candidates while all its choices may step out of them), pinned to 0; elsewhere the
    greatest ``v <= 1`` with ``v(s) <= sum P(c) v`` for each choice ``c`` of ``s``."""
    p = mdp.matrix.toarray()
    n = mdp.n_states
    groups = np.asarray(mdp.row_groups)
    avoid = set(np.flatnonzero(~mdp.target).tolist())
    changed = True
    while changed:
        changed = False
        for s in sorted(avoid):
            rows = p[groups[s]:groups[s + 1]]
            outside = [t for t in range(n) if t not in avoid]
            if not any(np.all(r[outside] == 0.0) for r in rows):
                avoid.discard(s)
                changed = True
    a_ub = []
    for s in range(n):
        if mdp.target[s] or s in avoid:
            continue
        for c in range(groups[s], groups[s + 1]):
            row = -p[c].copy()
            row[s] += 1.0
            a_ub.append(row)
    bounds = [(1.0, 1.0) if mdp.target[s] else (0.0, 0.0) if s in avoid else (0.0, 1.0)
              for s in range(n)]
    res = linprog(-np.ones(n), A_ub=np.array(a_ub), b_ub=np.zeros(len(a_ub)),
                  bounds=bounds, method="highs",
                  options={"primal_feasibility_tolerance": 1e-10,
                           "dual_feasibility_tolerance": 1e-10})
    assert res.status == 0
    return res.x


@pytest.mark.usefixtures("_walked_chains")
@pytest.mark.parametrize("seed", range(4))
def test_lp_stage_policy_value_is_linprogs_minimum(seed: int) -> None:
    mdp = tied_mdp(seed, n=40)
    want = _min_by_linprog(mdp)
    it = interval_iteration(mdp, mdp.target, sense=Sense.MIN, gap="max", progress=False)
    got = solve_lp(mdp, mdp.target, sense=Sense.MIN, everywhere=True,
                   bounds=(it.lower, it.upper))
    assert got.status.value == "optimal" and got.values is not None
    np.testing.assert_allclose(got.values, want, atol=1e-9)
    assert abs(got.value - want[mdp.initial]) <= 1e-9
