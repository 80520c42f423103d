"""What an answer of :meth:`mitld_lp.worlds.game.Game.successors` must be: a distribution.

The rule the product applies to every row it reads from a world
(:func:`distribution_faults`, a batch of rows at once; :func:`distribution_fault` says
what is wrong with one): pairs ``(next_state, probability)`` with hashable next
states, not empty, every probability a finite, non-negative number, the total within
:data:`PROBABILITY_TOLERANCE` of 1.  :class:`mitld_lp.worlds.game.ExplicitGame` (on its
tables) and :func:`mitld_lp.worlds.game.check_game` (on a world it explores) hold a world to
the stricter letter of the protocol with the same tolerance: probabilities in (0, 1],
distinct next states.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from numbers import Real
from typing import Any

import numpy as np

__all__ = [
    "PROBABILITY_TOLERANCE",
    "is_real",
    "place",
    "as_probabilities",
    "distribution_faults",
    "distribution_fault",
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
    n = lengths.size
    row = np.repeat(np.arange(n), lengths)
    wrong = ~np.isfinite(probs) | (probs < 0.0)
    bad = lengths == 0
    bad[row[wrong]] = True
    total = np.bincount(row, weights=np.where(wrong, 0.0, probs), minlength=n)
    bad |= np.abs(total - 1.0) > tolerance
    return np.flatnonzero(bad)


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


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
    if abs(total - 1.0) > tolerance:
        return f"probabilities sum to {total!r}, not 1"
    return None


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
