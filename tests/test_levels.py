"""The layering of a graph's strongly connected components (``graph.levels``) against a
construction in plain Python: Tarjan-free (components from mutual reachability by
breadth-first search), levels by the longest path to a sink of the component graph,
reach sets by search from each component."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers.graph import levels
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
