r"""Float sums bounded in exact arithmetic, the probabilities' allowance, and directed
rounding: what the certificates (:mod:`mitld_lp.solvers.certify`) rest on.

The product stores floats ``p^`` for the model's exact probabilities ``p`` with
``|p^ - p| <= eta * p`` (:data:`ETA`, :func:`model_eta`).

One bound of a float sum: for a row of ``n`` stored entries and ``x >= 0``, the float
``s^`` of ``sum_j p^_j x_j`` (any order, FMA or not) satisfies
``|s^ - sum p^ x| <= gamma_n sum p^ x`` plus ``n 2^-1075`` of underflow, with
``gamma_n = n u / (1 - n u)``, ``u = 2^-53``; so
``(s^ - D) / ((1 + gamma_n)(1 + eta)) <= sum_j p_j x_j <= (s^ + D) / ((1 - gamma_n)(1 - eta))``.
:class:`Rounding` holds per row factors below and above these (with four units of
margin for the two float operations that apply them): :func:`below`, :func:`above`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.result import read_only
from mitld_lp.solvers.rows import row_entries

if TYPE_CHECKING:
    from mitld_lp.automata.sta import STA

__all__ = ["UNIT", "ETA", "ETA_LIMIT", "TINY", "HAZARD_ACCURACY", "Rounding", "rounding", "below",
           "above", "support_extreme", "range_extreme", "model_eta", "float_down", "float_up",
           "one_minus"]

UNIT = 2.0**-53
"""The unit roundoff of IEEE double precision (round to nearest)."""

ETA = 2.0**-44
r"""The relative distance allowed between a stored probability and the model's exact
one, ``|p^ - p| <= ETA * p`` (about ``5.7e-14``, 512 units of roundoff ``u``).  Every
builder computes a probability from the model's decimals by a few dozen correctly
rounded operations on positive numbers at most, each adding at most ``u = 2^-53``
relative error: a decimal read as the nearest double (TOML) or by Storm, which folds a
PRISM program's constant expressions in rational arithmetic before one conversion (at
most ``2u``); a product of a world probability and the events' hazard factors (one
``u`` per factor); duplicate successors merged by a sum of positive terms (``(k - 1)
u`` for ``k`` terms).  The one subtraction that can cancel, ``1 - h`` for an event
that does not happen, is added per model by :func:`model_eta` (and the sensed route's
posterior weights, products along a history, by their length); a PRISM probability
computed from state variables by an expression that cancels (``1 - p*x`` near 0) is
outside this claim (docs/results.md)."""

TINY = 2.0**-1073
"""Four times the smallest subnormal: the absolute slack per term for underflow."""

HAZARD_ACCURACY = 2.0**-48
"""The relative accuracy assumed of a law's hazard as computed (closed forms and table
laws: a few roundings; SciPy's laws: their documented double accuracy)."""

BATCH = 1 << 16
"""Rows read at a time by :func:`support_extreme` (its memory bound, not its answer)."""


# ------------------------------------------------------------------ rigorous row sums


@dataclass(frozen=True, slots=True, eq=False)
class Rounding:
    """Per row of an MDP's matrix: ``low`` / ``high``, factors that turn a float row sum
    into a bound below / above the exact model's, and ``slack``, the absolute term for
    underflow (module docs); ``eta`` the probabilities' allowance they include.  Each
    depends on the row's count of stored entries alone: held as that count per row
    (``count``, 4 bytes where it fits) and the three values per count (``low_of``,
    ``high_of``, ``slack_of``), not three floats a row through the whole certificate."""

    count: np.ndarray
    low_of: np.ndarray
    high_of: np.ndarray
    slack_of: np.ndarray
    eta: float

    @property
    def low(self) -> np.ndarray:
        return self.low_of[self.count]

    @property
    def high(self) -> np.ndarray:
        return self.high_of[self.count]

    @property
    def slack(self) -> np.ndarray:
        return self.slack_of[self.count]


ETA_LIMIT = 2.0**-3
"""The largest allowance the one-step factors serve (``1 / ((1 - g)(1 - eta)) <= 1 +
2 (g + eta)`` needs ``g + eta <= 1/2``): past it a row's sum is bounded by 0 below and
infinity above, sound and useless, so every check that needs arithmetic fails."""


def rounding(matrix: sp.csr_array, eta: float = ETA) -> Rounding:
    """The :class:`Rounding` of ``matrix``'s rows for the allowance ``eta`` (past
    :data:`ETA_LIMIT`: the trivial factors 0 and infinity)."""
    if not eta >= 0.0:
        raise ValueError(f"eta: must be a number >= 0, got {eta!r}")
    indptr = np.asarray(matrix.indptr)
    count = np.diff(indptr).astype(np.int32 if indptr[-1] < np.iinfo(np.int32).max
                                   else np.int64)
    n = np.arange(int(count.max(initial=0)) + 1, dtype=np.float64)  # every count
    slack = read_only((n + 4.0) * TINY)
    if eta > ETA_LIMIT:
        return Rounding(read_only(count), read_only(np.zeros_like(n)),
                        read_only(np.full_like(n, np.inf)), slack, float(eta))
    gamma = n * UNIT / (1.0 - n * UNIT)
    margin = 1.0 + 2.0**-20  # the constants' own rounding
    low = (gamma + eta + gamma * eta + 4.0 * UNIT) * margin
    high = (2.0 * (gamma + eta) + 4.0 * UNIT) * margin
    return Rounding(read_only(count), read_only(1.0 - low), read_only(1.0 + high), slack,
                    float(eta))


