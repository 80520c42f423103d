"""The library's defaults, each defined once; every stage and the CLI read them here,
with the one range check of the truncation budget."""

from __future__ import annotations

import math
import numbers

__all__ = [
    "EPSILON",
    "MAX_STATES",
    "MAX_AUTOMATON_STATES",
    "TOL",
    "PRECISION",
    "CERTIFY_TOL",
    "SOLVER",
    "RUNS",
    "MAX_RUNS",
    "MAX_STEPS",
    "MAX_STEPS_LIMIT",
    "EXACT_MAX_TRANSITIONS",
    "EXACT_MAX_BLOCK",
    "check_epsilon",
]

EPSILON = 0.01
"""Truncation budget shared over the events whose hazard never becomes constant."""

MAX_STATES = 5_000_000
"""Largest state space built (the product's reachable states; the automaton's too)
before refusing with the numbers."""

MAX_AUTOMATON_STATES = 200_000
"""Largest automaton built, on top of :data:`MAX_STATES`: an automaton state (an
obligation with its transition diagram) takes about 5 KB and 1 ms to build where a
product state takes tens of bytes, so the product's budget would let one formula take
some 25 GB and hours before the budget acted; 200,000 is about 1 GB and minutes."""

TOL = 1e-9
"""Accuracy asked of the solvers (LP gap and feasibility, interval-iteration gap)."""

CERTIFY_TOL = 1e-6
"""How far a value computed in floating point to a solver's tolerance (the constrained
LP's optimum) may lie below a certified bound and still count as consistent with it (the
robust constrained route's check); every other bound is checked in exact arithmetic
(:mod:`mitld_lp.solvers.certify`), with no tolerance."""

PRECISION = 1e-6
"""The relative precision asked (Storm's sound mode's default; ``--precision``,
``[solve] precision``): a certified bracket is at most ``PRECISION * lower`` wide where
no truncation is involved (with truncation, the solver's part of its width,
docs/results.md), and interval iteration closes a bracket when its gap is below both
:data:`TOL` and ``PRECISION`` times its lower bound, so a rare value (1e-30) is known to
six digits."""

SOLVER = "CLARABEL"
"""The LP solver, called directly on the sparse matrices (no cvxpy needed)."""

RUNS = 10_000
"""Monte-Carlo rollouts of a controller (a 95% interval of about +-0.01)."""

MAX_RUNS = 100_000_000
"""The most rollouts accepted: at tens of thousands a second, more would take days,
and the 95% interval's half-width is already below 1e-4."""

MAX_STEPS = 1000
"""Steps after which a rollout still undecided stops and counts as undecided."""

MAX_STEPS_LIMIT = 1_000_000
"""The largest ``max_steps`` accepted for a rollout."""

EXACT_MAX_TRANSITIONS = 1_000_000
"""The largest product an exact answer (``--exact``) takes, in transitions: each is
recomputed and multiplied in rational arithmetic in Python, some microseconds each and
more as the numbers grow (checked before the exact work)."""

EXACT_MAX_BLOCK = 1_000
"""The largest strongly connected block of a policy's chain an exact answer factorises:
one dense rational solve of that size (python-flint), about 3 s and 6,000-digit
numbers at 1,000 states, growing with the cube (checked before each solve, and on the
floating-point policy's chain before the exact work)."""


def check_epsilon(value: object) -> float:
    """``value`` as a truncation budget: a real number strictly between 0 and 1.

    Raises ``ValueError("must be a number in (0, 1), got ...")``; the caller names the
    place (a key path, an option, an argument).
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"must be a number in (0, 1), got {value!r}")
    number = float(value)
    if not (math.isfinite(number) and 0.0 < number < 1.0):  # also refuses nan
        raise ValueError(f"must be a number in (0, 1), got {value!r}")
    return number
