"""The supported fragment (MITLD^-, co-safe): negation normal form and the checks.

A formula is supported when

* every distribution eventuality ``D[mu] a`` applies directly to a proposition ``a``
  (the *event*), never under negation (polarity is counted through ``!``; ``p -> q`` is
  sugar for ``!p | q`` and so counts the left side as negated), and each event has one
  distribution (the same one repeated is fine);
* it is *syntactically co-safe*: in negation normal form there is no unbounded release
  (``G p``, ``p R q``, ``!(p U q)``, ...), so a run satisfies it exactly when some finite
  prefix already decides it, which is what the automaton's reach objective measures.
  ``D[mu] a`` reads as ``F a`` and is fine; bounded ``G[l,u]``/``R[l,u]`` are fine.

:func:`check` runs all checks and returns a :class:`FragmentReport`; anything outside the
fragment raises :class:`FragmentError` naming the offending subformula.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from mitld_lp.distributions import DistributionError, from_spec
from mitld_lp.logic.parser import parse_source
from mitld_lp.logic.source import Source
from mitld_lp.logic.syntax import (
    And,
    Const,
    Dist,
    DistLiteral,
    DistSpec,
    Formula,
    Next,
    Not,
    Or,
    Prop,
    Release,
    Until,
    conj,
    disj,
    dist,
    neg,
    nxt,
    release,
    until,
)

__all__ = [
    "FragmentError",
    "FragmentReport",
    "nnf",
    "event_distributions",
    "is_co_safe",
    "horizon",
    "check",
]

_NOT_CO_SAFE = "unbounded always/release cannot be decided on a finite prefix"


class FragmentError(ValueError):
    """A formula outside the supported fragment; the message names the subformula, and
    starts with ``line:column`` when the formula's text is known (``line`` and
    ``column`` are then set, else ``None``)."""

    def __init__(
        self, subformula: Formula, why: str, line: int | None = None, column: int | None = None
    ) -> None:
        self.subformula = subformula
        self.why = why
        self.line = line
        self.column = column
        where = f"{line}:{column}: " if line is not None else ""
        super().__init__(f"{where}{subformula} {why}")

    def __reduce__(self):
        return (type(self), (self.subformula, self.why, self.line, self.column))


@dataclass(frozen=True, slots=True)
class FragmentReport:
    """What :func:`check` found: the formula as given, its negation normal form, each
    event with its distribution (sorted by event name), whether it is co-safe (always
    true in a report: :func:`check` raises otherwise) and its :func:`horizon`."""

    formula: Formula
    nnf: Formula
    events: tuple[tuple[str, DistSpec], ...]
    co_safe: bool
    horizon: int | None


# --------------------------------------------------------------------------- NNF


def nnf(f: Formula) -> Formula:
    """Negation normal form: negations pushed down to propositions by De Morgan,
    ``!(a U[I] b) == !a R[I] !b``, ``!(a R[I] b) == !a U[I] !b`` and ``!X a == X !a``
    (time is infinite, so every step has a successor).  Built with the smart
    constructors.  Raises :class:`FragmentError` for ``!D[mu] a``, which has no dual in
    the logic (a distribution eventuality cannot be negated).
    """
    return _nnf(f, True)


def _nnf(f: Formula, positive: bool) -> Formula:
    match f:
        case Const(v):
            return Const(v == positive)
        case Prop():
            return f if positive else Not(f)
        case Not(a):
            return _nnf(a, not positive)
        case And(args):
            parts = [_nnf(a, positive) for a in args]
            return conj(*parts) if positive else disj(*parts)
        case Or(args):
            parts = [_nnf(a, positive) for a in args]
            return disj(*parts) if positive else conj(*parts)
        case Until(left, right, iv):
            make = until if positive else release
            return make(_nnf(left, positive), _nnf(right, positive), iv)
        case Release(left, right, iv):
            make = release if positive else until
            return make(_nnf(left, positive), _nnf(right, positive), iv)
        case Next(a):
            return nxt(_nnf(a, positive))
        case Dist(mu, a):
            if not positive:
                raise FragmentError(
                    neg(f), "negates a distribution eventuality, which MITLD^- does not allow"
                )
            return dist(mu, _nnf(a, True))
        case _:
            raise TypeError(f"not a formula: {f!r}")


# --------------------------------------------------------------------------- events


def _with_polarity(f: Formula) -> Iterator[tuple[Formula, bool, Formula | None, Not | None]]:
    """Every subformula occurrence with its polarity (True = under an even number of
    negations), its parent (None for the root) and its nearest ``Not`` ancestor."""
    stack: list[tuple[Formula, bool, Formula | None, Not | None]] = [(f, True, None, None)]
    while stack:
        g, positive, parent, negation = stack.pop()
        yield g, positive, parent, negation
        match g:
            case Not(a):
                stack.append((a, not positive, g, g))
            case Next(a) | Dist(_, a):
                stack.append((a, positive, g, negation))
            case And(args) | Or(args):
                stack.extend((a, positive, g, negation) for a in reversed(args))
            case Until(left, right, _) | Release(left, right, _):
                stack.append((right, positive, g, negation))
                stack.append((left, positive, g, negation))


def event_distributions(f: Formula | Source) -> dict[str, DistSpec]:
    """Each event proposition of ``f`` with its distribution.

    For a :class:`~mitld_lp.logic.source.Source` every ``D[mu] a`` its text writes
    counts, also one the simplification dropped (``D[mu] a & false``), with its polarity
    counted on the text; errors then carry its line and column.

    Raises :class:`FragmentError` when a ``D[mu]`` is not directly followed by a
    proposition, occurs under negation, or when one event gets two different
    distributions.
    """
    if isinstance(f, Source):
        sites = [
            (site.dist, site.positive, None, site.negation, (site.line, site.column))
            for site in f.laws
        ]
    else:
        sites = [
            (g, positive, parent, None if negation is None else str(negation), None)
            for g, positive, parent, negation in _with_polarity(f)
            if isinstance(g, Dist)
        ]
    found: dict[str, DistSpec] = {}
    for g, positive, parent, negation, where in sites:
        assert isinstance(g, Dist)
        at = where or (None, None)
        if not isinstance(g.arg, Prop):
            raise FragmentError(
                g, "is not supported: D[mu] must apply directly to an event proposition", *at
            )
        if not positive:
            why = "is not supported: a distribution eventuality occurs under negation"
            if isinstance(parent, Not):
                raise FragmentError(parent, why)
            raise FragmentError(g, f"{why} (in {negation})", *at)
        event = g.arg.name
        if event in found and found[event] != g.mu:
            raise FragmentError(
                g,
                f"is not supported: event {event} already has the distribution "
                f"{found[event]}; each event gets exactly one",
                *at,
            )
        found[event] = g.mu
    return found


# --------------------------------------------------------------------------- co-safety


def _not_co_safe(f: Formula) -> tuple[Formula, str] | None:
    """The first subformula that makes ``f`` not co-safe, as written by the user (a
    negated unbounded until is named with its ``!``), and why; or None."""
    for g, positive, parent, negation in _with_polarity(f):
        match g:
            case Release(_, _, None) if positive:
                return g, f"is not co-safe: {_NOT_CO_SAFE}"
            case Until(_, _, None) | Dist() if not positive:
                if isinstance(parent, Not):
                    return parent, f"is not co-safe: {_NOT_CO_SAFE}"
                return g, (
                    f"is not co-safe: under negation (in {negation}) it is an unbounded "
                    "release (always), which cannot be decided on a finite prefix"
                )
    return None


def is_co_safe(f: Formula) -> bool:
    """True when the negation normal form of ``f`` has no unbounded release, i.e. no
    unbounded until or ``D`` under negation and no unbounded release outside it.  (Counted
    by polarity, so it also answers for ``!D[mu] a``, which :func:`nnf` refuses.)"""
    return _not_co_safe(f) is None


# --------------------------------------------------------------------------- horizon


def horizon(f: Formula) -> int | None:
    """The number of steps after ``t`` that decide ``f`` at ``t``, or None if unbounded.

    ``f``'s truth at step ``t`` depends only on the letters at steps ``t .. t + h`` (so a
    trace of ``h + 1`` letters decides it at step 0):

    * constants and propositions: 0; ``!``, ``&``, ``|``: the largest of the operands;
    * ``X a``: ``1 + h(a)``;
    * ``a U[l,u] b`` and ``a R[l,u] b``: ``b`` is read at steps up to ``t + u`` and ``a``
      at steps up to ``t + u - 1``, so ``max(u + h(b), u - 1 + h(a))``, and just
      ``h(b)`` when ``u == 0`` (``a`` is never read);
    * unbounded ``U``/``R`` and ``D[mu] a`` (read as ``F a``): None.
    """
    memo: dict[int, int | None] = {}

    def h(g: Formula) -> int | None:
        key = id(g)
        if key in memo:
            return memo[key]
        match g:
            case Const() | Prop():
                out: int | None = 0
            case Not(a):
                out = h(a)
            case Next(a):
                ha = h(a)
                out = None if ha is None else ha + 1
            case And(args) | Or(args):
                hs = [h(a) for a in args]
                out = None if any(x is None for x in hs) else max(x for x in hs if x is not None)
            case Until(left, right, iv) | Release(left, right, iv):
                if iv is None:
                    out = None
                else:
                    hr = h(right)
                    hl = h(left) if iv.hi > 0 else 0
                    if hr is None or hl is None:
                        out = None
                    elif iv.hi == 0:
                        out = hr
                    else:
                        out = max(iv.hi + hr, iv.hi - 1 + hl)
            case Dist():
                out = None
            case _:
                raise TypeError(f"not a formula: {g!r}")
        memo[key] = out
        return out

    return h(f)


# --------------------------------------------------------------------------- check


def check(f: Formula | Source | str) -> FragmentReport:
    """Check that ``f`` is in the supported fragment and report its NNF, events and
    horizon.  Raises :class:`FragmentError` naming the offending subformula otherwise,
    also for an inline law whose values are invalid (``D[geometric(1.5)] a``).

    ``f`` may be the formula's text (parsed with
    :func:`~mitld_lp.logic.parser.parse_source`, so :class:`ParseError` too) or its
    :class:`~mitld_lp.logic.source.Source`: then every ``D[mu] a`` the text writes binds
    its event, also where the simplification dropped it (``(D[mu] e & false) | F e``
    declares the event ``e``), and errors carry the line and column of the subformula.
    """
    source = parse_source(f) if isinstance(f, str) else f
    formula = source.formula if isinstance(source, Source) else source
    events = event_distributions(source)
    for event, mu in events.items():
        if isinstance(mu, DistLiteral):
            try:
                from_spec(mu)
            except DistributionError as err:
                raise FragmentError(
                    dist(mu, Prop(event)), f"has an invalid distribution: {err.reason}"
                ) from None
    bad = _not_co_safe(formula)
    if bad is not None:
        where = source.position(bad[0]) if isinstance(source, Source) else None
        raise FragmentError(*bad, *(where or (None, None)))
    return FragmentReport(
        formula=formula,
        nnf=nnf(formula),
        events=tuple(sorted(events.items())),
        co_safe=True,
        horizon=horizon(formula),
    )