def below(r: Rounding, rows: np.ndarray | slice, sums: np.ndarray) -> np.ndarray:
    """A lower bound on the exact ``E_c(x)`` of each choice ``rows`` (indices, or
    ``slice(None)`` for every row) from the float sums ``sums`` of ``P^[c] @ x``
    (``x >= 0``)."""
    count = r.count[rows]
    out = sums - r.slack_of[count]  # in place from here: one array a row, not three
    out *= r.low_of[count]
    return np.maximum(out, 0.0, out=out)


def above(r: Rounding, rows: np.ndarray | slice, sums: np.ndarray) -> np.ndarray:
    """An upper bound on the exact ``E_c(x)`` of each choice ``rows`` (``x >= 0``)."""
    count = r.count[rows]
    out = sums + r.slack_of[count]
    out *= r.high_of[count]
    return out


def support_extreme(matrix: sp.csr_array, rows: np.ndarray, x: np.ndarray,
                     largest: bool) -> np.ndarray:
    """Per row of ``rows``: the largest (smallest) ``x`` over its support, read
    :data:`BATCH` rows at a time (the gathered entries of every row at once cost 24
    bytes an entry: most of the certificate's peak on a product of a million choices)."""
    out = np.full(rows.size, -np.inf if largest else np.inf)
    pick = np.maximum if largest else np.minimum
    for a in range(0, rows.size, BATCH):
        local, cols, _ = row_entries(matrix, rows[a:a + BATCH])
        pick.at(out[a:a + BATCH], local, x[cols])
    return out


def range_extreme(matrix: sp.csr_array, a: int, z: int, x: np.ndarray,
                  largest: bool) -> np.ndarray:
    """:func:`support_extreme` of the consecutive rows ``a:z`` (-inf / inf on an empty
    row, as there): their entries are one slice of the matrix's arrays, so ``x`` is
    read at the slice's columns and reduced row by row where each row starts (one
    gather and one ``reduceat``), with no index array of the rows, no gathered copy of
    their entries and no ``ufunc.at``.  A maximum or minimum is exact, in any order:
    the same values.  For a batch where most rows are asked (QVBS ``zeroconf_dl``
    1000-1-30: 161,464 of 195,261 rows in the Bellman check of the upper bound, those of
    the states at 1 and at 0)."""
    ptr = matrix.indptr
    ea, ez = int(ptr[a]), int(ptr[z])
    out = np.full(z - a, -np.inf if largest else np.inf)
    if ez == ea:
        return out
    starts = ptr[a:z] - ea
    filled = ptr[a + 1:z + 1] > ptr[a:z]
    reached = x[matrix.indices[ea:ez]]
    pick = np.maximum if largest else np.minimum
    if filled.all():
        return pick.reduceat(reached, starts)
    out[filled] = pick.reduceat(reached, starts[filled])
    return out


# ------------------------------------------------------------------ the allowance eta


def model_eta(sta: STA | None, *, history: bool = False) -> float:
    """The probabilities' allowance of a product built with ``sta``'s laws: :data:`ETA`
    plus, per event, the largest cancellation of ``1 - h`` over the hazards its clock
    reads (``h * HAZARD_ACCURACY / (1 - h)``, the relative error of ``1 - h`` when ``h``
    is accurate to :data:`HAZARD_ACCURACY`); past :data:`ETA_LIMIT` (a hazard within
    about ``2^-45`` of 1) the rows' sums are bounded by 0 and infinity, and the
    certificates' checks fail (:func:`rounding`).  ``history``:
    the probabilities are also products along an event's history (the sensed route's
    posterior weights: a few roundings a step up to its truncation point or cap), each
    step adding ``4u``."""
    eta = ETA
    if sta is None:
        return eta
    for clock in sta.clocks.values():
        worst = 0.0
        law = clock.distribution
        steps = np.arange(1, clock.cap + 2)  # the clock reads min(t, cap) + 1
        for h in (np.atleast_1d(np.asarray(x, dtype=np.float64)) for x in law.hazard_band(steps)):
            inside = h[(h > 0) & (h < 1)]
            if inside.size:
                worst = max(worst, float(np.max(inside / (1.0 - inside))))
        eta += worst * HAZARD_ACCURACY
        if history:
            eta += 4.0 * UNIT * max(clock.cap, clock.truncation or 0)
    return eta


# ------------------------------------------------------------------ directed rounding


def float_down(q: Fraction | float) -> float:
    """The largest double at most ``q``."""
    q = Fraction(q)
    f = float(q)
    return f if Fraction(f) <= q else math.nextafter(f, -math.inf)


def float_up(q: Fraction | float) -> float:
    """The smallest double at least ``q``."""
    q = Fraction(q)
    f = float(q)
    return f if Fraction(f) >= q else math.nextafter(f, math.inf)


def one_minus(lower: float, upper: float) -> tuple[float, float]:
    """``[1 - upper, 1 - lower]`` rounded outward and kept in ``[0, 1]``: the bracket of
    the complement's probability from a bracket of a probability.  A bound past 0 or 1
    (an LP's upper bound of 1 + 2e-11) says less than the interval a probability lies in
    anyway, and would leave a minimum of exactly 0 a bracket ``[-2e-11, 0]`` whose
    relative width no precision meets."""
    return (max(0.0, float_down(1 - Fraction(upper))),
            min(1.0, float_up(1 - Fraction(lower))))
