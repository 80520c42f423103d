"""The order in which the compiled Gauss--Seidel sweeps of the interval iteration visit a
block's states: where the value comes from first.

A Gauss--Seidel sweep reads, for each state, the bounds its successors have *in this
sweep*: a state visited after its successors sees their new bounds, one visited before
sees last sweep's.  The value of a reachability probability enters a block where its
choices reach the target (``to_target``), and flows back along the block's moves from
there; so the sweeps visit the states in the order of their distance to those states
(backwards along the moves inside the block), and a sweep carries the target's value as
far back as the block reaches, not one step.  States that reach no such state
inside the block (their value comes through the block's exits to lower levels) follow,
by their distance to the states with exits; any left (none in a block of a quotient,
where every state leaves) keep the default order
(:func:`mitld_lp.solvers.kernels.sweep_order`), after all of them.  The states at one
distance keep the default order among themselves (the last state first: the product's
exploration order reversed, which carries a value back towards the initial state).
Without that tie-break (in the search's own order) QVBS ``zeroconf`` 1000-4-false
``correct_max``'s block of 213,268 states took 60 sweeps against 39 in the default
order; with it, 39.

The interval iteration renumbers the block in this order (last first), so that the
kernel's own sweep, from the last state to the first, visits it while reading the rows
in memory order: handed to the kernel as an order of visits over the block as it was,
the same 465 sweeps of ``bus_scaled`` n128 d3 took 2.75 s CPU against 1.13 s renumbered
(one profile each, the machine loaded), a row far from the last one read at every state.

Any order gives sound bounds (each update is a Bellman update of one state from bounds
that are sound, so a lower bound stays below the optimum and an upper one above it); the
order changes only how many sweeps close the gap, and with it the last bits of the
bracket the sweeps stop at.  ``bus_scaled`` n128 d3 (two grid blocks of 32,768 and
16,384 states, depth 254, hazards leaving from every cell): 374 + 295 sweeps in the
default order (from the last state to the first), 168 + 233 in this one; 168 + 280
from the states with exits of any kind (the hazards' exits are everywhere, so their
distance says little); 168 + 233 with or without the tie-break below (``docs/results.md``,
"The compiled sweeps' order: the target's value first").
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.kernels import sweep_order
from mitld_lp.solvers.rows import gather_ranges
from mitld_lp.solvers.topological import Block

__all__ = ["renumbered", "value_order"]


def renumbered(block: Block, order: np.ndarray) -> Block:
    """``Block.of(q, block.states[order])`` from the block itself: its states, choices
    and rows taken in ``order`` (a permutation of its local indices), the inner columns
    renamed to the new places.  Each row keeps its entries in their stored order, as
    ``Block.of`` splits them from the quotient's rows, so every field is the same to the
    bit and in the same types; the quotient's rows are not gathered and split a second
    time."""
    order = np.asarray(order, dtype=np.int64)
    n = block.states.size
    groups = block.groups
    picked = gather_ranges(groups[order], groups[order + 1])  # old choice places
    place = np.empty(n, dtype=block.inner.indices.dtype)
    place[order] = np.arange(n, dtype=place.dtype)
    inner = _rows(block.inner, picked, place)
    outer = _rows(block.outer, picked, None)
    counts = groups[order + 1] - groups[order]
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    return Block(block.states[order], block.choices[picked], inner, outer, starts,
                 block.to_target[picked])


def _rows(m: sp.csr_array, rows: np.ndarray, rename: np.ndarray | None) -> sp.csr_array:
    """``m``'s ``rows`` in that order (SciPy's row gather: each row's entries in their
    stored order), the columns renamed by ``rename`` where given; ``m``'s index types
    kept."""
    out = sp.csr_array(m[rows])
    if rename is not None:
        out.indices = rename[out.indices].astype(m.indices.dtype, copy=False)
    out.indptr = out.indptr.astype(m.indptr.dtype, copy=False)
    return out


def value_order(block: Block) -> np.ndarray:
    """The block's states (local indices, int64 as the kernel takes them) in the order
    of the module docs: by distance to a state with a choice that reaches the target,
    then by distance to a state with an exit, then the rest in the default order."""
    n = block.states.size
    owner = np.repeat(np.arange(n, dtype=np.int64), np.diff(block.groups))
    row = np.repeat(owner, np.diff(block.inner.indptr))
    succ = np.asarray(block.inner.indices, dtype=np.int64)
    target = _states_of(owner, np.asarray(block.to_target) > 0, n)
    leaving = _states_of(owner, np.diff(block.outer.indptr) > 0, n)
    seen = np.zeros(n, dtype=bool)
    parts = []
    for seeds in (target, leaving):
        if seeds.size == 0 or seen.all():
            continue
        reached = _backwards(succ, row, seeds, n)
        reached = reached[~seen[reached]]
        seen[reached] = True
        parts.append(reached)
    default = sweep_order(n)
    parts.append(default[~seen[default]])
    order = np.concatenate(parts)
    return np.ascontiguousarray(order, dtype=np.int64)


def _states_of(owner: np.ndarray, choices: np.ndarray, n: int) -> np.ndarray:
    """The states (ascending) with at least one of the ``choices`` (a mask over them)."""
    mark = np.zeros(n, dtype=bool)
    mark[owner[choices]] = True
    return np.flatnonzero(mark)


def _backwards(succ: np.ndarray, row: np.ndarray, seeds: np.ndarray, n: int) -> np.ndarray:
    """The states from which a move inside the block reaches one of ``seeds`` (the seeds
    first), by that distance (one breadth-first search from a node ``n`` with an edge to
    every seed, along the moves reversed: successor to owner), and within a distance in
    the default order, the last state first."""
    graph = sp.csr_array((np.ones(succ.size + seeds.size),
                          (np.concatenate([succ, np.full(seeds.size, n)]),
                           np.concatenate([row, seeds]))), shape=(n + 1, n + 1))
    # csgraph imports scipy.sparse.linalg and scipy.linalg: only a compiled block's order
    # needs it, not every route that imports the iteration
    from scipy.sparse.csgraph import breadth_first_order

    found, parent = breadth_first_order(graph, n, directed=True, return_predecessors=True)
    found = np.asarray(found[1:], dtype=np.int64)
    dist = _levels(found, parent, n)
    if dist is None:
        dist = _jumped(found, parent, n)
    # by distance, and within a distance in the default order (the last state first)
    return _by_distance(found, dist, n)


def _by_distance(found: np.ndarray, dist: np.ndarray, n: int) -> np.ndarray:
    """``found`` (distinct states of ``0..n-1``) by ``dist``, and at one distance the
    last state first: ``found[np.lexsort((-found, dist))]``, as a stable sort of the
    states taken from the last down, by distances that fit 16 bits (NumPy sorts those
    by radix: 6 against 47 ms for ``lexsort`` on QVBS ``zeroconf`` 1000-4's block of
    213,268 states)."""
    if dist.size == 0 or int(dist.max()) >= 2**16:
        return found[np.lexsort((-found, dist))]
    at = np.zeros(n, dtype=np.uint16)
    at[found] = dist
    mark = np.zeros(n, dtype=bool)
    mark[found] = True
    down = np.flatnonzero(mark)[::-1]
    return down[np.argsort(at[down], kind="stable")]


LEVEL_STEPS = 4096
"""Distances read level by level (:func:`_levels`) up to this depth; a deeper search
(a chain) is read by pointer jumping (:func:`_jumped`)."""


def _levels(found: np.ndarray, parent: np.ndarray, n: int) -> np.ndarray | None:
    """The distance (the root's children at 1) of each of ``found`` (a breadth-first
    order from the root ``n``, without it; ``parent``: the search tree's), read level by
    level: a search from a queue finds a node's children after those of every node found
    before it, so the parents' places in ``found`` never fall along it, and each level
    ends where the parents reach the next one's start (a binary search a level, against
    the depth's log of passes over every state by pointer jumping: 20-25 ms of the 60
    of QVBS ``zeroconf`` 1000-4's block).  ``None`` if the parents' places do fall
    (another search order) or the search is deeper than :data:`LEVEL_STEPS`."""
    place = np.empty(n + 1, dtype=np.int64)
    place[n] = -1
    place[found] = np.arange(found.size, dtype=np.int64)
    up = place[parent[found]]
    if up.size and (up[0] != -1 or np.any(up[1:] < up[:-1])):
        return None
    ends = [int(np.searchsorted(up, 0))]  # the root's children: parent place -1
    while ends[-1] < found.size:
        if len(ends) > LEVEL_STEPS:
            return None
        ends.append(int(np.searchsorted(up, ends[-1])))
    counts = np.diff(np.concatenate([[0], ends]))
    return np.repeat(np.arange(1, counts.size + 1, dtype=np.int64), counts)


def _jumped(found: np.ndarray, parent: np.ndarray, n: int) -> np.ndarray:
    """The distances of :func:`_levels`, by pointer jumping up the search tree (its
    depth's log passes over the states, not one a state)."""
    up = np.full(n + 1, n, dtype=np.int64)
    up[found] = parent[found]
    dist = np.ones(n + 1, dtype=np.int64)
    dist[n] = 0
    while True:
        higher = up[up]
        if np.array_equal(higher, up):
            break
        dist += dist[up] * (up != n)
        up = higher
    return dist[found]
