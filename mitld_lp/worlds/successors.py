"""What an answer of :meth:`mitld_lp.worlds.game.Game.successors` must be: a distribution.

The one place a world's successor distribution is checked.  The rule the product
applies to every row it reads from a world (:func:`distribution_faults`, a batch of rows
at once; :func:`distribution_fault` says what is wrong with one): pairs ``(next_state,
probability)`` with hashable next states, not empty, every probability a finite,
non-negative number, the total within :data:`PROBABILITY_TOLERANCE` of 1.
:func:`mitld_lp.worlds.game.check_game` (on a world it explores) holds a world to the stricter
letter of the protocol with the same tolerance (:func:`strict_distribution_fault`:
probabilities in (0, 1], distinct next states); :class:`mitld_lp.worlds.game.ExplicitGame`
reads its tables with :func:`table_distribution` (repeated next states merged, zeros
dropped); a PRISM world's tables are checked in a batch with PRISM's own tolerance
(:mod:`mitld_lp.worlds.prism_tables`), and a row that PRISM's tolerance accepts but this
one does not is divided by its sum there (:func:`normalise_rows`), which the world
declares as its :class:`Normalisation`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from numbers import Real
from typing import Any

import numpy as np

__all__ = [
    "PROBABILITY_TOLERANCE",
    "Normalisation",
    "normalise_rows",
    "is_real",
    "place",
    "as_probabilities",
    "distribution_faults",
    "checked_rows",
    "distribution_fault",
    "strict_distribution_fault",
    "table_distribution",
    "actions_fault",
    "propositions_fault",
]

PROBABILITY_TOLERANCE = 1e-9
"""How far a successor distribution's total may be from 1."""


def is_real(x: object) -> bool:
    """A real number, not a bool."""
    return isinstance(x, Real) and not isinstance(x, bool)


def place(state: Any, action: str, events: Iterable[str] = ()) -> str:
    """Where a successor answer comes from, for messages: ``state (0, 1), action 'E'``
    and ``, events ['b1']`` when the step has events."""
    where = f"state {state!r}, action {action!r}"
    ev = sorted(events)
    return f"{where}, events {ev}" if ev else where


def as_probabilities(values: list[Any]) -> np.ndarray:
    """``values`` as a float64 array; TypeError unless each is a real number (not a
    bool, not a string that numpy would parse)."""
    raw = np.array(values)
    if raw.dtype.kind not in "fiu":  # bools, strings, objects: each checked
        if not all(is_real(v) for v in values):
            raise TypeError("a probability is not a number")
        raw = np.array([float(v) for v in values])
    return raw.astype(np.float64, copy=False)


def distribution_faults(
    lengths: np.ndarray, probs: np.ndarray, tolerance: float = PROBABILITY_TOLERANCE
) -> np.ndarray:
    """The indices of the rows that are not distributions, for rows given as their
    ``lengths`` and their probabilities ``probs`` concatenated (float64).

    A row is a distribution when it is non-empty, every probability is finite and
    non-negative, and their total (summed in order) is within ``tolerance`` of 1: the
    rule the product applies to every answer of :meth:`Game.successors`, for a batch of
    answers at once.  :func:`distribution_fault` says what is wrong with one of them.
    """
    return checked_rows(lengths, probs, tolerance)[0]


