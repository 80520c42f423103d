"""The library's defaults, each defined once; every stage and the CLI read them here,
with the one range check of each setting a user gives (the truncation budget, seconds,
counts, bytes, tolerances: the library, the command line, a model file's ``[budgets]``
and a sweep's ``[solve]`` apply the same rule, each naming the place) and the names a
method, a backend and an objective may have."""

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
    "HORIZON_MAX_WORK",
    "METHODS",
    "BACKENDS",
    "OBJECTIVES",
    "BANDS",
    "MAX_MEMORY_SIZE",
    "check_epsilon",
    "check_unit",
    "check_seconds",
    "check_count",
    "check_bytes",
    "check_memory",
    "check_bands",
    "parse_size",
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

HORIZON_MAX_WORK = 1_000_000_000
"""The most work of a step-bounded reward (``C<=k``, ``I=k``) past the exact budget,
``k`` times the transitions and choices: each step one sparse product per bound in
floating point, about a second per 100 million (checked before the work)."""

EXACT_MAX_BLOCK = 1_000
"""The largest strongly connected block of a policy's chain an exact answer factorises:
one dense rational solve of that size (python-flint), about 3 s and 6,000-digit
numbers at 1,000 states, growing with the cube (checked before each solve, and on the
floating-point policy's chain before the exact work)."""


#: The solve methods: the occupancy LP (with interval iteration as its cross-check) or
#: interval iteration alone.
METHODS = ("lp", "vi")
#: How an LP reaches its solver: cvxpy for any solver but Clarabel, Clarabel directly.
BACKENDS = ("auto", "cvxpy", "direct")
#: What is optimised: the probability's maximum or minimum.
OBJECTIVES = ("max", "min")
#: How a law known only within a band is read: ``worst``, the law of the band worst for
#: the robot at every step (nature against it: PRISM's ``Pmaxmin``, Storm's robust
#: resolution), or ``best``, the law best for it (nature with it: ``Pmaxmax``, Storm's
#: cooperative resolution); the spread between the two is what the band leaves open.
BANDS = ("worst", "best")

MAX_MEMORY_SIZE = (1 << 63) - 1
"""The largest memory budget accepted (8E less a byte): a byte count is a signed 64-bit
integer to the operating system, and no machine comes near it."""

_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40, "P": 1 << 50,
          "E": 1 << 60}


def _real(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return None
    return float(value)


def check_unit(value: object, shown: str | None = None) -> float:
    """``value`` as a real number strictly between 0 and 1 (a truncation budget, a
    tolerance, a precision).  Raises ``ValueError("must be a number in (0, 1), got
    ...")`` (``shown``: how the caller writes the value); the caller names the place (a
    key path, an option, an argument)."""
    number = _real(value)
    if number is None or not (math.isfinite(number) and 0.0 < number < 1.0):  # nan too
        raise ValueError(f"must be a number in (0, 1), got {shown or repr(value)}")
    return number


def check_epsilon(value: object) -> float:
    """``value`` as a truncation budget (:func:`check_unit`)."""
    return check_unit(value)


def check_seconds(value: object, shown: str | None = None) -> float:
    """``value`` as a time limit: a positive, finite number of seconds (zero is refused
    on every surface: no work fits in it)."""
    number = _real(value)
    if number is None or not 0.0 < number < math.inf:
        raise ValueError(f"must be a positive number of seconds, got {shown or repr(value)}")
    return number


def check_count(value: object, shown: str | None = None) -> int:
    """``value`` as a state budget: a whole number >= 1."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
        raise ValueError(f"must be a whole number >= 1, got {shown or repr(value)}")
    return int(value)


def check_bytes(value: object, shown: str | None = None) -> int:
    """``value`` as a memory budget: a whole number of bytes from 1 to
    :data:`MAX_MEMORY_SIZE`."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not (
            1 <= int(value) <= MAX_MEMORY_SIZE):
        raise ValueError(f"must be a number of bytes from 1 to 2^63 - 1, got "
                         f"{shown or repr(value)}")
    return int(value)


def check_memory(value: object, shown: str | None = None) -> int:
    """A file's memory budget: a number of bytes (:func:`check_bytes`) or a size
    written as text (:func:`parse_size`)."""
    return parse_size(value) if isinstance(value, str) else check_bytes(value, shown)


def check_bands(value: object, shown: str | None = None) -> str:
    """``value`` as a reading of the bands: one of :data:`BANDS`."""
    if not isinstance(value, str) or value not in BANDS:
        raise ValueError(f"must be 'worst' or 'best', got {shown or repr(value)}")
    return str(value)


def parse_size(text: str) -> int:
    """A memory budget written as a size: ``500M``, ``4G``, ``1.5G``, ``2P`` (``K M G T
    P E``, each 1024 times the last; a trailing ``B`` or ``iB`` is allowed), held to
    :func:`check_bytes`'s range."""
    body = text.strip().upper().removesuffix("B").removesuffix("I")
    unit = body[-1:] if body[-1:] in _UNITS and body[-1:] else ""
    try:
        number = float(body[: len(body) - len(unit)])
    except ValueError:
        raise ValueError(f"must be a size such as 4G or 500M, got {text!r}") from None
    if not number == number or number in (math.inf, -math.inf):  # nan, inf
        raise ValueError(f"must be a finite size, got {text!r}")
    value = number * _UNITS[unit]
    if value < 1:
        raise ValueError(f"must be a positive size (at least 1 byte), got {text!r}")
    if value > MAX_MEMORY_SIZE:
        raise ValueError(f"must be below 8E (2^63 bytes), got {text!r}")
    return int(value)
