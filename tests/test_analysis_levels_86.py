"""The components' levels from one compiled pass
(:func:`~mitld_lp.solvers.analysis_kernels.component_levels`, read by the fused pass's
``later()`` in :func:`~mitld_lp.solvers.analysis_reach.fused_components_reaching`),
checked against a route written here: the components from SciPy's
``connected_components`` on a state graph built from sets of successors, their edges as
Python sets, and each component's level (its longest path to a sink) as the fixpoint
of ``level[c] = max(level[d] + 1)`` relaxed in rounds until nothing changes (no
topological order, no Tarjan numbering).  The kernel is run as Python (its ``py_func``)
but in the one test of its compiled machine code."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from mitld_lp.solvers import analysis_gates, analysis_kernels, analysis_reach

REACH = analysis_kernels.components_reach.py_func
LEVELS = analysis_kernels.component_levels.py_func


def _matrix(rng: np.random.Generator, n: int, spread: int, forward: bool,
            ) -> tuple[sp.csr_array, np.ndarray]:
    """A choice matrix over ``n`` states (1-3 choices a state, 1-3 entries a choice, each
    to a state ``-spread .. 2 spread`` away, or only ahead with ``forward``: long chains,
    a deadline's shape), int32 indices, read-only int64 row groups."""
    per_state = rng.integers(1, 4, n)
    groups = np.concatenate([[0], np.cumsum(per_state)]).astype(np.int64)
    owner = np.repeat(np.arange(n), per_state)
    rows, cols = [], []
    for r in range(int(groups[-1])):
        s = int(owner[r])
        low = 0 if forward else -spread
        for d in rng.integers(low, 2 * spread + 1, int(rng.integers(1, 4))):
            rows.append(r)
            cols.append(min(s + int(d), n - 1) if forward else (s + int(d)) % n)
    m = sp.csr_array((np.ones(len(rows)), (rows, cols)), shape=(int(groups[-1]), n))
    m.sum_duplicates()
    m.indices = m.indices.astype(np.int32)
    m.indptr = m.indptr.astype(np.int32)
    groups.flags.writeable = False
    return m, groups


def _brute_levels(m: sp.csr_array, groups: np.ndarray) -> np.ndarray:
    """Each state's component's level, by the rounds of the module docs."""
    n = groups.size - 1
    succ = [{int(t) for r in range(groups[s], groups[s + 1])
             for t in m.indices[m.indptr[r]:m.indptr[r + 1]]} for s in range(n)]
    rows = [s for s, ts in enumerate(succ) for _ in ts]
    cols = [t for ts in succ for t in ts]
    graph = sp.csr_array((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    n_comp, comp = connected_components(graph, directed=True, connection="strong")
    out: list[set[int]] = [set() for _ in range(n_comp)]
    for s, ts in enumerate(succ):
        out[comp[s]].update(int(comp[t]) for t in ts if comp[t] != comp[s])
    level = [0] * n_comp
    changed = True
    while changed:
        changed = False
        for c in range(n_comp):
            best = max((level[d] + 1 for d in out[c]), default=0)
            if best != level[c]:
                level[c] = best
                changed = True
    return np.array([level[c] for c in comp], dtype=np.int64)


def _cases() -> list[tuple[int, int, bool]]:
    return [(seed, spread, forward) for seed in range(4) for spread in (1, 4)
            for forward in (False, True)]


@pytest.mark.parametrize("seed, spread, forward", _cases())
def test_levels_are_the_longest_paths_to_a_sink(seed: int, spread: int, forward: bool) -> None:
    rng = np.random.default_rng(8600 + 10 * seed + spread)
    m, groups = _matrix(rng, int(rng.integers(2, 300)), spread, forward)
    seeds = np.zeros((groups.size - 1, 1), dtype=bool)
    n_comp, label, *_ = REACH(m.indptr, m.indices, groups, seeds)
    level, ok = LEVELS(m.indptr, m.indices, groups, label, int(n_comp))
    assert ok
    assert level.dtype == np.int64 and level.shape == (int(n_comp),)
    assert np.array_equal(level[label], _brute_levels(m, groups))


def test_a_numbering_with_an_edge_up_is_refused() -> None:
    """Two states, ``0 -> 1``, labelled in the wrong order (Tarjan completes 1 first)."""
    groups = np.array([0, 1, 2], dtype=np.int64)
    indptr = np.array([0, 1, 2], dtype=np.int32)
    indices = np.array([1, 1], dtype=np.int32)
    assert LEVELS(indptr, indices, groups, np.array([1, 0], dtype=np.int32), 2)[1]
    level, ok = LEVELS(indptr, indices, groups, np.array([0, 1], dtype=np.int32), 2)
    assert not ok


def test_compiled_kernel_gives_the_python_bits() -> None:
    rng = np.random.default_rng(86)
    m, groups = _matrix(rng, 400, 3, False)
    n_comp, label, *_ = REACH(m.indptr, m.indices, groups, np.zeros((400, 1), dtype=bool))
    want = LEVELS(m.indptr, m.indices, groups, label, int(n_comp))
    got = analysis_kernels.component_levels(m.indptr, m.indices, groups, label, int(n_comp))
    assert got[1] == want[1] and np.array_equal(got[0], want[0])


@pytest.mark.parametrize("compiled", [False, True])
@pytest.mark.parametrize("forward", [False, True])
def test_fused_later_gives_the_brute_levels(monkeypatch, compiled: bool, forward: bool) -> None:
    """``later()`` of the fused pass, the levels kernel taken or not (the state graph
    condensed and walked level by level): the same levels, those of the brute route."""
    rng = np.random.default_rng(861 + forward)
    m, groups = _matrix(rng, 600, 2, forward)
    n = groups.size - 1
    monkeypatch.setattr(analysis_reach, "_kernels", lambda: SimpleNamespace(
        components_reach=REACH, component_levels=LEVELS,
        seed_columns=analysis_kernels.seed_columns))
    monkeypatch.setattr(analysis_reach, "SMALL", 0)
    monkeypatch.setattr(analysis_gates, "PAID_MIN_ENTRIES", 0)
    monkeypatch.setattr(analysis_reach, "component_walks", lambda entries, states: None)
    monkeypatch.setattr(analysis_reach, "warm", lambda kernel: compiled)
    got = analysis_reach.fused_components_reaching(m, groups, np.zeros((n, 1), dtype=bool))
    assert got is not None
    found = got[0]
    assert found.level is None and found.later is not None
    level = found.later()
    assert level.dtype == np.int64
    assert np.array_equal(level[found.component], _brute_levels(m, groups))


def _post_order(m: sp.csr_array, groups: np.ndarray) -> list[int]:
    """Each state's place in the order a recursive depth-first search leaves the states
    (roots increasing, each state's distinct successors from the largest down)."""
    import sys

    n = groups.size - 1
    succ = [sorted({int(t) for r in range(groups[s], groups[s + 1])
                    for t in m.indices[m.indptr[r]:m.indptr[r + 1]]}, reverse=True)
            for s in range(n)]
    place = [-1] * n
    seen = [False] * n
    count = [0]

    def visit(v: int) -> None:
        seen[v] = True
        for w in succ[v]:
            if not seen[w]:
                visit(w)
        place[v] = count[0]
        count[0] += 1

    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 4 * n + 100))
    try:
        for root in range(n):
            if not seen[root]:
                visit(root)
    finally:
        sys.setrecursionlimit(limit)
    return place


@pytest.mark.parametrize("seed", range(6))
def test_acyclic_graph_numbered_as_the_search_leaves_it(seed: int) -> None:
    """A graph without a cycle but self-loops (a deadline's shape): each state its own
    component, numbered by the post-order of a recursive search written here, reach by
    the brute fixpoint; one edge back (a 2-cycle) makes the same partition as SciPy's."""
    rng = np.random.default_rng(8650 + seed)
    m, groups = _matrix(rng, int(rng.integers(2, 400)), 3, True)
    n = groups.size - 1
    seeds = rng.random((n, 2)) < 0.05
    n_comp, label, reach, crowd, _, _ = REACH(m.indptr, m.indices, groups,
                                              analysis_kernels.seed_columns(seeds))
    assert int(n_comp) == n and crowd.size == 0
    assert label.tolist() == _post_order(m, groups)
    succ = [{int(t) for r in range(groups[s], groups[s + 1])
             for t in m.indices[m.indptr[r]:m.indptr[r + 1]]} for s in range(n)]
    edges = [(a, b) for a in range(n) for b in succ[a]]
    for j in range(2):  # the sources of edges into the set, added until it stays
        found = set(np.flatnonzero(seeds[:, j]).tolist())
        size = -1
        while size != len(found):
            size = len(found)
            found |= {a for a, b in edges if b in found}
        assert reach[:, j].tolist() == [s in found for s in range(n)]
    # a choice of t back to s, where s has an entry forward to t: a 2-cycle
    src = [s for s in range(n) if any(t > s for t in succ[s])]
    if not src:
        return
    s = src[-1]
    t = max(t for t in succ[s] if t > s)
    back = sp.vstack([m[:int(groups[t + 1])], sp.csr_array(([1.0], ([0], [s])), shape=(1, n)),
                      m[int(groups[t + 1]):]]).tocsr()
    back.indices = back.indices.astype(np.int32)
    back.indptr = back.indptr.astype(np.int32)
    g2 = groups.copy()
    g2.flags.writeable = True
    g2[t + 1:] += 1
    g2.flags.writeable = False
    n_comp2, label2, _, crowd2, _, _ = REACH(back.indptr, back.indices, g2,
                                             np.zeros((n, 1), dtype=bool))
    rows = [a for a in range(n) for _ in succ[a]] + [t]
    cols = [b for a in range(n) for b in succ[a]] + [s]
    graph = sp.csr_array((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    n_want, want = connected_components(graph, directed=True, connection="strong")
    assert int(n_comp2) == n_want < n
    pairs = set(zip(label2.tolist(), want.tolist(), strict=True))
    assert len(pairs) == n_want
    assert crowd2.size >= 2 and s in crowd2.tolist() and t in crowd2.tolist()
    level, ok = LEVELS(back.indptr, back.indices, g2, label2, int(n_comp2))
    assert ok  # every edge between components runs down: Tarjan's numbering
