"""Constraints on a synthesis: the records, their text form and their checks.

A constraint bounds a quantity that is linear in the occupancy measure of the product:

* ``P(FORMULA) <= x`` / ``P(FORMULA) >= x``: the probability that the run satisfies the
  (co-safe) MITLD formula, over the same world and events as the task;
* ``E(steps) <= x``: the expected number of steps until the task is decided;
* ``E(cost) <= x``: the expected cost until the task is decided, each step costing the
  cost of the action taken (a model file's ``[costs]`` table, 1 for an action it omits).

"Until the task is decided": until the task's automaton accepts or rejects, or the run
enters a product state from which no policy can satisfy the task even if every
truncated event came in time (see docs/constraints.md).

The lexicographic option (:data:`THEN`): ``min-steps`` / ``min-cost`` minimises the
expected steps / cost among the policies within :data:`LEXICOGRAPHIC_TOL` of the best
(constrained) probability.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from mitld_lp.logic import FragmentError, ParseError, check, parse_source
from mitld_lp.logic.syntax import Formula

__all__ = [
    "Constraint",
    "ConstraintError",
    "THEN",
    "LEXICOGRAPHIC_TOL",
    "CONSTRAINT_TOL",
    "parse_constraint",
    "parse_constraints",
    "check_costs",
]

THEN = ("min-steps", "min-cost")
"""The secondary objectives of a lexicographic synthesis."""

LEXICOGRAPHIC_TOL = 1e-6
"""A lexicographic synthesis keeps the probability within this of its optimum."""

CONSTRAINT_TOL = 1e-6
"""How far a constraint's exact value on the returned policy may exceed its bound (the
LP's own accuracy) and still count as met."""

_NUMBER = r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?"
_SHAPE = re.compile(
    rf"^\s*(?:(?P<p>P)\s*\((?P<formula>.*)\)|E\s*\(\s*(?P<e>\w+)\s*\))\s*"
    rf"(?P<sense><=|>=)\s*(?P<bound>{_NUMBER})\s*$",
    re.DOTALL,
)


class ConstraintError(ValueError):
    """A constraint that cannot be read; the message names it and the place."""


@dataclass(frozen=True, slots=True)
class Constraint:
    """One bound on one quantity.

    Attributes:
        kind: ``"prob"``, ``"steps"`` or ``"cost"``.
        sense: ``"<="`` or ``">="`` (``>=`` only for ``prob``).
        bound: the number ``x``.
        formula: the formula of a ``prob`` constraint, else None.
        text: the constraint as written (``P(F hazard) <= 0.05``).
    """

    kind: str
    sense: str
    bound: float
    formula: Formula | None = None
    text: str = ""

    def __str__(self) -> str:
        return self.text or self.label()

    def label(self) -> str:
        """The quantity: ``P(formula)``, ``E(steps)`` or ``E(cost)``."""
        return f"P({self.formula})" if self.kind == "prob" else f"E({self.kind})"

    def holds(self, value: float, tol: float = CONSTRAINT_TOL) -> bool:
        """Whether ``value`` meets the bound, to ``tol``."""
        if self.sense == "<=":
            return value <= self.bound + tol
        return value >= self.bound - tol


def parse_constraint(text: str, where: str = "--constraint") -> Constraint:
    """Read ``P(FORMULA) <= x``, ``P(FORMULA) >= x``, ``E(steps) <= x`` or
    ``E(cost) <= x``.  Raises :class:`ConstraintError` ``WHERE: 'text': problem`` (a
    formula's error with its column within ``text``)."""
    if not isinstance(text, str):
        raise ConstraintError(f"{where}: must be a string such as 'P(F hazard) <= 0.05', "
                              f"got {type(text).__name__}")
    m = _SHAPE.match(text)
    head = f"{where}: {text!r}"
    if m is None:
        raise ConstraintError(
            f"{head}: expected 'P(FORMULA) <= x', 'P(FORMULA) >= x', 'E(steps) <= x' or "
            "'E(cost) <= x'"
        )
    bound = float(m["bound"])
    if not math.isfinite(bound):
        raise ConstraintError(f"{head}: the bound must be a finite number")
    sense = m["sense"]
    if m["p"] is None:
        kind = m["e"]
        if kind not in ("steps", "cost"):
            raise ConstraintError(f"{head}: unknown expectation E({kind}); expected E(steps) "
                                  "or E(cost)")
        if sense != "<=":
            raise ConstraintError(f"{head}: an expectation takes an upper bound (<=) only")
        if bound < 0:
            raise ConstraintError(f"{head}: the bound must be >= 0")
        return Constraint(kind, sense, bound, None, text.strip())
    if not 0.0 <= bound <= 1.0:
        raise ConstraintError(f"{head}: a probability bound must be in [0, 1]")
    offset = m.start("formula")
    try:
        source = parse_source(m["formula"])
    except ParseError as exc:
        column = exc.column + (offset if exc.line == 1 else 0)
        raise ConstraintError(f"{head}: {exc.line}:{column}: {exc.reason}") from None
    try:
        report = check(source)
    except FragmentError as exc:
        raise ConstraintError(f"{head}: {exc}") from None
    if not report.co_safe:
        raise ConstraintError(
            f"{head}: a {report.fragment} formula; a constraint's formula must be co-safe "
            "(no unbounded G, R or W in negation normal form)"
        )
    return Constraint("prob", sense, bound, report.formula, text.strip())


def parse_constraints(
    items: Iterable[str | Constraint], where: str = "--constraint"
) -> tuple[Constraint, ...]:
    """Each item read by :func:`parse_constraint` (records are kept as they are)."""
    out = []
    for i, item in enumerate(items):
        out.append(item if isinstance(item, Constraint) else
                   parse_constraint(item, f"{where}[{i}]" if where != "--constraint" else where))
    return tuple(out)


def check_costs(costs: Mapping[str, object], where: str = "costs") -> dict[str, float]:
    """Per-action costs: every value a finite number > 0 (so that a policy of finite
    expected cost leaves every end component, as one of finite expected steps does).
    Raises :class:`ConstraintError` naming the key path."""
    out: dict[str, float] = {}
    for action, value in costs.items():
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConstraintError(f"{where}.{action}: must be a number, got {value!r}")
        if not (math.isfinite(value) and value > 0):
            raise ConstraintError(f"{where}.{action}: must be a finite number > 0, got {value!r}")
        out[str(action)] = float(value)
    return out
