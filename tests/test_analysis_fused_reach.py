"""The product's components and reach in one compiled pass
(:func:`~mitld_lp.solvers.analysis_kernels.components_reach`,
:mod:`~mitld_lp.solvers.analysis_reach`), checked against independent routes:

* the labels against SciPy's ``connected_components(connection='strong')`` on the state
  graph built in the test (a set of successors a state), number for number;
* the reach bits against a breadth-first search written in the test on the reversed
  graph, on random graphs with self-loops, repeated entries, states without choices,
  the empty graph, int32 and int64 indices;
* a minimum's and a maximum's analysis with the fused route forced and with SciPy's route: the same
  quotients, array for array and bit for bit, and the solve's bracket holding SciPy's
  LP optimum of the minimum."""

from __future__ import annotations

from collections import deque
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog
from scipy.sparse.csgraph import connected_components

from mitld_lp.mdp import MDP
from mitld_lp.solvers import analysis, analysis_gates, analysis_kernels, analysis_reach
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration

KERNEL = analysis_kernels.components_reach.py_func  # the kernel's code, run as Python


def _random_pattern(rng: np.random.Generator, n: int, index: type) -> tuple:
    """A choice matrix's pattern over ``n`` states: 0-3 choices a state, 1-4 entries a
    choice (repeats and self-loops left in)."""
    per_state = rng.integers(0, 4, n)
    groups = np.concatenate([[0], np.cumsum(per_state)]).astype(np.int64)
    per_row = rng.integers(1, 5, int(groups[-1]))
    indptr = np.concatenate([[0], np.cumsum(per_row)]).astype(index)
    indices = rng.integers(0, max(n, 1), int(indptr[-1])).astype(index)
    return indptr, indices, groups


def _successors(indptr, indices, groups) -> list[set[int]]:
    n = groups.shape[0] - 1
    return [{int(t) for r in range(groups[s], groups[s + 1])
             for t in indices[indptr[r]:indptr[r + 1]]} for s in range(n)]


def _reaching(succ: list[set[int]], seeds: np.ndarray) -> np.ndarray:
    """The states with a path to a seed (seeds included): a BFS of the reversed graph."""
    preds: list[list[int]] = [[] for _ in succ]
    for s, ts in enumerate(succ):
        for t in ts:
            preds[t].append(s)
    found = seeds.copy()
    queue = deque(np.flatnonzero(seeds).tolist())
    while queue:
        t = queue.popleft()
        for s in preds[t]:
            if not found[s]:
                found[s] = True
                queue.append(s)
    return found


