"""The product's transition probabilities in rational arithmetic, from its factors.

The product (:mod:`mitld_lp.product`) stores each transition as a float: the STA's
probability of the step's events times the world's probability of the next state,
summed where several (events, next state) pairs lead to one product state.  An exact
answer needs each as the rational number the model writes.  It is recomputed here, a
second time and another way: state by state, from the same factors asked for their
rational values --

    P((s, q, Y, c) --a--> (s', q', Y \\ E, c'))  =  sum over the pairs that meet there of
        prod_{e in E} h_e(c)  prod_{e in Y \\ E} (1 - h_e(c))  *  P(s' | s, a, E)

with ``h_e`` the law's exact hazard (:meth:`~mitld_lp.distributions.FirstOccurrence.
exact_hazard`), ``P(s' | s, a, E)`` the world's ``exact_successors``
(:mod:`mitld_lp.worlds.exact`), ``q' = delta(q, props(s') | E)`` and ``c'`` the STA's
clock step, as :mod:`mitld_lp.product` defines them.  Each row found so must have the
float row's successors exactly (an outcome whose float probability underflowed to 0
would be missing from the product: refused) and each value within a relative 1e-6 of
the float one (a check of the two constructions, not of rounding), and sum to exactly
1.  Only the rows of the states asked for are recomputed.
"""

from __future__ import annotations

import functools
import itertools
import math
import time
from collections.abc import Hashable
from fractions import Fraction
from typing import Any

import numpy as np

from mitld_lp.automata.sta import STA
from mitld_lp.exact.errors import ExactError, TimeUp
from mitld_lp.mdp import MDP
from mitld_lp.product import Absorbing, ProductState, ProductStates
from mitld_lp.worlds.exact import exact_successors_of
from mitld_lp.worlds.game import world_members

__all__ = ["exact_rows", "rational"]

#: How far a float transition may be from its exact value (relative: 1/AGREE) before
#: the two constructions are taken to disagree: far above any rounding of a product of a
#: few factors and a sum of positive terms, far below any semantic difference.
AGREE = 10**6


def rational(x: Any) -> Any:
    """``x`` (a Fraction, an int, an exact rational) as python-flint's ``fmpq``."""
    fmpq = _fmpq()
    kind = type(x)
    if kind is fmpq:
        return x
    if kind is Fraction:
        return fmpq(x.numerator, x.denominator)
    f = Fraction(x)
    return fmpq(f.numerator, f.denominator)


@functools.cache
def _fmpq() -> Any:
    from flint import fmpq  # python-flint: the exact answer's extra (refused without it)

    return fmpq


class _Factors:
    """The factors of the product, each asked once, in rational arithmetic."""

    def __init__(self, mdp: MDP, game: Any, sta: STA) -> None:
        moves = exact_successors_of(game)
        if moves is None:
            raise ExactError(f"the world ({type(game).__name__}) has no exact probabilities")
        self.moves, self.game, self.sta, self.dta = moves, game, sta, sta.dta
        self.ignores = world_members(game).ignores_events
        self.atoms = frozenset(self.dta.atoms)
        if not isinstance(mdp.states, ProductStates):
            raise ExactError("an exact answer reads a product built by mitld_lp.product")
        self.states = mdp.states
        self._outcomes: dict[tuple[frozenset[str], int], list[tuple[Any, ...]]] = {}
        self._rows: dict[tuple[Hashable, str, frozenset[str]], list[tuple[Any, Any]]] = {}
        self._labels: dict[Hashable, frozenset[str]] = {}
        self._delta: dict[tuple[int, frozenset[str]], int] = {}
        self._ids: dict[Any, int | None] = {}

    def outcomes(self, pending: frozenset[str], clock: int) -> list[tuple[Any, ...]]:
        """``(events, probability, pending after, clock after or None if truncated)``
        of each outcome of positive probability (:meth:`STA.outcomes`, in rationals)."""
        key = (pending, clock)
        hit = self._outcomes.get(key)
        if hit is None:
            events = sorted(pending)
            hazards = []
            for a in events:
                c = self.sta.clocks[a]
                hazards.append(rational(c.distribution.exact_hazard(min(clock, c.cap) + 1)))
            hit = []
            for happened in itertools.product((False, True), repeat=len(events)):
                p = rational(1)
                for h, yes in zip(hazards, happened, strict=True):
                    p *= h if yes else 1 - h
                if p == 0:
                    continue
                occurred = frozenset(a for a, yes in zip(events, happened, strict=True) if yes)
                left = pending - occurred
                step = self.sta.advance(left, clock)
                hit.append((occurred, p, left, None if step.truncated else step.clock))
            self._outcomes[key] = hit
        return hit

    def row(self, state: Hashable, action: str, events: frozenset[str]) -> list[tuple[Any, Any]]:
        key = (state, action, frozenset() if self.ignores else events)
        hit = self._rows.get(key)
        if hit is None:
            hit = [(s, rational(p)) for s, p in self.moves(*key)]
            total = sum((p for _, p in hit), rational(0))
            if total != 1:
                raise ExactError(f"the world's exact probabilities at state {state!r}, action "
                                 f"{action!r} sum to {total}, not 1")
            self._rows[key] = hit
        return hit

    def step(self, q: int, state: Hashable, events: frozenset[str]) -> int:
        labels = self._labels.get(state)
        if labels is None:
            labels = self._labels[state] = frozenset(self.game.propositions(state)) & self.atoms
        word = labels | (events & self.atoms)
        nxt = self._delta.get((q, word))
        if nxt is None:
            nxt = self._delta[q, word] = self.dta.step(q, word)
        return nxt

    def position(self, record: Any) -> int:
        i = self._ids.get(record)
        if i is None and record not in self._ids:
            i = self._ids[record] = self.states.position(record)
        if i is None:
            raise ExactError(f"product state {record} is reached with positive exact "
                             "probability but is not in the product (a probability that "
                             "rounds to 0 in floating point)")
        return i


