"""A minimum's staying strategy on its prob-0 states, read from the attractor that found
them (for :func:`~mitld_lp.solvers.analysis.analyse` and the lift,
:func:`~mitld_lp.solvers.quotient.lift_policy`).

A minimum's prob-0 states (``Prob0E``) are the complement of the attractor of its target.
The lifted policy plays, on each of them with more than one choice, its first choice
whose every successor of positive probability stays among them
(:func:`~mitld_lp.solvers.quotient.first_staying`).  The attractor's walk marks every
choice with an entry into its set (:func:`~mitld_lp.solvers.graph.attractor_spared`'s
*hit* choices), and the analysis's matrix stores no zero: a choice of a prob-0 state is
unhit exactly when its support lies among the prob-0 states.  So the first unhit choice
is the lift's choice, the same integer.  The record holds only the states whose first
choice is hit (elsewhere the lift's first choice is the staying one): it spares the lift
its search through the rows (QVBS csma 4-2: 28,447 states of several choices searched,
none of which has its first choice hit).  Each state outside the set with a
choice keeps one unhit (else it would have joined), so the walk below ends.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mitld_lp.solvers.result import read_only
from mitld_lp.solvers.value_one import SureStrategy
from mitld_lp.util.arrays import index_dtype

__all__ = ["STAYING_STRATEGY", "Staying", "first_unhit", "recorded_staying", "staying_record"]

STAYING_STRATEGY = "staying strategy"
"""The key in ``Quotient.shared`` of a minimum's staying strategies: a tuple of
:class:`Staying` records, one per prob-0 set the analysis found (:func:`staying_record`);
a quotient reads the one whose set *is* its ``prob0``."""


def first_unhit(row_groups: np.ndarray, zero: np.ndarray, hit: np.ndarray) -> SureStrategy:
    """The states of ``zero`` (``(n,)`` bool) whose first choice is ``hit``
    (``(n_choices,)`` bool), ascending, and each one's first choice not hit, in
    :func:`~mitld_lp.util.arrays.index_dtype` of the states' and the choices' counts.
    Every other state of ``zero`` with a choice has its first unhit: the lift's first
    choice there is already the staying one (QVBS csma 4-2: all of its 367,456).  Every
    state of ``zero`` with a choice must have an unhit one (outside an attractor that
    marked its hit choices): raises otherwise."""
    groups = np.asarray(row_groups)
    n = groups.shape[0] - 1
    # the states past the last choice have none (their first row would be past the end;
    # one of none before it reads the next state's, dropped below)
    k = int(np.searchsorted(groups[:-1], groups[-1], side="left"))
    states = np.flatnonzero(np.asarray(zero[:k], dtype=bool) & hit[groups[:k]])
    choice = groups[states].astype(np.int64)
    last = groups[states + 1] - 1
    if np.any(last < choice):  # a state of no choice read its successor's first row
        keep = last >= choice
        states, choice, last = states[keep], choice[keep], last[keep]
    pending = np.arange(states.size)
    while pending.size:  # the states whose candidate is hit: their next choice
        if np.any(choice[pending] >= last[pending]):
            raise ValueError("a state outside the attractor has every choice hit")
        choice[pending] += 1
        pending = pending[hit[choice[pending]]]
    return SureStrategy(read_only(states.astype(index_dtype(n), copy=False)),
                        read_only(choice.astype(index_dtype(int(hit.size)), copy=False)))


@dataclass(frozen=True, slots=True, eq=False)
class Staying:
    """A prob-0 set (``zero``, the array a quotient holds as its ``prob0``) and the
    staying strategy on its states of several choices (``played``).  Equal to another
    with equal arrays (two analyses of one product compare equal)."""

    zero: np.ndarray
    played: SureStrategy

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, Staying) and self.zero.dtype == other.zero.dtype
                and np.array_equal(self.zero, other.zero) and self.played == other.played)

    __hash__ = None  # type: ignore[assignment]  # mutable-looking arrays: unhashable


def staying_record(pairs: list[tuple[np.ndarray, np.ndarray]], row_groups: np.ndarray
                   ) -> tuple[Staying, ...]:
    """:data:`STAYING_STRATEGY`'s record: per ``(prob0, hit)`` (a prob-0 set, the
    complement of an attractor, and that attractor's hit choices), the set itself and
    :func:`first_unhit`'s strategy on it."""
    return tuple(Staying(zero, first_unhit(row_groups, zero, hit)) for zero, hit in pairs)


def recorded_staying(shared: dict, prob0: np.ndarray) -> SureStrategy | None:
    """The staying strategy recorded in ``shared`` for the prob-0 set ``prob0`` (the
    same array object), else None (a quotient built otherwise: the lift searches)."""
    for record in shared.get(STAYING_STRATEGY, ()):
        if record.zero is prob0:
            return record.played
    return None
