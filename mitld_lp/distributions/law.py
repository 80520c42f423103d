"""The type of a first-occurrence law and its numerics: pmf, survival, hazard, the step
from which the hazard is constant, truncation points and sampling.

An external event ``a`` happens at most once; its first-occurrence step ``K`` takes values
in ``{1, 2, ...}`` (never step 0) with pmf ``mu(k) = P(K = k)``.  Whatever mass the
distribution leaves undefined is the probability that the event *never* happens:
``never = 1 - sum_k mu(k)``.

The environment model needs the *hazard*, not the pmf: given that ``a`` has not happened
by step ``k-1``, it happens at step ``k`` with probability::

    h(k) = mu(k) / S(k-1),     S(k) = P(K > k) = 1 - sum_{j<=k} mu(j)   (never included)

so ``S(k) = S(k-1) (1 - h(k))`` and ``mu(k) = S(k-1) h(k)``.  Where ``S(k-1) = 0`` the
event has surely happened before step ``k``, the state "not yet happened at ``k-1``" is
unreachable, and we define ``h(k) = 1`` by convention.

A distribution whose hazard is constant from some step ``k0`` on needs the event's age
only up to ``k0`` (clock reduction (d)); one with constant hazard from step 1 is
memoryless and needs no clock at all (clock reduction (a)).  For any other distribution
the age is truncated at the smallest ``T`` with ``S(T) <= eps``
(:meth:`FirstOccurrence.truncation_point`).

The concrete laws live in :mod:`.closed` (geometric, finite tables, long uniform) and
:mod:`.scipy_laws` (laws read from ``scipy.stats``); :mod:`.families` builds them.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import Any, overload

import numpy as np
import numpy.typing as npt

from mitld_lp.util.text import excerpt

__all__ = [
    "DistributionError",
    "FirstOccurrence",
    "MASS_TOLERANCE",
    "HAZARD_RTOL",
    "HAZARD_ATOL",
    "NEGLIGIBLE_TAIL",
    "MAX_HAZARD_SCAN",
    "MAX_TABLE_STEPS",
    "step_array",
    "scalar_or_array",
    "MAX_STEP",
]

#: Totals of a pmf table within this of 1 are treated as exactly 1 (no never-mass).
MASS_TOLERANCE = 1e-12
#: Two hazards ``h, h0`` count as equal when ``|h - h0| <= HAZARD_RTOL*|h0| + HAZARD_ATOL``.
#: The absolute part covers the rounding of ``1 - S(k)/S(k-1)`` (a few ulps of ``log S``).
HAZARD_RTOL = 1e-10
HAZARD_ATOL = 1e-13
#: Tail mass below which an infinite-support distribution is scanned for a constant hazard.
NEGLIGIBLE_TAIL = 1e-12
#: Scans for a constant hazard stop here (a power of two); beyond it the answer is None.
MAX_HAZARD_SCAN = 2**20
#: The most steps a per-step table may have (a pmf's masses; a uniform law longer than
#: this uses its closed form instead).  Three float64 arrays of this length are 24 MiB.
MAX_TABLE_STEPS = 2**20
#: Searches for a truncation point or a sample stop here (a power of two); no law may
#: put mass beyond it (steps are int64 arrays).
MAX_STEP = 2**62

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
Steps = int | np.integer[Any] | npt.NDArray[Any] | Sequence[int]


class DistributionError(ValueError):
    """An invalid distribution: ``where`` names it (or the model-file key path), ``reason``
    says which parameter is wrong and why, e.g. ``geometric(1.5): p must be in (0, 1]``.
    ``str()`` is one line; a long ``where`` (a literal of thousands of masses) is quoted
    as an excerpt."""

    def __init__(self, where: str, reason: str) -> None:
        super().__init__(where, reason)
        self.where = where
        self.reason = reason

    def __str__(self) -> str:
        return f"{excerpt(self.where)}: {self.reason}"


# --------------------------------------------------------------------------- helpers


def step_array(k: Steps) -> tuple[IntArray, bool]:
    """``k`` as an int64 array, and whether it was a scalar."""
    arr = np.asarray(k)
    scalar = arr.ndim == 0
    if arr.dtype.kind in "iu":
        return arr.astype(np.int64), scalar
    if arr.dtype.kind == "f" and np.all(np.isfinite(arr)) and np.all(arr == np.floor(arr)):
        return arr.astype(np.int64), scalar
    if arr.size == 0 and arr.dtype.kind == "f":  # np.array([]) defaults to float
        return arr.astype(np.int64), scalar
    raise TypeError(f"steps must be integers, got {k!r}")


def scalar_or_array(values: FloatArray, scalar: bool) -> Any:
    """``values`` as a float when the steps were a scalar (:func:`step_array`), else as is."""
    return float(values) if scalar else values


def hazards_close(h: FloatArray, ref: float) -> npt.NDArray[np.bool_]:
    """Which hazards ``h`` equal ``ref`` within ``HAZARD_RTOL*|ref| + HAZARD_ATOL``."""
    return np.abs(h - ref) <= HAZARD_RTOL * abs(ref) + HAZARD_ATOL


def constant_from(close: npt.NDArray[np.bool_]) -> int:
    """The smallest ``k0`` (1-based) with ``close[k0-1:]`` all true (the last entry is)."""
    bad = np.flatnonzero(~close)
    return 1 if bad.size == 0 else int(bad[-1]) + 2


# --------------------------------------------------------------------------- the type


@dataclass(frozen=True, slots=True, eq=False)
class FirstOccurrence(ABC):
    """The distribution of an event's first-occurrence step ``K`` in ``{1, 2, ...}``
    (plus the mass ``never`` on "never happens").

    Every evaluation method takes an int or an integer array of steps and returns a float
    or a float array of the same shape.  ``str()`` is :attr:`label`, in the formula syntax.
    Equality is identity (two objects built from the same literal are different values).
    """

    label: str

    # ------------------------------------------------------------------ subclass hooks
    # Each receives an int64 array of steps k >= 1.

    @abstractmethod
    def _pmf_pos(self, k: IntArray) -> FloatArray: ...

    @abstractmethod
    def _cdf_pos(self, k: IntArray) -> FloatArray: ...

    @abstractmethod
    def _sf_pos(self, k: IntArray) -> FloatArray: ...

    @abstractmethod
    def _hazard_pos(self, k: IntArray) -> FloatArray:
        """``h(k)``, with ``h(k) = 1`` where ``S(k-1) = 0``."""

    @abstractmethod
    def _never(self) -> float: ...

    @abstractmethod
    def _last_step(self) -> float:
        """The last step with positive mass (``math.inf`` if the support is unbounded)."""

    @abstractmethod
    def _constant_hazard_from(self) -> int | None: ...

    def _first_step_survival_at_most(self, eps: float, cap: int) -> int | None:
        """The smallest ``T >= 0`` with ``S(T) <= eps``, or None if ``T > cap``.

        Doubling then bisection; relies on ``S`` being non-increasing.
        """
        if eps >= 1.0:
            return 0
        lo, hi = 0, 1  # invariant: S(lo) > eps
        while self._survival_at(hi) > eps:
            if hi >= cap:
                return None
            lo, hi = hi, 2 * hi
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if self._survival_at(mid) <= eps:
                hi = mid
            else:
                lo = mid
        return hi

    def _survival_at(self, k: int) -> float:
        return float(self._evaluate(k, self._sf_pos, 1.0, "survival"))

    def _evaluate(
        self, k: Steps, hook: Callable[[IntArray], FloatArray], before: float, what: str
    ) -> Any:
        """``hook`` at the steps ``k >= 1`` and ``before`` at the others, shaped like ``k``
        (a float for a scalar).  A value that is not a number (scipy cannot evaluate some
        laws at extreme parameters or far out in the tail) is a :class:`DistributionError`
        naming the step, never a nan passed on to the automaton."""
        ks, scalar = step_array(k)
        out = np.full(ks.shape, before)
        pos = ks >= 1
        if pos.any():
            out[pos] = hook(ks[pos])
            nan = np.isnan(out)
            if nan.any():
                raise DistributionError(
                    self.label,
                    f"the {what} at step {int(ks[nan].flat[0])} is not a number (the law "
                    "cannot be evaluated there)",
                )
        return scalar_or_array(out, scalar)

    def _sample_from(self, v: FloatArray) -> FloatArray:
        """Inverse cdf in survival form: for ``v`` uniform on ``(0, 1]``,
        ``K = min{k >= 1 : S(k) < v}`` (``inf`` if none, i.e. ``v <= never``), so that
        ``P(K = k) = S(k-1) - S(k) = mu(k)``."""
        out = np.full(v.shape, np.inf)
        live = v > self.never
        vv = v[live]
        lo = np.zeros(vv.shape, dtype=np.int64)  # S(lo) >= v
        hi = np.ones(vv.shape, dtype=np.int64)
        need = np.ones(vv.shape, dtype=bool)
        while True:
            idx = np.flatnonzero(need)
            if idx.size == 0:
                break
            still = self._sf_pos(hi[idx]) >= vv[idx]
            need[idx[~still]] = False
            grow = idx[still]
            if grow.size and int(hi[grow].max()) >= MAX_STEP:
                raise DistributionError(self.label, "tail too heavy to sample")
            lo[grow] = hi[grow]
            hi[grow] *= 2
        while True:
            idx = np.flatnonzero(hi - lo > 1)
            if idx.size == 0:
                break
            mid = (lo[idx] + hi[idx]) // 2
            below = self._sf_pos(mid) < vv[idx]
            hi[idx[below]] = mid[below]
            lo[idx[~below]] = mid[~below]
        out[live] = hi.astype(np.float64)
        return out

    # ------------------------------------------------------------------ public API

    def __str__(self) -> str:
        return self.label

    @overload
    def pmf(self, k: int | np.integer[Any]) -> float: ...
    @overload
    def pmf(self, k: npt.NDArray[Any] | Sequence[int]) -> FloatArray: ...
    def pmf(self, k: Steps) -> float | FloatArray:
        """``mu(k) = P(K = k)``; 0 for ``k <= 0``."""
        return self._evaluate(k, self._pmf_pos, 0.0, "pmf")

    @overload
    def cdf(self, k: int | np.integer[Any]) -> float: ...
    @overload
    def cdf(self, k: npt.NDArray[Any] | Sequence[int]) -> FloatArray: ...
    def cdf(self, k: Steps) -> float | FloatArray:
        """``P(K <= k) = sum_{j<=k} mu(j)``; 0 for ``k <= 0``.  ``cdf(k) + survival(k) = 1``."""
        return self._evaluate(k, self._cdf_pos, 0.0, "cdf")

    @overload
    def survival(self, k: int | np.integer[Any]) -> float: ...
    @overload
    def survival(self, k: npt.NDArray[Any] | Sequence[int]) -> FloatArray: ...
    def survival(self, k: Steps) -> float | FloatArray:
        """``S(k) = P(K > k)``, the never-mass included; ``S(k) = 1`` for ``k <= 0``."""
        return self._evaluate(k, self._sf_pos, 1.0, "survival")

    @overload
    def hazard(self, k: int | np.integer[Any]) -> float: ...
    @overload
    def hazard(self, k: npt.NDArray[Any] | Sequence[int]) -> FloatArray: ...
    def hazard(self, k: Steps) -> float | FloatArray:
        """``h(k) = mu(k) / S(k-1) = 1 - S(k)/S(k-1)`` for ``k >= 1``: the probability that the
        event happens at step ``k`` given it has not happened by step ``k-1``.

        Where ``S(k-1) = 0`` that condition is unreachable and ``h(k) = 1`` by convention
        (so a finite table with total 1 has hazard 1 at and after its last support step).
        ``h(k) = 0`` for ``k <= 0``.
        """
        return self._evaluate(k, self._hazard_pos, 0.0, "hazard")

    @property
    def never(self) -> float:
        """``1 - sum_k mu(k)``: the probability that the event never happens."""
        return self._never()

    @property
    def constant_hazard_from(self) -> int | None:
        """The smallest ``k0 >= 1`` with ``h(k) = h(k0)`` for every ``k >= k0``, or None.

        Exact for the geometric (1) and for finite tables (pmf, uniform), whose hazard after
        the support is 1 (total 1) or 0 (never-mass > 0).  For infinite-support families it
        is detected numerically: with ``K`` the first step with ``S(K) <= NEGLIGIBLE_TAIL``,
        the hazards on ``1..2K`` are compared with ``h(2K)`` (tolerances ``HAZARD_RTOL``,
        ``HAZARD_ATOL``); ``k0`` is the start of the final run of equal hazards and is
        accepted only if ``k0 <= K`` (the constant stretch starts while non-negligible mass
        is left).  If ``K > MAX_HAZARD_SCAN`` the answer is None.
        """
        return self._constant_hazard_from()

    @property
    def is_memoryless(self) -> bool:
        """Whether the hazard is constant for all ``k >= 1`` (the event needs no clock)."""
        return self.constant_hazard_from == 1

    def truncation_point(self, eps: float) -> int:
        """The smallest ``T >= 0`` with ``S(T) = P(K > T) <= eps``.

        Raises :class:`DistributionError` if ``eps < 0``, if ``never > eps`` (the survival
        never drops below ``never``), or if ``eps = 0`` and the support is unbounded.
        """
        e = float(eps)
        if not e >= 0:
            raise DistributionError(self.label, f"truncation eps must be >= 0, got {eps!r}")
        if self.never > e:
            raise DistributionError(
                self.label,
                f"the event never happens with probability {self.never:.6g} > eps = {e:.6g}, "
                "so no truncation point has survival <= eps",
            )
        if e == 0 and math.isinf(self._last_step()):
            raise DistributionError(
                self.label, "survival is positive at every step; truncation eps must be > 0"
            )
        t = self._first_step_survival_at_most(e, MAX_STEP)
        if t is None:
            raise DistributionError(
                self.label, f"survival is still above eps = {e:.6g} at step 2**62"
            )
        return t

    def hazard_range_from(self, k: int) -> tuple[float, float]:
        """``(inf, sup)`` of the hazards ``h(j)`` over every step ``j >= k`` (``k >= 1``),
        sound bounds where they are not attained: from :attr:`constant_hazard_from`
        ``c`` the hazards of ``k..max(k, c)`` (a table of masses past its support:
        ``(0, 0)``, or ``(1, 1)`` for one that surely happens, by the convention of
        ``h``; a geometric ``(p, p)``); a law whose hazard never settles answers with
        :meth:`_hazard_range_unsettled`, ``(0, 1)`` unless its family knows better (a
        Poisson law's hazard increases towards 1: :mod:`.scipy_laws`).  The tail of a
        band whose hazard may stay positive for ever is bounded with it
        (:func:`mitld_lp.distributions.band.tail_intervals`)."""
        k = max(int(k), 1)
        c = self.constant_hazard_from
        if c is None:
            return self._hazard_range_unsettled(k)
        end = max(k, c)
        if end - k > MAX_HAZARD_SCAN:
            return 0.0, 1.0
        h = np.asarray(self.hazard(np.arange(k, end + 1, dtype=np.int64)), dtype=np.float64)
        return float(h.min()), float(h.max())

    def _hazard_range_unsettled(self, k: int) -> tuple[float, float]:
        """``(inf, sup)`` of ``h(j)``, ``j >= k``, for a law whose hazard never settles:
        nothing is known but that hazards lie in ``[0, 1]``."""
        return 0.0, 1.0

    # ------------------------------------------------------------------ exact hazards
    # A law whose hazards are rational for rational parameters (:mod:`.closed`: the
    # geometric, a table of masses, the uniform) overrides these two with the hazards of
    # its parameters as written (:func:`mitld_lp.util.decimals.exact_value`); every
    # other law has none, and an exact answer refuses it by name (:mod:`mitld_lp.exact`).

    @property
    def exact_hazards(self) -> bool:
        """Whether :meth:`exact_hazard` gives this law's hazards as rational numbers."""
        return False

    def exact_hazard(self, k: int) -> Fraction:
        """``h(k)`` as a rational number, from the parameters as written (``k >= 1``).
        Raises :class:`DistributionError` for a law without rational hazards."""
        raise DistributionError(self.label, "its hazards are not rational numbers (an exact "
                                "answer takes geometric, pmf and uniform laws)")

    def exact_constant_from(self) -> int:
        """The smallest ``k0 >= 1`` with :meth:`exact_hazard` the same at every ``k >=
        k0``, in rational arithmetic: where :attr:`constant_hazard_from`, found in floats,
        may have taken two hazards that differ beyond double precision for equal."""
        raise DistributionError(self.label, "its hazards are not rational numbers")

    # ------------------------------------------------------------------ ambiguity
    # A law known exactly is its own band; :mod:`.band` overrides these three.

    @property
    def is_ambiguous(self) -> bool:
        """Whether the law is a band (:mod:`.band`): its per-step hazard is known only
        within an interval chosen step by step by an adversary (docs/semantics.md)."""
        return False

    def hazard_band(self, k: Steps) -> tuple[Any, Any]:
        """``(h_lo(k), h_hi(k))``: the hazards the law allows at step ``k``; for a law
        known exactly both are :meth:`hazard`."""
        h = self.hazard(k)
        return h, h

    def survival_upper(self, k: Steps) -> Any:
        """The largest ``P(K > k)`` the law allows; for a law known exactly,
        :meth:`survival`.  Truncation cuts at most this much."""
        return self.survival(k)

    def sample(self, rng: np.random.Generator, size: int | tuple[int, ...]) -> FloatArray:
        """Independent first-occurrence steps by inverse cdf, as floats (``inf`` = never).

        For ``v = 1 - U`` with ``U`` from ``rng.random``: ``K = min{k : S(k) < v}``.
        """
        v = 1.0 - rng.random(size)
        return self._sample_from(np.asarray(v, dtype=np.float64))
