"""The levels of a deep component graph by SciPy's compiled searches
(:func:`~mitld_lp.solvers.graph.levels`' way out of its level-by-level walk): a
deadline clock makes a thousand levels and more of some hundred components each, where
a round of NumPy calls a level costs more than a search of the whole graph."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["LEVEL_CALL_SECONDS", "PROBE_LEVELS", "SEARCH_SECONDS", "reaching",
           "searched_levels", "thin"]

PROBE_LEVELS = 16
""":func:`~mitld_lp.solvers.graph.levels` walks the levels one by one up to this
depth, then judges at each doubling of the depth whether the levels just walked were
thin (:func:`thin`)."""

LEVEL_CALL_SECONDS = 1e-4
"""About what one level of :func:`~mitld_lp.solvers.graph.levels`' loop costs in NumPy
calls, whatever its size (QVBS ``zeroconf_dl`` 1000-1-30: 0.12 s for 1,164 levels)."""

SEARCH_SECONDS = 1.2e-7
"""About what :func:`searched_levels` costs a component and an edge between components.
Measured (CPU seconds, searched against walked level by level): QVBS ``zeroconf_dl``
1000-1-30 (113,542 components, 248,268 edges, 1,164 levels) 0.049 against 0.12;
``firewire_dl`` 3-600 (168,064, 196,845, 792 levels) 0.033 against 0.10; ``wlan_dl``
0-80 (189,642, 330,803, 212 levels) 0.059 against 0.07; ``csma`` 4-2 (591,933,
1,066,969, 382 levels) 0.20 against 0.20."""


def thin(walked: int, probe: int, n_comp: int, n_edges: int) -> bool:
    """Whether the levels walked since the last probe (up to depth ``probe``, a power of
    two from :data:`PROBE_LEVELS`), ``walked`` components in all, cost more a component
    than the search does (levels narrower than about 300 components on the products
    measured)."""
    depth = probe // 2 if probe > PROBE_LEVELS else probe
    per_component = SEARCH_SECONDS * (n_comp + n_edges) / max(n_comp, 1)
    return depth * LEVEL_CALL_SECONDS > walked * per_component


def searched_levels(preds_of: sp.csr_array, sinks: np.ndarray, comp: np.ndarray,
                    seeds: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The levels of :func:`~mitld_lp.solvers.graph.levels` from the component graph
    (``preds_of``: row ``d`` lists the components with an edge to ``d``) by SciPy's
    compiled searches instead of one round of NumPy calls per level (a deadline makes a
    thousand levels and more): the level of a component is its longest path to a sink,
    found as a shortest path by Dijkstra's algorithm on the reversed graph, each edge
    ``d -> c`` of weight -1 reweighted by the potential ``h(x) = -2 x`` into
    ``2 (c - d) - 1 >= 1`` (Johnson's reweighting). That holds iff every edge runs from a
    higher component id to a lower one, as Tarjan's numbering (csgraph's and
    :func:`~mitld_lp.util.traversal.strong_components`') makes it: checked, and ``None``
    where it does not hold (the caller walks the levels). Which components reach each seed
    set: a breadth-first search of the reversed graph (``preds_of``) from the seeds'
    component, or, where they lie in several, from a node joined to them. The levels and
    reach of :class:`~mitld_lp.solvers.graph.Levels` (levels are integers, exact in
    float64 below 2**53; the reach is a set)."""
    from scipy.sparse import csgraph

    n_comp = preds_of.shape[0]
    # the search's graph in 4-byte indices where its size allows (csgraph's own type:
    # no conversion of int64 arrays made here first); the weights are the same floats
    index = np.int32 if n_comp + preds_of.nnz + sinks.size < np.iinfo(np.int32).max \
        else np.int64
    below = preds_of.indices.astype(index, copy=False)  # the predecessors c of each row d
    row = np.repeat(np.arange(n_comp, dtype=index), np.diff(preds_of.indptr))
    if not bool(np.all(below > row)):
        return None
    source = n_comp  # a node joined to every sink, at potential h = 2 (id -1)
    ptr = np.concatenate([np.asarray(preds_of.indptr, dtype=index),
                          np.asarray([preds_of.indptr[-1] + sinks.size], dtype=index)])
    cols = np.concatenate([below, np.asarray(sinks, dtype=index)])
    weight = np.concatenate([2.0 * (below - row) - 1.0, 2.0 + 2.0 * sinks])
    del row
    reweighted = sp.csr_array((weight, cols, ptr), shape=(n_comp + 1, n_comp + 1))
    dist = csgraph.dijkstra(reweighted, directed=True, indices=source)[:n_comp]
    del reweighted, weight
    # d(x) = d'(x) - h(source) + h(x); the level is -d(x)
    level = np.rint(2.0 + 2.0 * np.arange(n_comp) - dist).astype(np.int64)
    if not bool(np.all(level >= 0)):  # pragma: no cover - every component reaches a sink
        raise AssertionError("the component graph has a node that reaches no sink")
    del cols, ptr, below
    return level, reaching(preds_of, comp, seeds)


def reaching(preds_of: sp.csr_array, comp: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """``(n_components, k)`` bool: which components reach a state of each seed set
    (``seeds``: ``(n_states, k)`` bool; ``comp``: each state's component), by one
    breadth-first search a set on the reversed component graph (``preds_of``: row ``d``
    lists the components with an edge to ``d``), from the seeds' component or, where
    they lie in several, from a node joined to them.  A set, so the same whatever walk
    finds it (:func:`~mitld_lp.solvers.graph.levels` walks it up its levels on a small
    graph)."""
    from scipy.sparse import csgraph

    n_comp = preds_of.shape[0]
    k = seeds.shape[1]
    reach = np.zeros((n_comp, k), dtype=bool)
    for j in range(k):
        start = np.flatnonzero(np.bincount(comp[seeds[:, j]], minlength=n_comp))
        if start.size == 0:
            continue
        if start.size == 1:  # one component: searched from it on ``preds_of`` itself
            found = csgraph.breadth_first_order(preds_of, int(start[0]), directed=True,
                                                return_predecessors=False)
            reach[found, j] = True
            continue
        # the reversed graph again, with a node joined to the seeds' components
        index = preds_of.indices.dtype
        graph = sp.csr_array((np.ones(preds_of.nnz + start.size, dtype=np.int8),
                              np.concatenate([preds_of.indices, start.astype(index)]),
                              np.concatenate([preds_of.indptr,
                                              [preds_of.nnz + start.size]]).astype(index)),
                             shape=(n_comp + 1, n_comp + 1))
        found = csgraph.breadth_first_order(graph, n_comp, directed=True,
                                            return_predecessors=False)
        reach[found[found < n_comp], j] = True
    return reach
