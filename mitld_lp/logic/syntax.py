"""The MITLD abstract syntax: a small core of frozen nodes and sugar built from it.

Core nodes: ``Const`` (true/false), ``Prop``, ``Not``, ``And``, ``Or``, ``Until`` (with an
optional integer interval), ``Release`` (its dual, needed for negation normal form),
``Next`` and ``Dist`` (the distribution eventuality ``D[mu] a``).  Everything else --
``F``, ``G``, ``W``, ``->``, ``F<=k`` -- is sugar that builds core nodes.

The node classes are plain records; the *smart constructors* (``conj``, ``disj``, ``neg``,
``until``, ``release``, ``eventually``, ``always``, ``implies``, ``nxt``, ``dist``)
simplify as they build: they flatten nested ``And``/``Or``, absorb ``true``/``false``,
drop duplicate operands and fold double negation.  The parser and the operator overloads
(``&``, ``|``, ``~``) use them, so every formula a user meets is in that simplified form.

``str(formula)`` prints the parser's own ASCII syntax with the fewest parentheses the
precedence rules allow (loosest first: ``->``, ``|``, ``&``, ``U``/``R``, unary), so that
``parse(str(phi)) == phi``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import TypeAlias

# The law literal node lives with the laws (it builds its law once); the formula layer
# imports the laws, never the reverse.
from mitld_lp.distributions import DistArg, DistLiteral

__all__ = [
    "RESERVED",
    "is_proposition_name",
    "Interval",
    "DistRef",
    "DistLiteral",
    "DistArg",
    "DistSpec",
    "Formula",
    "Const",
    "Prop",
    "Not",
    "And",
    "Or",
    "Until",
    "Release",
    "Next",
    "Dist",
    "TRUE",
    "FALSE",
    "flatten",
    "conj",
    "disj",
    "neg",
    "implies",
    "until",
    "release",
    "weak",
    "eventually",
    "always",
    "nxt",
    "dist",
    "atoms",
    "subformulas",
    "show",
]


#: The words the parser reads as operators (``grammar.lark`` spells each one as a
#: terminal; a test checks the two agree): never a proposition, event, region or
#: distribution name.
RESERVED = frozenset({"true", "false", "X", "F", "G", "U", "R", "W", "D"})

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def is_proposition_name(name: object) -> bool:
    """Whether a formula can write ``name`` as a proposition: letters, digits and ``_``,
    not starting with a digit, and not one of :data:`RESERVED`."""
    return isinstance(name, str) and bool(_NAME.match(name)) and name not in RESERVED


@dataclass(frozen=True, slots=True)
class Interval:
    """A closed integer interval ``[lo, hi]`` of steps, ``0 <= lo <= hi``."""

    lo: int
    hi: int

    def __post_init__(self) -> None:
        for name, v in (("lower bound", self.lo), ("upper bound", self.hi)):
            if isinstance(v, bool) or not isinstance(v, int):
                raise ValueError(f"interval {name} must be an integer, got {v!r}")
        if self.lo < 0:
            raise ValueError(f"interval [{self.lo},{self.hi}]: lower bound must be >= 0")
        if self.lo > self.hi:
            raise ValueError(
                f"interval [{self.lo},{self.hi}]: lower bound {self.lo} exceeds upper bound "
                f"{self.hi}"
            )

    def __str__(self) -> str:
        return f"[{self.lo},{self.hi}]"


# --------------------------------------------------------------------------- distributions


@dataclass(frozen=True, slots=True)
class DistRef:
    """A distribution named in the formula, bound later (e.g. from a model file)."""

    name: str

    def __str__(self) -> str:
        return self.name


DistSpec: TypeAlias = DistRef | DistLiteral


# --------------------------------------------------------------------------- formulas


class Formula:
    """Base class of every formula node.  Supports ``&``, ``|``, ``~`` and ``>>`` (implies)."""

    __slots__ = ()

    def __and__(self, other: Formula) -> Formula:
        return conj(self, other)

    def __or__(self, other: Formula) -> Formula:
        return disj(self, other)

    def __invert__(self) -> Formula:
        return neg(self)

    def __rshift__(self, other: Formula) -> Formula:
        return implies(self, other)

    def __str__(self) -> str:
        return _show(self, 0, None)


@dataclass(frozen=True, slots=True, repr=False)
class Const(Formula):
    """``true`` or ``false``."""

    value: bool
    _hash: int = field(default=0, init=False, repr=False, compare=False)

    def __repr__(self) -> str:
        return "TRUE" if self.value else "FALSE"


@dataclass(frozen=True, slots=True, repr=False)
class Prop(Formula):
    """An atomic proposition: a robot proposition of the game or an external event."""

    name: str
    _hash: int = field(default=0, init=False, repr=False, compare=False)

    def __repr__(self) -> str:
        return f"Prop({self.name!r})"


@dataclass(frozen=True, slots=True, repr=False)
class Not(Formula):
    arg: Formula
    _hash: int = field(default=0, init=False, repr=False, compare=False)

    def __repr__(self) -> str:
        return f"Not({self.arg!r})"


@dataclass(frozen=True, slots=True, repr=False)
class And(Formula):
    """n-ary conjunction (at least two operands, none an ``And``, no ``Const``)."""

    args: tuple[Formula, ...]
    _hash: int = field(default=0, init=False, repr=False, compare=False)

    def __repr__(self) -> str:
        return f"And({', '.join(map(repr, self.args))})"


@dataclass(frozen=True, slots=True, repr=False)
class Or(Formula):
    """n-ary disjunction (at least two operands, none an ``Or``, no ``Const``)."""

    args: tuple[Formula, ...]
    _hash: int = field(default=0, init=False, repr=False, compare=False)

    def __repr__(self) -> str:
        return f"Or({', '.join(map(repr, self.args))})"


@dataclass(frozen=True, slots=True, repr=False)
class Until(Formula):
    """``left U[l,u] right``: some j in [t+l, t+u] has ``right``, and every i in [t, j) has
    ``left``.  ``interval=None`` is the unbounded until (j >= t)."""

    left: Formula
    right: Formula
    interval: Interval | None = None
    _hash: int = field(default=0, init=False, repr=False, compare=False)

    def __repr__(self) -> str:
        return f"Until({self.left!r}, {self.right!r}, {self.interval})"


@dataclass(frozen=True, slots=True, repr=False)
class Release(Formula):
    """``left R[l,u] right == !(!left U[l,u] !right)``: every j in [t+l, t+u] has ``right``
    unless ``left`` held at some i in [t, j).  ``G[l,u] p == false R[l,u] p``."""

    left: Formula
    right: Formula
    interval: Interval | None = None
    _hash: int = field(default=0, init=False, repr=False, compare=False)

    def __repr__(self) -> str:
        return f"Release({self.left!r}, {self.right!r}, {self.interval})"


@dataclass(frozen=True, slots=True, repr=False)
class Next(Formula):
    """``X arg``: ``arg`` holds at the next step."""

    arg: Formula
    _hash: int = field(default=0, init=False, repr=False, compare=False)

    def __repr__(self) -> str:
        return f"Next({self.arg!r})"


@dataclass(frozen=True, slots=True, repr=False)
class Dist(Formula):
    """The distribution eventuality ``D[mu] arg``: the first step at which ``arg`` holds
    is distributed as ``mu``.  For the automaton it reads as ``F arg``."""

    mu: DistSpec
    arg: Formula
    _hash: int = field(default=0, init=False, repr=False, compare=False)

    def __repr__(self) -> str:
        return f"Dist({self.mu}, {self.arg!r})"


def _cached_hash(self) -> int:
    # Formulas are deep trees hashed over and over as dict keys (automaton states are
    # formulas); the dataclass hash would walk the whole tree every time.
    h = self._hash
    if not h:
        h = hash((type(self).__name__, *(getattr(self, f) for f in self.__match_args__))) or 1
        object.__setattr__(self, "_hash", h)
    return h


for _cls in (Const, Prop, Not, And, Or, Until, Release, Next, Dist):
    _cls.__hash__ = _cached_hash  # type: ignore[method-assign]

TRUE = Const(True)
FALSE = Const(False)


# --------------------------------------------------------------------------- constructors


def flatten(kind: type[And] | type[Or], args: Iterable[Formula]) -> list[Formula] | Const:
    """The operands of ``kind(*args)`` with nested ``kind`` nodes flattened, the unit
    (``true`` for ``And``, ``false`` for ``Or``) dropped and duplicates removed, in order
    of first occurrence; or the zero (``false``/``true``) when an operand is it.  Shared by
    the simplifying constructors here and the canonical ones of
    :mod:`mitld_lp.logic.normal`."""
    zero = FALSE if kind is And else TRUE
    out: dict[Formula, None] = {}
    for a in args:
        if not isinstance(a, Formula):
            raise TypeError(f"expected a Formula, got {a!r}")
        for p in a.args if isinstance(a, kind) else (a,):
            # ``p == zero`` and ``p != unit`` as the dataclass compares: only a Const
            # equals a Const, by its value (asked here first: the automaton's
            # construction flattens thousands of operands, most of them not constants)
            if type(p) is Const:
                if p.value == zero.value:
                    return zero
            else:
                out[p] = None
    return list(out)


def _nary(kind: type[And] | type[Or], args: tuple[Formula, ...]) -> Formula:
    out = flatten(kind, args)
    if isinstance(out, Const):
        return out
    if not out:
        return TRUE if kind is And else FALSE
    if len(out) == 1:
        return out[0]
    return kind(tuple(out))


def conj(*args: Formula) -> Formula:
    """Conjunction, flattened, with ``true`` dropped, ``false`` absorbing, duplicates removed."""
    return _nary(And, args)


def disj(*args: Formula) -> Formula:
    """Disjunction, flattened, with ``false`` dropped, ``true`` absorbing, duplicates removed."""
    return _nary(Or, args)


def neg(arg: Formula) -> Formula:
    """Negation with ``!true == false``, ``!false == true`` and ``!!p == p``."""
    if isinstance(arg, Const):
        return Const(not arg.value)
    if isinstance(arg, Not):
        return arg.arg
    return Not(arg)


def implies(left: Formula, right: Formula) -> Formula:
    """``left -> right == !left | right``."""
    return disj(neg(left), right)


def _interval(bounds: Interval | tuple[int, int] | None) -> Interval | None:
    if bounds is None or isinstance(bounds, Interval):
        return bounds
    lo, hi = bounds
    return Interval(lo, hi)


def until(
    left: Formula, right: Formula, interval: Interval | tuple[int, int] | None = None
) -> Formula:
    """``left U[l,u] right``, with ``right == false`` giving false and, for an interval
    starting at 0, ``right == true`` giving true."""
    iv = _interval(interval)
    if right == FALSE:
        return FALSE
    if right == TRUE and (iv is None or iv.lo == 0):
        return TRUE
    return Until(left, right, iv)


def release(
    left: Formula, right: Formula, interval: Interval | tuple[int, int] | None = None
) -> Formula:
    """``left R[l,u] right``, the dual of until: ``right == true`` gives true and, for an
    interval starting at 0, ``right == false`` gives false."""
    iv = _interval(interval)
    if right == TRUE:
        return TRUE
    if right == FALSE and (iv is None or iv.lo == 0):
        return FALSE
    return Release(left, right, iv)


def weak(left: Formula, right: Formula) -> Formula:
    """The weak until ``left W right == (left U right) | G left``: ``left`` holds at every
    step before the first ``right``, and forever if ``right`` never comes.  Kept in core
    form as ``right R (left | right)`` (equal with the strict until: a step with neither
    ``left`` nor ``right`` is allowed only after a ``right``), printed back as ``W``."""
    return release(right, disj(left, right))


def eventually(arg: Formula, interval: Interval | tuple[int, int] | None = None) -> Formula:
    """``F[l,u] arg == true U[l,u] arg``."""
    return until(TRUE, arg, interval)


def always(arg: Formula, interval: Interval | tuple[int, int] | None = None) -> Formula:
    """``G[l,u] arg == !F[l,u] !arg``, kept in core form as ``!(true U[l,u] !arg)``."""
    return neg(eventually(neg(arg), interval))


def nxt(arg: Formula) -> Formula:
    """``X arg``; ``X true == true`` and ``X false == false``."""
    if isinstance(arg, Const):
        return arg
    return Next(arg)


def dist(mu: DistSpec, arg: Formula) -> Formula:
    """The distribution eventuality ``D[mu] arg``."""
    return Dist(mu, arg)


# --------------------------------------------------------------------------- traversal


def subformulas(f: Formula):
    """Every subformula of ``f`` (pre-order, ``f`` first; shared subterms repeated)."""
    stack = [f]
    while stack:
        g = stack.pop()
        yield g
        match g:
            case Not(a) | Next(a) | Dist(_, a):
                stack.append(a)
            case And(args) | Or(args):
                stack.extend(reversed(args))
            case Until(left, right, _) | Release(left, right, _):
                stack.append(right)
                stack.append(left)


def atoms(f: Formula) -> frozenset[str]:
    """The names of the propositions that occur in ``f``."""
    return frozenset(g.name for g in subformulas(f) if isinstance(g, Prop))


# --------------------------------------------------------------------------- printing

# Precedence levels, loosest first; a child printed at a level below its context is
# parenthesised.  ``->`` is sugar and never printed (``!a | b`` parses to the same node).
_OR, _AND, _BIN, _UNARY = 1, 2, 3, 4


def _bracket(iv: Interval | None) -> str:
    return "" if iv is None else str(iv)


def show(f: Formula, replace: Mapping[Formula, str]) -> str:
    """``str(f)``, except that each subformula that is a key of ``replace`` is printed as
    its value (parenthesised as the subformula would be).  Used to show an automaton
    state with the intervals of the source formula and its clock values."""
    return _show(f, 0, replace)


def _show(f: Formula, ctx: int, over: Mapping[Formula, str] | None) -> str:
    def sub(g: Formula, level: int) -> str:
        return _show(g, level, over)

    match f:
        case Const(v):
            return "true" if v else "false"
        case Prop(name):
            return name
        case Not(Until(Const(True), Not(inner), iv)):
            text, level = f"G{_bracket(iv)} {sub(inner, _UNARY)}", _UNARY
        case Not(a):
            text, level = f"!{sub(a, _UNARY)}", _UNARY
        case Next(a):
            text, level = f"X {sub(a, _UNARY)}", _UNARY
        case Dist(mu, a):
            text, level = f"D[{mu}] {sub(a, _UNARY)}", _UNARY
        case Until(Const(True), right, iv):
            text, level = f"F{_bracket(iv)} {sub(right, _UNARY)}", _UNARY
        case Release(right, Or(args), None) if args[-1] == right:
            # ``a W b`` is ``b R (a | b)`` with ``b`` the last operand, as ``weak`` builds it
            left = args[0] if len(args) == 2 else Or(args[:-1])
            text = f"{sub(left, _UNARY)} W {sub(right, _UNARY)}"
            level = _BIN
        case Release(right, same, None) if same == right:
            text, level = f"{sub(right, _UNARY)} W {sub(right, _UNARY)}", _BIN
        case Release(Const(False), right, iv):
            # ``false R p`` is ``G p`` but is a different node from ``!(true U !p)``, so
            # it keeps the R syntax to round-trip.
            text, level = f"false R{_bracket(iv)} {sub(right, _UNARY)}", _BIN
        case Until(left, right, iv):
            text = f"{sub(left, _UNARY)} U{_bracket(iv)} {sub(right, _UNARY)}"
            level = _BIN
        case Release(left, right, iv):
            text = f"{sub(left, _UNARY)} R{_bracket(iv)} {sub(right, _UNARY)}"
            level = _BIN
        case And(args):
            text, level = " & ".join(sub(a, _AND + 1) for a in args), _AND
        case Or(args):
            text, level = " | ".join(sub(a, _OR + 1) for a in args), _OR
        case _:
            raise TypeError(f"not a formula: {f!r}")
    if over is not None and f in over:
        text = over[f]
    return f"({text})" if level < ctx else text
