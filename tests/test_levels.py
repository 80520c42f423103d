"""The layering of a graph's strongly connected components (``graph.levels``) against a
construction in plain Python: Tarjan-free (components from mutual reachability by
breadth-first search), levels by the longest path to a sink of the component graph,
reach sets by search from each component."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import graph as graph_module
from mitld_lp.solvers.graph import blocks_from, graph_blocks, levels
from mitld_lp.util import traversal


def _reachable(adj: list[set[int]], start: int) -> set[int]:
    seen, todo = {start}, [start]
    while todo:
        for t in adj[todo.pop()]:
            if t not in seen:
                seen.add(t)
                todo.append(t)
    return seen


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("index", [np.int32, np.int64])
@pytest.mark.parametrize("small", [-1, 10**9], ids=["csgraph", "python"])
def test_levels_and_reach_match_a_plain_construction(seed: int, index: type, small: int,
                                                     monkeypatch) -> None:
    monkeypatch.setattr(traversal, "SMALL", small)  # the components by either walk
    rng = np.random.default_rng(seed)
    n = int(rng.integers(20, 120))
    # mostly forward edges (a deep component graph), some back edges (cycles), repeats
    src = rng.integers(0, n, 4 * n)
    dst = np.where(rng.random(src.size) < 0.85, np.minimum(src + rng.integers(1, 6, src.size),
                                                           n - 1), rng.integers(0, n, src.size))
    keep = src != dst
    src, dst = src[keep], dst[keep]
    graph = sp.csr_array((np.ones(src.size), (src, dst)), shape=(n, n))
    graph.sum_duplicates()
    graph.indices = graph.indices.astype(index)
    graph.indptr = graph.indptr.astype(index)
    seeds = rng.random((n, 2)) < 0.05
    got = levels(graph, seeds)

    adj = [set() for _ in range(n)]
    for s, t in zip(src.tolist(), dst.tolist(), strict=True):
        adj[s].add(t)
    reach = [_reachable(adj, s) for s in range(n)]
    same = [frozenset(t for t in reach[s] if s in reach[t]) for s in range(n)]
    # one component id per class, as levels numbers them
    for s in range(n):
        assert {int(got.component[t]) for t in same[s]} == {int(got.component[s])}
    assert len(set(same)) == int(got.component.max()) + 1

    @functools.cache
    def level(c: frozenset[int]) -> int:
        below = {same[t] for s in c for t in adj[s]} - {c}
        return 1 + max(map(level, below)) if below else 0

    for s in range(n):
        assert got.level[got.component[s]] == level(same[s])
        for j in range(seeds.shape[1]):
            expect = any(seeds[t, j] for t in reach[s])
            assert bool(got.reach[got.component[s], j]) == expect


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("radix", [True, False])
def test_blocks_order_states_by_level_and_renumber_ids_in_order(seed: int, radix: bool,
                                                                monkeypatch) -> None:
    """``graph_blocks`` (ids and levels as ``levels`` found them) and ``blocks_from``
    (a subset's ids of a larger graph, renumbered) against their definition written
    in Python: ``by_level`` the states sorted by level, ties in state order;
    ``level_starts`` where each level begins; ids and levels renumbered densely in
    their order; the sizes counted."""
    monkeypatch.setattr(graph_module, "RADIX_LEVELS", 1 << 16 if radix else 0)
    rng = np.random.default_rng(seed)
    n = int(rng.integers(30, 150))
    src = rng.integers(0, n, 3 * n)
    dst = np.where(rng.random(src.size) < 0.8, np.minimum(src + rng.integers(1, 4, src.size),
                                                          n - 1), rng.integers(0, n, src.size))
    graph = sp.csr_array((np.ones(src.size), (src, dst)), shape=(n, n))
    graph.sum_duplicates()
    loops = rng.random(n)
    found = levels(graph)

    def check(blk, component: list[int], level_of: dict[int, int], states: list[int]) -> None:
        ids = sorted(set(component))
        used = sorted({level_of[c] for c in ids})
        dense = [ids.index(c) for c in component]
        lv = [used.index(level_of[c]) for c in ids]
        assert blk.component.tolist() == dense and blk.level.tolist() == lv
        assert blk.size.tolist() == [dense.count(k) for k in range(len(ids))]
        state_level = [lv[d] for d in dense]
        order = sorted(range(len(states)), key=lambda i: (state_level[i], i))
        assert blk.by_level.tolist() == order
        assert blk.level_starts.tolist() == [sum(x < k for x in state_level)
                                             for k in range(len(used) + 1)]
        np.testing.assert_array_equal(blk.self_loop, loops[states])

    level_of = dict(enumerate(found.level.tolist()))
    check(graph_blocks(graph, loops), found.component.tolist(), level_of, list(range(n)))
    # a subset of the states under ids spread out (the sorted path) or not (the table)
    n_comp = found.level.size
    for spread in (1, 1000):
        sub = np.sort(rng.choice(n, n // 3, replace=False))
        comp = found.component[sub] * spread
        level_at = np.zeros((n_comp - 1) * spread + 1, dtype=np.int64)
        level_at[np.arange(n_comp) * spread] = found.level
        check(blocks_from(comp, level_at, loops[sub]), comp.tolist(),
              {int(c): int(level_at[c]) for c in comp}, sub.tolist())