def checked_rows(lengths: np.ndarray, probs: np.ndarray, tolerance: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`distribution_faults`' indices, and what it computed on the way: each
    row's total (summed in order, a wrong probability counted as 0) and each entry's
    row, which :func:`normalise_rows` takes instead of computing them again (where no
    row is faulty the totals are its own, bit for bit: the same sums in the same order)."""
    n = lengths.size
    row = np.repeat(np.arange(n, dtype=np.int32 if n < 1 << 31 else np.int64), lengths)
    wrong = ~np.isfinite(probs) | (probs < 0.0)
    bad = lengths == 0
    if wrong.any():
        bad[row[wrong]] = True
        probs = np.where(wrong, 0.0, probs)
    total = np.bincount(row, weights=probs, minlength=n)
    off = total - 1.0  # one temporary a row, not two
    np.abs(off, out=off)
    bad |= off > tolerance
    del off
    return np.flatnonzero(bad), total, row


@dataclass(frozen=True, slots=True)
class Normalisation:
    """The rows of a world's table whose probabilities summed to 1 only within a wider
    tolerance than :data:`PROBABILITY_TOLERANCE` (PRISM's ``1e-5``), each divided by its
    sum when the world was read (:func:`normalise_rows`): every answer is then for the
    normalised world.

    Attributes:
        source: the file the rows come from.
        rows: how many rows were divided by their sums.
        largest: the largest ``|sum - 1|`` among them, the relative deviation of a sum
            from 1; each probability of such a row changed by the factor ``1 / sum``,
            within ``1 / (1 - largest)`` of 1.
        tolerance: the rule the rows were read with (``|sum - 1| <= tolerance``).
    """

    source: str
    rows: int
    largest: float
    tolerance: float

    def __str__(self) -> str:
        rows = "1 row" if self.rows == 1 else f"{self.rows:,} rows"
        return (f"{rows} of {self.source} summed to 1 only within {self.tolerance:g} "
                f"(largest |sum - 1| = {self.largest:.3g}), each divided by its sum: "
                "the answer is for the normalised world")


def normalise_rows(lengths: np.ndarray, probs: np.ndarray,
                   checked: tuple[np.ndarray, np.ndarray] | None = None,
                   ) -> tuple[np.ndarray, int, float]:
    """Rows (as for :func:`distribution_faults`, already checked with a wider tolerance)
    whose total is more than :data:`PROBABILITY_TOLERANCE` from 1, each divided by its
    total: returns the probabilities, how many rows changed and their largest
    ``|total - 1|`` (``probs`` itself, 0 and 0.0 when none did).  ``checked``: the
    totals and the entries' rows of :func:`checked_rows` on these rows, none faulty
    (else computed here).  Every row returned is a distribution within
    :data:`PROBABILITY_TOLERANCE` (a divided row's new total is checked)."""
    n = lengths.size
    if checked is None:
        row = np.repeat(np.arange(n), lengths)
        total = np.bincount(row, weights=probs, minlength=n)
    else:
        total, row = checked
    deviation = total - 1.0
    np.abs(deviation, out=deviation)
    off = deviation > PROBABILITY_TOLERANCE
    if not off.any():
        return probs, 0, 0.0
    out = probs / np.where(off, total, 1.0)[row]
    mine = off[row]  # the divided rows' entries, their new totals summed in order
    again = np.bincount(row[mine], weights=out[mine], minlength=n)[off]
    if np.any(np.abs(again - 1.0) > PROBABILITY_TOLERANCE):  # cannot happen: never trust
        raise ValueError("a row divided by its sum does not sum to 1")
    return out, int(np.count_nonzero(off)), float(deviation[off].max())


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _total_fault(total: float, tolerance: float) -> str | None:
    """The one test of a distribution's total (summed in order)."""
    return None if abs(total - 1.0) <= tolerance else f"probabilities sum to {total!r}, not 1"


def distribution_fault(dist: Any, tolerance: float = PROBABILITY_TOLERANCE) -> str | None:
    """What makes one answer of :meth:`Game.successors` not a distribution (the rule of
    :func:`distribution_faults`, and pairs ``(next_state, probability)`` with hashable
    next states and numbers), or None when it is one."""
    try:
        items = list(dist)
    except TypeError:
        return f"successors must be pairs (next_state, probability), got {_short(dist)}"
    if not items:
        return "successors must not be empty"
    total = 0.0
    for item in items:
        try:
            nxt, p = item
            hash(nxt)
        except (TypeError, ValueError):
            return f"expected (next_state, probability) with a hashable state, got {_short(item)}"
        if not is_real(p) or not math.isfinite(float(p)) or float(p) < 0.0:
            return f"probability of {_short(nxt)} must be finite and non-negative, got {p!r}"
        total += float(p)
    return _total_fault(total, tolerance)


def strict_distribution_fault(dist: Any,
                              tolerance: float = PROBABILITY_TOLERANCE) -> str | None:
    """The letter of the protocol (:func:`mitld_lp.worlds.game.check_game`): a non-empty tuple
    of ``(next_state, probability)`` pairs, distinct hashable next states, every
    probability in (0, 1], the total within ``tolerance`` of 1; None when it holds."""
    if not isinstance(dist, tuple) or not dist:
        return f"successors must be a non-empty tuple, got {dist!r}"
    nexts: set[Any] = set()
    total = 0.0
    for item in dist:
        if not isinstance(item, tuple) or len(item) != 2:
            return f"expected (next_state, probability), got {item!r}"
        nxt, p = item
        if not is_real(p) or not (0.0 < float(p) <= 1.0):
            return f"probability of {nxt!r} must be in (0, 1], got {p!r}"
        try:
            fresh = nxt not in nexts
        except TypeError:
            return f"next state {nxt!r} is not hashable"
        if not fresh:
            return f"next state {nxt!r} is listed twice"
        nexts.add(nxt)
        total += float(p)
    return _total_fault(total, tolerance)


def table_distribution(value: Any, tolerance: float = PROBABILITY_TOLERANCE
                       ) -> tuple[tuple[tuple[Any, float], ...], str | None]:
    """A distribution given in a table (:class:`mitld_lp.worlds.game.ExplicitGame`): a mapping
    ``next -> probability`` or pairs, each probability in [0, 1]; repeated next states
    are merged and exact zeros dropped.  Returns the pairs and None, or ``()`` and what
    is wrong (the total of the merged pairs, summed exactly, within ``tolerance`` of 1)."""
    pairs = value.items() if isinstance(value, Mapping) else value
    merged: dict[Any, float] = {}
    for item in pairs:
        try:
            nxt, p = item
        except (TypeError, ValueError):
            return (), f"expected (next_state, probability), got {item!r}"
        if not is_real(p) or not math.isfinite(float(p)):
            return (), f"probability of {nxt!r} must be a number, got {p!r}"
        p = float(p)
        if p < 0.0 or p > 1.0:
            return (), f"probability of {nxt!r} must be in [0, 1], got {p!r}"
        try:
            merged[nxt] = merged.get(nxt, 0.0) + p
        except TypeError:
            return (), f"next state {nxt!r} is not hashable"
    out = tuple((s, p) for s, p in merged.items() if p > 0.0)
    total = math.fsum(p for _, p in out)
    if not out or _total_fault(total, tolerance):
        return (), f"probabilities must sum to 1, got {total!r}"
    return out, None


def actions_fault(actions: Any) -> str | None:
    """What makes an answer of :meth:`Game.actions` wrong (it must be a non-empty list or
    tuple of distinct strings), or None."""
    if not isinstance(actions, list | tuple):
        return f"actions must be a tuple of names, got {_short(actions)}"
    if not actions:
        return "actions must not be empty (a state with nothing to do needs an action such " \
               "as 'stay')"
    for a in actions:
        if not isinstance(a, str):
            return f"an action must be a string, got {_short(a)}"
    if len(set(actions)) != len(actions):
        return f"actions must be distinct, got {_short(actions)}"
    return None


def propositions_fault(props: Any, names: frozenset[str]) -> str | None:
    """What makes an answer of :meth:`Game.propositions` wrong (a set of strings among
    the world's ``proposition_names``), or None."""
    if not isinstance(props, frozenset | set):
        return f"propositions must be a frozenset of names, got {_short(props)}"
    unknown = [p for p in props if p not in names]
    if unknown:
        return (f"propositions {_short(sorted(map(str, unknown)))} are not among its "
                f"proposition_names {_short(sorted(names))}")
    return None
