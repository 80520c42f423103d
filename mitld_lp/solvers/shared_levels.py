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

On a quotient of single states only (a deadline's product), the iteration's compiled walk
also makes, in the same pass, each model's LP values walk (:func:`walk_handing`: the
LP's values and choices, the same sums in the same order as
:meth:`~mitld_lp.solvers.topological.SingleLevels.values`), handed over with the levels;
the LP stage takes them (:func:`handed`, :func:`mitld_lp.solvers.lp.solve_lp`) and walks
only the policy's flow (QVBS ``zeroconf_dl`` 1000-1-30: the LP stage 26 -> 6 ms of CPU
in a fresh process).

The object is kept while the quotient's matrix lives (a weak reference to it), until the
LP stage takes it (``last``, or the last model's handed walk): the LP's peak and what it
keeps are what they were.  It is kept only for quotients of at least
:data:`RUNS_MIN_LEVELS` levels, where the LP walks it.  Held from the iteration's end to
the LP (some 30 bytes a transition on the deadline products, and the handed walks' float
and int64 a state and model), beside the iteration's greedy policy and lifted bounds: the
iteration makes the policy before it lifts the bounds, so that its traced peak stays
under the LP's (zeroconf_dl 154.5 against 154.6 bytes a transition).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np

from mitld_lp.solvers.graph import Blocks, Sense
from mitld_lp.solvers.level_batches import TIE
from mitld_lp.solvers.reduced import Quotient
from mitld_lp.solvers.topological import SingleLevels, level_kernels

__all__ = ["RUNS_MIN_LEVELS", "Walked", "handed", "shared_levels", "walk_handing"]

RUNS_MIN_LEVELS = 16
"""Levels from which :func:`~mitld_lp.solvers.lp_blocks.solve_decomposed` and
:func:`~mitld_lp.solvers.lp_blocks.policy_flow` take the single states a run of levels
at a time from arrays gathered once (:class:`~mitld_lp.solvers.topological.
SingleLevels`), not level by level (same answers; a deadline clock makes a thousand
levels), and from which the iteration shares its levels with them."""

# per quotient matrix (by its id: a sparse array has no hash), a weak reference to it
# and the order, row groups and sense the levels were built from, the levels, and the
# iteration's walk handed over with them (a list of at most one :class:`Walked`)
_KEPT: dict[int, tuple[weakref.ref[Any], Blocks, Any, Any, SingleLevels, list[Any]]] = {}


def shared_levels(q: Quotient, b: Blocks, *, last: bool = False) -> SingleLevels:
    """``SingleLevels(q, b)`` (no skip, the walks :func:`level_kernels` picks now): the
    one built before for the same matrix, row groups, sense, order and walks, else a new
    one, kept for the next caller while ``q.matrix`` lives.  ``last``: the caller is the
    last to use them (the LP stage): they are not kept past its use, whose memory peak
    is then the one of levels built for it alone."""
    kernels = level_kernels(q.matrix.nnz, b.n_levels, singles=True)
    key = id(q.matrix)
    kept = _KEPT.pop(key, None) if last else _KEPT.get(key)
    if kept is not None and _same(kept, q, b) and kept[4].kernels is kernels:
        return kept[4]
    levels = SingleLevels(q, b)
    if not last:
        _KEPT[key] = (weakref.ref(q.matrix, _forget(key)), b, q.row_groups, q.sense,
                      levels, [])
    return levels


def _same(kept: tuple, q: Quotient, b: Blocks) -> bool:
    """Whether the kept entry was built from ``q``'s matrix, row groups, sense and the
    order ``b``."""
    ref, order, groups, sense = kept[:4]
    return (ref() is q.matrix and order is b and groups is q.row_groups
            and sense is q.sense)


@dataclass(frozen=True, slots=True, eq=False)
class Walked:
    """One model's part of the iteration's walk of a quotient of single states only
    (:func:`walk_handing`), as the LP stage takes it (:func:`handed`): the values and
    choices the LP's values walk (:meth:`~mitld_lp.solvers.topological.SingleLevels.
    values` on the model's one-step target probabilities, its known zeros left out)
    writes, made in the iteration's pass by the same sums in the same order: ``values``
    a float a state (0 on the known zeros), ``picks`` a quotient choice a single state
    in the levels' order (``SingleLevels.states``; -1 on the known zeros)."""

    values: np.ndarray
    picks: np.ndarray


def walk_handing(q: Quotient, levels: SingleLevels, rewards: np.ndarray,
                 bounds: np.ndarray, models: list[Quotient]) -> bool:
    """The iteration's walk of every level of ``levels`` (``levels.solve`` on all of
    them: the same bounds to the bit) by the compiled walk that also makes, for each of
    the ``models`` (their one-step target probabilities the columns ``2 j`` and
    ``2 j + 1`` of ``rewards``), the LP's values walk in the same pass
    (:class:`Walked`), handed over with ``levels`` where they are the ones kept for
    ``q``, for the LP stage (:func:`handed`).  ``False``: nothing done (the NumPy walks,
    or ``levels`` not kept for ``q``): the caller walks."""
    kept = _KEPT.get(id(q.matrix))
    if (levels.kernels is None or kept is None or kept[4] is not levels
            or not _same(kept, q, q.order) or levels.states.size == 0):
        return False
    picked = np.arange(0, 2 * len(models), 2, dtype=np.int64)
    skip = np.stack([np.asarray(m.zero, dtype=bool) for m in models])
    values = np.zeros((len(models), q.n_states))  # a model's row contiguous: no copy
    picks = np.empty((len(models), levels.states.size), dtype=np.int64)
    rows = levels.rows  # the quotient's rows, read in place
    levels.kernels.single_bounds_values(
        0, levels.states.size, levels.state_choice, rows.indptr, levels.states,
        levels.choices, rows.indices, rows.data, levels.leave,
        np.asarray(rewards, dtype=np.float64), bounds, q.sense is Sense.MIN, picked,
        skip, TIE, values, picks)
    kept[5][:] = [(m.to_target, Walked(values[j], picks[j])) for j, m in enumerate(models)]
    return True


def handed(q: Quotient, b: Blocks) -> tuple[SingleLevels, Walked] | None:
    """The levels kept for ``q`` and the walk the iteration handed over with them for
    ``q``'s model (:func:`walk_handing`; the model found by its one-step target
    probabilities, the same array), taken: the levels are not kept past the last
    model's (the LP stage is their last user); None where there is none (nothing is
    taken then)."""
    key = id(q.matrix)
    kept = _KEPT.get(key)
    if kept is None or not _same(kept, q, b):
        return None
    at = next((k for k, (t, _) in enumerate(kept[5]) if t is q.to_target), None)
    if at is None:
        return None
    walked = kept[5].pop(at)[1]
    if not kept[5]:
        del _KEPT[key]
    return kept[4], walked


def _forget(key: int) -> Any:
    """The callback that drops ``key``'s entry when its matrix is freed (and only its
    own: a later matrix may have the same id and an entry of its own)."""
    def forget(ref: weakref.ref[Any]) -> None:
        kept = _KEPT.get(key)
        if kept is not None and kept[0] is ref:
            del _KEPT[key]
    return forget
