"""The supported fragment: negation normal form, the events and the formula's class.

A formula is supported when

* every distribution eventuality ``D[mu] a`` applies directly to a proposition ``a``
  (the *event*), never under negation (polarity is counted through ``!``; ``p -> q`` is
  sugar for ``!p | q`` and so counts the left side as negated), and each event has one
  distribution (the same one repeated is fine);
* it is an *obligation* formula, syntactically: in negation normal form (where
  ``D[mu] a`` reads as ``F a``) no unbounded until (``F``, ``U``, ``D``) has an unbounded
  release (``G``, ``R``, ``W``) inside it and no unbounded release has an unbounded until
  inside it.  Bounded operators, ``X``, ``&`` and ``|`` combine freely.  Its class is then

  - **co-safe**: no unbounded release; a run satisfies it exactly when a finite prefix
    already decides it true (a reach objective);
  - **safety**: no unbounded until; a run violates it exactly when a finite prefix
    already decides it false (``G !h``, ``G (p -> F[0,3] q)``, ``!h W goal``);
  - **obligation**: both kinds, combined by ``&``/``|`` (``G !h & F goal``).

  Outside are *persistence* (an unbounded until over an unbounded release, ``F G p``),
  *recurrence* (the reverse, ``G F p``) and their combinations (*reactivity*).
  Formulas without unbounded operators are counted co-safe.

:func:`check` runs all checks and returns a :class:`FragmentReport`; anything outside the
fragment raises :class:`FragmentError` naming the offending subformula (and, given the
formula's text, its line and column).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from mitld_lp.distributions import DistributionError
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
    "classify",
    "CO_SAFE",
    "SAFETY",
    "OBLIGATION",
    "PERSISTENCE",
    "RECURRENCE",
    "REACTIVITY",
    "SUPPORTED",
    "horizon",
    "check",
]

#: The classes of :func:`classify`; the first three are supported.
CO_SAFE = "co-safe"
SAFETY = "safety"
OBLIGATION = "obligation"
PERSISTENCE = "persistence"
RECURRENCE = "recurrence"
REACTIVITY = "reactivity"
SUPPORTED = (CO_SAFE, SAFETY, OBLIGATION)

_OUTSIDE = {
    PERSISTENCE: "an unbounded eventually/until over an unbounded always/release, like "
    "F G p, holds when something holds forever from an unknown step on",
    RECURRENCE: "an unbounded always/release over an unbounded eventually/until, like "
    "G F p, asks for something infinitely often",
}
_SUPPORTED_TEXT = (
    "supported are co-safe, safety and obligation formulas (&/| combinations of formulas "
    "without unbounded G/R/W and formulas without unbounded F/U)"
)


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
    """What :func:`check` found: the formula (as given, or as its text simplifies), its
    negation normal form, each event with its distribution (sorted by event name),
    whether it is co-safe, its :func:`horizon` and its class (``fragment``: one of
    :data:`SUPPORTED`, :func:`check` raises otherwise)."""

    formula: Formula
    nnf: Formula
    events: tuple[tuple[str, DistSpec], ...]
    co_safe: bool
    horizon: int | None
    fragment: str


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


@dataclass(frozen=True, slots=True)
class _Shape:
    """What the negation normal form of a subformula contains: an unbounded until, an
    unbounded release, an until with a release inside (persistence), a release with an
    until inside (recurrence)."""

    until: bool = False
    release: bool = False
    persistence: bool = False
    recurrence: bool = False

    def join(self, other: _Shape) -> _Shape:
        return _Shape(*(a or b for a, b in zip(self.astuple(), other.astuple(), strict=True)))

    def astuple(self) -> tuple[bool, bool, bool, bool]:
        return (self.until, self.release, self.persistence, self.recurrence)

    @property
    def kind(self) -> str:
        if self.persistence and self.recurrence:
            return REACTIVITY
        if self.persistence:
            return PERSISTENCE
        if self.recurrence:
            return RECURRENCE
        if self.until and self.release:
            return OBLIGATION
        return SAFETY if self.release else CO_SAFE


def _shapes(f: Formula) -> tuple[_Shape, tuple[Formula, str, str] | None]:
    """The :class:`_Shape` of ``f`` and the innermost subformula that makes it
    persistence or recurrence (as written: an operator that is negated is named with its
    ``!``), a note, and that class; polarity is counted through ``!``."""
    memo: dict[tuple[int, bool], _Shape] = {}
    worst: list[tuple[Formula, str, str]] = []

    def shape(g: Formula, positive: bool, parent: Formula | None) -> _Shape:
        key = (id(g), positive)
        hit = memo.get(key)
        if hit is not None:
            return hit
        match g:
            case Const() | Prop():
                out = _Shape()
            case Not(a):
                out = shape(a, not positive, g)
            case Next(a):
                out = shape(a, positive, g)
            case And(args) | Or(args):
                out = _Shape()
                for a in args:
                    out = out.join(shape(a, positive, g))
            case Until(left, right, iv) | Release(left, right, iv):
                inner = shape(left, positive, g).join(shape(right, positive, g))
                out = inner
                if iv is None:
                    eventual = isinstance(g, Until) == positive
                    out = _nest(inner, eventual, _as_written(g, positive, parent), worst)
            case Dist(_, a):  # F a
                named = _as_written(g, positive, parent)
                out = _nest(shape(a, positive, g), positive, named, worst)
            case _:
                raise TypeError(f"not a formula: {g!r}")
        memo[key] = out
        return out

    top = shape(f, True, None)
    return top, (worst[0] if worst else None)


def _as_written(g: Formula, positive: bool, parent: Formula | None) -> tuple[Formula, str]:
    """How to name operator ``g`` in a message: with the ``!`` just above it when that
    negation turns it into its dual (``G p`` is ``!(true U !p)``), or with a note when a
    negation further up does."""
    if positive:
        return g, ""
    if isinstance(parent, Not):
        return parent, ""
    return g, " under negation"


def _nest(
    inner: _Shape,
    eventual: bool,
    named: tuple[Formula, str],
    worst: list[tuple[Formula, str, str]],
) -> _Shape:
    """The shape of an unbounded until (``eventual``) or release over operands of shape
    ``inner``; the first nesting found (none is below it) is kept in ``worst`` under
    ``named``: the operator, or the ``!`` above it when it is negated (``G p`` is
    ``!(true U !p)``)."""
    if eventual:
        out = _Shape(True, inner.release, inner.persistence or inner.release, inner.recurrence)
        nested = inner.release
    else:
        out = _Shape(inner.until, True, inner.persistence, inner.recurrence or inner.until)
        nested = inner.until
    if nested and not worst:
        worst.append((*named, PERSISTENCE if eventual else RECURRENCE))
    return out


def classify(f: Formula) -> str:
    """The syntactic class of ``f`` (see the module docstring): :data:`CO_SAFE`,
    :data:`SAFETY`, :data:`OBLIGATION`, :data:`PERSISTENCE`, :data:`RECURRENCE` or
    :data:`REACTIVITY`.  Counted by polarity, so it also answers for ``!D[mu] a`` (a
    release), which :func:`nnf` refuses."""
    return _shapes(f)[0].kind


def is_co_safe(f: Formula) -> bool:
    """True when the negation normal form of ``f`` has no unbounded release, i.e. no
    unbounded until or ``D`` under negation and no unbounded release outside it."""
    return classify(f) == CO_SAFE


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
    also for an inline law whose values are invalid (``D[geometric(1.5)] a``); a literal
    the parser already built is not built again (:attr:`DistLiteral.law` is kept).

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
                mu.law  # noqa: B018 - built once per literal, kept by it
            except DistributionError as err:
                raise FragmentError(
                    dist(mu, Prop(event)), f"has an invalid distribution: {err.reason}"
                ) from None
    shape, worst = _shapes(formula)
    if worst is not None:
        named, note, kind = worst
        where = source.position(named) if isinstance(source, Source) else None
        raise FragmentError(
            named, f"is{note} a {kind} formula ({_OUTSIDE[kind]}); {_SUPPORTED_TEXT}",
            *(where or (None, None)),
        )
    return FragmentReport(
        formula=formula,
        nnf=nnf(formula),
        events=tuple(sorted(events.items())),
        co_safe=shape.kind == CO_SAFE,
        horizon=horizon(formula),
        fragment=shape.kind,
    )