def _row(f: _Factors, state: ProductState, action: str) -> dict[int, Any]:
    """One choice's successors and their exact probabilities (module docs)."""
    dta = f.dta
    out: dict[int, Any] = {}
    for events, p, left, clock in f.outcomes(state.pending, state.clock):
        if clock is None:  # the step crossed a truncation point
            j = f.position(Absorbing.TRUNCATED)
            out[j] = out.get(j, 0) + p
            continue
        for nxt, q in f.row(state.game, action, events):
            a = f.step(state.automaton, nxt, events)
            if a == dta.accepting:
                j = f.position(Absorbing.TARGET)
            elif a == dta.rejecting:
                j = f.position(Absorbing.SINK)
            else:
                j = f.position(ProductState(nxt, a, left, clock))
            out[j] = out.get(j, 0) + p * q
    return out


def exact_rows(mdp: MDP, game: Any, sta: STA, states: np.ndarray,
               deadline: float = math.inf) -> list[Any]:
    """The exact probability (``fmpq``) of every entry of ``mdp.matrix`` (CSR order) in
    the rows of ``states`` (a bool mask; the other entries are None), recomputed from
    the factors and checked against the product (module docs).  Raises
    :class:`ExactError`, and :class:`TimeUp` past ``deadline`` (``time.perf_counter``)."""
    f = _Factors(mdp, game, sta)
    matrix = mdp.matrix
    indptr, indices, data = matrix.indptr, matrix.indices, matrix.data
    values: list[Any] = [None] * int(indptr[-1])
    fmpq = _fmpq()
    one = fmpq(1)
    for n, s in enumerate(np.flatnonzero(states).tolist()):
        if n % 1024 == 0 and time.perf_counter() > deadline:
            raise TimeUp
        record = mdp.states[s]
        for c in mdp.choices(s):
            lo, hi = int(indptr[c]), int(indptr[c + 1])
            if isinstance(record, Absorbing):  # its self-loop
                values[lo] = one
                continue
            assert isinstance(record, ProductState)
            action = mdp.action_name(c)
            row = _row(f, record, action)
            cols = indices[lo:hi].tolist()
            if sorted(row) != sorted(cols):
                raise ExactError(f"state {record}, action {action!r}: the exact successors "
                                 "differ from the product's (a probability that rounds to 0 "
                                 "in floating point)")
            if sum(row.values()) != 1:
                raise ExactError(f"state {record}, action {action!r}: the exact "
                                 "probabilities do not sum to 1")
            for k, j in enumerate(cols):
                e, x = row[j], fmpq(*float(data[lo + k]).as_integer_ratio())
                if abs(x - e) * AGREE > e:
                    raise ExactError(f"state {record}, action {action!r}: the product's "
                                     f"probability {float(x)!r} and the exact {e} disagree "
                                     "(a defect: please report it)")
                values[lo + k] = e
    return values
