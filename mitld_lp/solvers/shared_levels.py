r"""One :class:`~mitld_lp.solvers.topological.SingleLevels` a quotient, built once and
shared by the interval iteration and the LP stage.

Both walk the single states of a quotient's levels: the iteration's bounds
(:func:`mitld_lp.solvers.iteration.interval_iterations`) and the LP's values and flow
(:func:`mitld_lp.solvers.lp_blocks.solve_decomposed`).  ``SingleLevels(q, b)`` reads only
``q.matrix``, ``q.row_groups``, ``q.sense``, the block order ``b`` (its levels and
self-loops) and the choice of walks (:func:`~mitld_lp.solvers.topological.level_kernels`,
which depends on whether numba is loaded); it never writes them, and its walks never write
its own arrays.  So where all of these are the same objects, a second build is the first
one again, array for array: it was built twice a solve (some 0.05 s each on QVBS
``zeroconf_dl`` 1000-1-30's 1,164 levels), and is now built once.

The iteration left out (``skip``) the states the initial state cannot reach; the object
shared is the one without a skip.  Its bounds walk then also computes those states, and
they are put back afterwards (:func:`mitld_lp.solvers.iteration._topological`): a state
the initial state reaches has only such successors, so no bound it reads changes, and the
bounds are those of the walk with the skip, bit for bit.

The object is kept while the quotient's matrix lives (a weak reference to it), until the
LP stage takes it (``last``): the LP's peak and what it keeps are what they were.  It is
kept only for quotients of at least :data:`RUNS_MIN_LEVELS` levels, where the LP walks
it.  Held from the iteration's end to the LP (some 30 bytes a transition on the
deadline products), beside the iteration's greedy policy and lifted bounds: the
iteration makes the policy before it lifts the bounds, so that its traced peak stays
under the LP's (zeroconf_dl 154.5 against 154.6 bytes a transition).
"""

from __future__ import annotations

import weakref
from typing import Any

from mitld_lp.solvers.graph import Blocks
from mitld_lp.solvers.reduced import Quotient
from mitld_lp.solvers.topological import SingleLevels, level_kernels

__all__ = ["RUNS_MIN_LEVELS", "shared_levels"]

RUNS_MIN_LEVELS = 16
"""Levels from which :func:`~mitld_lp.solvers.lp_blocks.solve_decomposed` and
:func:`~mitld_lp.solvers.lp_blocks.policy_flow` take the single states a run of levels
at a time from arrays gathered once (:class:`~mitld_lp.solvers.topological.
SingleLevels`), not level by level (same answers; a deadline clock makes a thousand
levels), and from which the iteration shares its levels with them."""

# per quotient matrix (by its id: a sparse array has no hash), a weak reference to it
# and the order, row groups and sense the levels were built from, and the levels
_KEPT: dict[int, tuple[weakref.ref[Any], Blocks, Any, Any, SingleLevels]] = {}


def shared_levels(q: Quotient, b: Blocks, *, last: bool = False) -> SingleLevels:
    """``SingleLevels(q, b)`` (no skip, the walks :func:`level_kernels` picks now): the
    one built before for the same matrix, row groups, sense, order and walks, else a new
    one, kept for the next caller while ``q.matrix`` lives.  ``last``: the caller is the
    last to use them (the LP stage): they are not kept past its use, whose memory peak
    is then the one of levels built for it alone."""
    kernels = level_kernels(q.matrix.nnz, b.n_levels, singles=True)
    key = id(q.matrix)
    kept = _KEPT.pop(key, None) if last else _KEPT.get(key)
    if kept is not None:
        ref, order, groups, sense, levels = kept
        if (ref() is q.matrix and order is b and groups is q.row_groups
                and sense is q.sense and levels.kernels is kernels):
            return levels
    levels = SingleLevels(q, b)
    if not last:
        _KEPT[key] = (weakref.ref(q.matrix, _forget(key)), b, q.row_groups, q.sense,
                      levels)
    return levels


def _forget(key: int) -> Any:
    """The callback that drops ``key``'s entry when its matrix is freed (and only its
    own: a later matrix may have the same id and an entry of its own)."""
    def forget(ref: weakref.ref[Any]) -> None:
        kept = _KEPT.get(key)
        if kept is not None and kept[0] is ref:
            del _KEPT[key]
    return forget