@pytest.mark.parametrize("index", [np.int32, np.int64])
@pytest.mark.parametrize("seed", range(25))
def test_labels_are_scipys_and_reach_is_a_bfs(seed: int, index: type) -> None:
    rng = np.random.default_rng(8400 + seed)
    n = int(rng.integers(0, 60)) if seed else 0
    indptr, indices, groups = _random_pattern(rng, n, index)
    seeds = rng.random((n, 3)) < 0.1
    n_comp, label, reach, crowd, ptr, got = KERNEL(indptr, indices, groups,
                                                   analysis_kernels.seed_columns(seeds))
    succ = _successors(indptr, indices, groups)
    assert [got[ptr[s]:ptr[s + 1]].tolist() for s in range(n)] == [sorted(t) for t in succ]
    assert ptr.dtype == got.dtype == np.int32
    rows = [s for s, ts in enumerate(succ) for _ in ts]
    cols = [t for ts in succ for t in sorted(ts)]
    graph = sp.csr_array((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    expected_n, expected = connected_components(graph, directed=True, connection="strong")
    assert n_comp == expected_n
    assert label.tolist() == expected.tolist()
    assert reach.shape == (n, 3) and reach.dtype == bool
    for j in range(3):
        assert reach[:, j].tolist() == _reaching(succ, seeds[:, j]).tolist()
    # the states of SciPy's components of more than one state, counted here
    sizes = np.bincount(expected, minlength=expected_n)
    assert crowd.dtype == np.int32
    assert crowd.tolist() == [s for s in range(n) if sizes[expected[s]] > 1]


def test_the_last_state_entered_is_not_taken_for_a_completed_one() -> None:
    """0 -> 0 completes first (a seed); then 1 -> 2 -> 2 enters every state left, so the
    self-loop's head holds the largest index there is: still on the stack, not a
    completed component (whose bits it would take: 2 reaches no seed)."""
    indptr = np.array([0, 1, 2, 3], dtype=np.int32)
    indices = np.array([0, 2, 2], dtype=np.int32)
    groups = np.array([0, 1, 2, 3], dtype=np.int64)
    seeds = np.array([[True], [False], [False]])
    for kernel in (KERNEL, analysis_kernels.components_reach):
        n_comp, label, reach, crowd, _, _ = kernel(indptr, indices, groups,
                                                   analysis_kernels.seed_columns(seeds))
        assert int(n_comp) == 3 and label.tolist() == [0, 2, 1]
        assert reach[:, 0].tolist() == [True, False, False]
        assert crowd.size == 0  # self-loops are components of one state


def test_compiled_kernel_matches_its_code_on_the_warm_signature() -> None:
    rng = np.random.default_rng(84)
    indptr, indices, groups = _random_pattern(rng, 500, np.int32)
    groups.flags.writeable = False
    seeds = analysis_kernels.seed_columns(rng.random((500, 2)) < 0.05)
    got = analysis_kernels.components_reach(indptr, indices, groups, seeds)
    want = KERNEL(indptr, indices, groups, seeds)
    assert int(got[0]) == int(want[0])
    for a, b in zip(got[1:], want[1:], strict=True):
        assert a.dtype == b.dtype and np.array_equal(a, b)


def test_seed_columns_names_a_bad_shape() -> None:
    with pytest.raises(ValueError, match="seeds"):
        analysis_kernels.seed_columns(np.zeros((3, 9), dtype=bool))
    with pytest.raises(ValueError, match="seeds"):
        analysis_kernels.seed_columns(np.zeros(3, dtype=bool))


def _product(rng: np.random.Generator, n: int) -> tuple[MDP, np.ndarray, np.ndarray]:
    """A random MDP of ``n`` states, its successors mostly near (components of a few
    states, chains between them), with absorbing goal and truncated states."""
    goal = rng.random(n) < 0.02
    extra = (rng.random(n) < 0.01) & ~goal
    rows, cols, vals, groups = [], [], [], [0]
    c = 0
    for s in range(n):
        if goal[s] or extra[s]:
            rows.append(c), cols.append(s), vals.append(1.0)
            c += 1
        else:
            for _ in range(int(rng.integers(1, 3))):
                k = int(rng.integers(1, 4))
                ts = {int((s + d) % n) for d in rng.integers(-3, 12, k)}
                for t in ts:
                    rows.append(c), cols.append(t), vals.append(1.0 / len(ts))
                c += 1
        groups.append(c)
    matrix = sp.csr_array((vals, (rows, cols)), shape=(c, n))
    matrix.indices = matrix.indices.astype(np.int32)
    matrix.indptr = matrix.indptr.astype(np.int32)
    mdp = MDP(matrix=matrix, row_groups=np.array(groups, dtype=np.int64),
              choice_actions=np.zeros(c, dtype=np.int32), action_names=(), initial=0,
              target=goal | extra, sink=np.zeros(n, dtype=bool), truncated=extra,
              states=range(n))
    return mdp, goal, extra


def _fused_forced(monkeypatch: pytest.MonkeyPatch, taken: list) -> None:
    """The fused route taken whatever the load and cache (the kernel run as Python)."""
    monkeypatch.setattr(analysis_reach, "_kernels", lambda: SimpleNamespace(
        components_reach=KERNEL, seed_columns=analysis_kernels.seed_columns,
        component_levels=analysis_kernels.component_levels.py_func))
    inner = analysis_reach.fused_components_reaching

    def spy(*args, **kwargs):
        got = inner(*args, **kwargs)
        taken.append(got is not None)
        return got

    monkeypatch.setattr(analysis, "fused_components_reaching", spy)


def _arrays(q) -> dict:
    out = {f: np.asarray(getattr(q, f)) for f in (
        "target", "prob0", "state_map", "to_target", "row_groups", "choice_origin", "zero")}
    out.update(data=q.matrix.data, indices=q.matrix.indices, indptr=q.matrix.indptr,
               one=np.asarray(q.qualitative.one), comp=np.asarray(q.layers[0]),
               level=np.asarray(q.layers[1]))
    return out


def _min_lp(mdp: MDP, goal: np.ndarray) -> float:
    """Pmin of reaching ``goal`` from the initial state by SciPy's LP (HiGHS): the largest
    ``sum x`` with ``x <= P x`` a choice on the states of positive minimum, 1 on the goal,
    0 where some policy avoids it (found here by a fixpoint of the attractor)."""
    m, g = mdp.matrix.toarray(), mdp.row_groups
    attract = goal.copy()
    grew = True
    while grew:  # Prob0E's complement: every choice reaches the attractor
        grew = False
        for s in np.flatnonzero(~attract):
            if all(m[c][attract].sum() > 0 for c in range(g[s], g[s + 1])):
                attract[s] = grew = True
    free = np.flatnonzero(attract & ~goal)
    at = {int(s): i for i, s in enumerate(free)}
    a_ub, b_ub = [], []
    for s in free:
        for c in range(g[s], g[s + 1]):
            row = np.zeros(free.size)
            row[at[int(s)]] += 1.0
            for t in np.flatnonzero(m[c][free] > 0):
                row[t] -= m[c][free[t]]
            a_ub.append(row)
            b_ub.append(m[c][goal].sum())
    got = linprog(-np.ones(free.size), A_ub=np.array(a_ub), b_ub=np.array(b_ub),
                  bounds=(0, 1), method="highs")
    assert got.status == 0
    init = int(mdp.initial)
    return 1.0 if goal[init] else (float(got.x[at[init]]) if init in at else 0.0)


@pytest.mark.parametrize("sense", [Sense.MIN, Sense.MAX])
@pytest.mark.parametrize("truncated", [False, True])
def test_analysis_the_same_by_either_route(monkeypatch, truncated: bool, sense: Sense) -> None:
    rng = np.random.default_rng(841 + truncated)
    mdp, goal, extra = _product(rng, 9000)
    if not truncated:
        extra[:] = False
    scipy_route = analysis.analyse(mdp, goal, extra, sense=sense)
    taken: list[bool] = []
    _fused_forced(monkeypatch, taken)
    fused = analysis.analyse(mdp, goal, extra, sense=sense)
    assert taken == [True]
    for a, b in zip(scipy_route, fused, strict=True):
        left, right = _arrays(a), _arrays(b)
        for name, value in left.items():
            assert value.dtype == right[name].dtype, name
            assert np.array_equal(value, right[name]), name


@pytest.mark.parametrize("seed", range(3))
def test_fused_solve_brackets_scipys_lp(monkeypatch, seed: int) -> None:
    rng = np.random.default_rng(8484 + seed)
    mdp, goal, _ = _product(rng, 150)
    monkeypatch.setattr(analysis_reach, "SMALL", 0)  # the route taken on a small product
    monkeypatch.setattr(analysis_gates, "PAID_MIN_ENTRIES", 0)
    taken: list[bool] = []
    _fused_forced(monkeypatch, taken)
    q = analysis.analyse(mdp, goal, sense=Sense.MIN)[0]
    assert taken == [True]
    got = interval_iteration(mdp, goal, quotient=q, sense=Sense.MIN, progress=False)
    exact = _min_lp(mdp, goal)
    assert got.value_lower - 1e-9 <= exact <= got.value_upper + 1e-9
    assert got.value_upper - got.value_lower <= 1e-5
