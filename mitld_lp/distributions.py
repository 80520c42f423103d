"""First-occurrence distributions of external events over the steps 1, 2, ...

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

Families (all over the steps 1, 2, ...):

* ``geometric(p)``: ``mu(k) = (1-p)^(k-1) p``, ``p in (0, 1]``; ``h(k) = p``.
* ``pmf(m1, m2, ...)``: ``mu(k) = m_k``; masses ``>= 0`` summing to at most 1.
* ``uniform(a, b)``: ``mu(k) = 1/(b-a+1)`` for ``a <= k <= b``; ``h(k) = 1/(b-k+1)`` there.
* ``poisson(lam)``: ``K = 1 + X``, ``X ~ Poisson(lam)``.
* ``scipy_discrete(name, *args)``: any ``scipy.stats`` discrete distribution; ``K = 1 + X``
  if its support starts at 0, ``K = X`` if it starts at 1 or later.
* ``discretised(name, *args)``, ``exponential(rate)``, ``weibull(shape, scale)``,
  ``gamma(shape, scale)``: a continuous ``X >= 0`` with cdf ``F`` read at whole steps,
  ``K = ceil(X)``: ``mu(k) = F(k) - F(k-1)``.

Numerics: survival is computed directly (a reverse cumulative sum for finite tables,
``q^k`` for the geometric, scipy's ``sf``/``logsf`` otherwise), never as ``1 - cdf``, so
tails far below machine epsilon stay accurate; the hazard is computed from the same
quantities (``pmf/S`` for finite tables, ``exp(logpmf(k) - logsf(k-1))`` for scipy
discrete, ``1 - S(k)/S(k-1) = -expm1(logsf(k) - logsf(k-1))`` for discretised ones).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, overload

import numpy as np
import numpy.typing as npt

# The logic layer's parser validates inline laws with this module, so this module reaches
# the logic layer only inside functions (either may be imported first).
if TYPE_CHECKING:
    from mitld_lp.logic.syntax import DistLiteral

__all__ = [
    "DistributionError",
    "FirstOccurrence",
    "geometric",
    "pmf",
    "poisson",
    "uniform",
    "scipy_discrete",
    "discretised",
    "exponential",
    "weibull",
    "gamma",
    "from_spec",
    "from_table",
    "FAMILIES",
    "Family",
    "MASS_TOLERANCE",
    "HAZARD_RTOL",
    "HAZARD_ATOL",
    "NEGLIGIBLE_TAIL",
    "MAX_HAZARD_SCAN",
    "MAX_TABLE_STEPS",
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
    says which parameter is wrong and why, e.g. ``geometric(1.5): p must be in (0, 1]``."""

    def __init__(self, where: str, reason: str) -> None:
        super().__init__(where, reason)
        self.where = where
        self.reason = reason

    def __str__(self) -> str:
        return f"{self.where}: {self.reason}"


# --------------------------------------------------------------------------- helpers


def _stats() -> Any:
    """``scipy.stats``, imported when a law first needs it: the import takes ~0.6 s and
    ``import mitld_lp`` (or a model with only geometric and pmf laws) should not pay it."""
    import scipy.stats

    return scipy.stats


def _steps(k: Steps) -> tuple[IntArray, bool]:
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


def _out(values: FloatArray, scalar: bool) -> Any:
    return float(values) if scalar else values


def _plain(a: Any) -> Any:
    """numpy scalars as Python numbers, so that labels print like the formula syntax."""
    if isinstance(a, np.integer):
        return int(a)
    if isinstance(a, np.floating):
        return float(a)
    return a


def _label(family: str, *args: Any) -> str:
    from mitld_lp.logic.syntax import DistLiteral

    return str(DistLiteral(family, tuple(_plain(a) for a in args)))


def _is_number(x: object) -> bool:
    return isinstance(x, int | float | np.integer | np.floating) and not isinstance(
        x, bool | np.bool_
    )


def _real(where: str, name: str, x: Any) -> float:
    if not _is_number(x):
        raise DistributionError(where, f"{name} must be a number, got {x!r}")
    return float(x)


def _positive(where: str, name: str, x: object) -> float:
    v = _real(where, name, x)
    if not (math.isfinite(v) and v > 0):
        raise DistributionError(where, f"{name} must be a finite number > 0, got {v!r}")
    return v


def _integer(where: str, name: str, x: object) -> int:
    v = _real(where, name, x)
    if not (math.isfinite(v) and v == math.floor(v)):
        raise DistributionError(where, f"{name} must be an integer, got {x!r}")
    return int(v)


def _close(h: FloatArray, ref: float) -> npt.NDArray[np.bool_]:
    return np.abs(h - ref) <= HAZARD_RTOL * abs(ref) + HAZARD_ATOL


def _constant_from(close: npt.NDArray[np.bool_]) -> int:
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
        return 1.0 if k <= 0 else float(self._sf_pos(np.array([k], dtype=np.int64))[0])

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
        ks, scalar = _steps(k)
        out = np.zeros(ks.shape)
        pos = ks >= 1
        if pos.any():
            out[pos] = self._pmf_pos(ks[pos])
        return _out(out, scalar)

    @overload
    def cdf(self, k: int | np.integer[Any]) -> float: ...
    @overload
    def cdf(self, k: npt.NDArray[Any] | Sequence[int]) -> FloatArray: ...
    def cdf(self, k: Steps) -> float | FloatArray:
        """``P(K <= k) = sum_{j<=k} mu(j)``; 0 for ``k <= 0``.  ``cdf(k) + survival(k) = 1``."""
        ks, scalar = _steps(k)
        out = np.zeros(ks.shape)
        pos = ks >= 1
        if pos.any():
            out[pos] = self._cdf_pos(ks[pos])
        return _out(out, scalar)

    @overload
    def survival(self, k: int | np.integer[Any]) -> float: ...
    @overload
    def survival(self, k: npt.NDArray[Any] | Sequence[int]) -> FloatArray: ...
    def survival(self, k: Steps) -> float | FloatArray:
        """``S(k) = P(K > k)``, the never-mass included; ``S(k) = 1`` for ``k <= 0``."""
        ks, scalar = _steps(k)
        out = np.ones(ks.shape)
        pos = ks >= 1
        if pos.any():
            out[pos] = self._sf_pos(ks[pos])
        return _out(out, scalar)

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
        ks, scalar = _steps(k)
        out = np.zeros(ks.shape)
        pos = ks >= 1
        if pos.any():
            out[pos] = self._hazard_pos(ks[pos])
        return _out(out, scalar)

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

    def sample(self, rng: np.random.Generator, size: int | tuple[int, ...]) -> FloatArray:
        """Independent first-occurrence steps by inverse cdf, as floats (``inf`` = never).

        For ``v = 1 - U`` with ``U`` from ``rng.random``: ``K = min{k : S(k) < v}``.
        """
        v = 1.0 - rng.random(size)
        return self._sample_from(np.asarray(v, dtype=np.float64))


# --------------------------------------------------------------------------- geometric


@dataclass(frozen=True, slots=True, eq=False)
class _Geometric(FirstOccurrence):
    """``mu(k) = q^(k-1) p``, ``S(k) = q^k``, ``h(k) = p`` with ``q = 1 - p``."""

    p: float
    _q: float = field(init=False, repr=False)
    _log_q: float = field(init=False, repr=False)
    _q_exact: bool = field(init=False, repr=False)

    def __post_init__(self) -> None:
        q = 1.0 - self.p
        object.__setattr__(self, "_q", q)
        object.__setattr__(self, "_log_q", math.log1p(-self.p) if self.p < 1 else -math.inf)
        # q is exact whenever p >= 1/2 (Sterbenz) or p is "round"; then q**n is correctly
        # rounded, otherwise exp(n log1p(-p)) avoids the rounding of 1 - p.
        object.__setattr__(self, "_q_exact", 1.0 - q == self.p)

    def _q_pow(self, n: IntArray) -> FloatArray:
        if self._q_exact:
            return np.power(self._q, n.astype(np.float64))
        return np.exp(n * self._log_q)

    def _pmf_pos(self, k: IntArray) -> FloatArray:
        return self.p * self._q_pow(k - 1)

    def _cdf_pos(self, k: IntArray) -> FloatArray:
        if self._q_exact and self.p >= 0.5:
            return 1.0 - self._q_pow(k)
        return -np.expm1(k * self._log_q)

    def _sf_pos(self, k: IntArray) -> FloatArray:
        return self._q_pow(k)

    def _hazard_pos(self, k: IntArray) -> FloatArray:
        return np.full(k.shape, self.p)

    def _never(self) -> float:
        return 0.0

    def _last_step(self) -> float:
        return 1.0 if self.p == 1.0 else math.inf

    def _constant_hazard_from(self) -> int | None:
        return 1

    def _sample_from(self, v: FloatArray) -> FloatArray:
        # S(k) = q^k < v  <=>  k > log(v)/log(q)
        with np.errstate(divide="ignore", invalid="ignore"):
            k = np.floor(np.log(v) / self._log_q) + 1.0
        return np.where(np.isnan(k), 1.0, k)


# --------------------------------------------------------------------------- finite tables


@dataclass(frozen=True, slots=True, eq=False)
class _Finite(FirstOccurrence):
    """A finite table: ``mu(k) = masses[k-1]`` for ``1 <= k <= n``, 0 beyond."""

    masses: FloatArray = field(repr=False)
    _cum: FloatArray = field(init=False, repr=False)  # _cum[k] = P(K <= k), k = 0..n
    _surv: FloatArray = field(init=False, repr=False)  # _surv[k] = P(K > k), k = 0..n
    _never_mass: float = field(init=False, repr=False)

    def __post_init__(self) -> None:
        m = np.array(self.masses, dtype=np.float64)
        total = math.fsum(m.tolist())
        if abs(total - 1.0) <= MASS_TOLERANCE:
            m = m / total
            never = 0.0
        else:
            never = 1.0 - total
        m.setflags(write=False)
        cum = np.minimum(np.concatenate([[0.0], np.cumsum(m)]), 1.0)
        tail = np.concatenate([np.cumsum(m[::-1])[::-1], [0.0]])
        surv = np.minimum(tail + never, 1.0)
        surv[0] = 1.0
        cum.setflags(write=False)
        surv.setflags(write=False)
        object.__setattr__(self, "masses", m)
        object.__setattr__(self, "_cum", cum)
        object.__setattr__(self, "_surv", surv)
        object.__setattr__(self, "_never_mass", never)

    @property
    def _n(self) -> int:
        return int(self.masses.shape[0])

    def _pmf_pos(self, k: IntArray) -> FloatArray:
        out = np.zeros(k.shape)
        inside = k <= self._n
        out[inside] = self.masses[k[inside] - 1]
        return out

    def _cdf_pos(self, k: IntArray) -> FloatArray:
        return self._cum[np.minimum(k, self._n)]

    def _sf_pos(self, k: IntArray) -> FloatArray:
        return self._surv[np.minimum(k, self._n)]

    def _hazard_pos(self, k: IntArray) -> FloatArray:
        before = self._surv[np.minimum(k - 1, self._n)]
        mass = self._pmf_pos(k)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(before > 0, mass / before, 1.0)

    def _never(self) -> float:
        return self._never_mass

    def _last_step(self) -> float:
        nz = np.flatnonzero(self.masses)
        return float(nz[-1] + 1) if nz.size else 0.0

    def _constant_hazard_from(self) -> int | None:
        # The hazard after the table is constant (1 or 0), so 1..n+1 decides it; it is
        # computed exactly (m/S is exactly 1 or 0 there), so compare exactly.
        h = self._hazard_pos(np.arange(1, self._n + 2, dtype=np.int64))
        return _constant_from(h == h[-1])

    def _first_step_survival_at_most(self, eps: float, cap: int) -> int | None:
        ok = np.flatnonzero(self._surv <= eps)
        if ok.size == 0:
            return None
        t = int(ok[0])
        return t if t <= cap else None

    def _sample_from(self, v: FloatArray) -> FloatArray:
        # K = min{k : S(k) < v}; -S is non-decreasing.
        idx = np.searchsorted(-self._surv, -v, side="right")
        return np.where(idx <= self._n, idx.astype(np.float64), np.inf)


# --------------------------------------------------------------------------- uniform


@dataclass(frozen=True, slots=True, eq=False)
class _Uniform(FirstOccurrence):
    """Equally likely on ``a..b`` in closed form, for supports too long for a table:
    with ``n = b - a + 1``, ``mu(k) = 1/n``, ``S(k) = min(max(b - k, 0), n) / n``,
    ``h(k) = 1/(b - k + 1)`` on ``a..b`` (0 before, 1 after)."""

    a: int
    b: int

    @property
    def _n(self) -> int:
        return self.b - self.a + 1

    def _pmf_pos(self, k: IntArray) -> FloatArray:
        return np.where((k >= self.a) & (k <= self.b), 1.0 / self._n, 0.0)

    def _cdf_pos(self, k: IntArray) -> FloatArray:
        return np.clip(k - self.a + 1, 0, self._n) / self._n

    def _sf_pos(self, k: IntArray) -> FloatArray:
        return np.clip(self.b - k, 0, self._n) / self._n

    def _hazard_pos(self, k: IntArray) -> FloatArray:
        left = np.maximum(self.b - k + 1, 1).astype(np.float64)
        return np.where(k < self.a, 0.0, np.where(k <= self.b, 1.0 / left, 1.0))

    def _never(self) -> float:
        return 0.0

    def _last_step(self) -> float:
        return float(self.b)

    def _constant_hazard_from(self) -> int | None:
        # h(b) = 1 and h = 1 after b; h(b-1) = 1/2 (or 0 before a when a = b)
        return self.b


# --------------------------------------------------------------------------- scipy based


_UNSET: Any = object()


@dataclass(frozen=True, slots=True, eq=False)
class _ScipyBased(FirstOccurrence):
    """Shared by the scipy families: the numeric constant-hazard scan, cached."""

    dist: Any = field(repr=False)  # a frozen scipy.stats distribution
    last: float = field(repr=False)  # the last step with positive mass, or inf
    _chf: Any = field(init=False, repr=False, default=_UNSET)

    def _never(self) -> float:
        return 0.0

    def _last_step(self) -> float:
        return self.last

    def _constant_hazard_from(self) -> int | None:
        if self._chf is _UNSET:
            object.__setattr__(self, "_chf", self._scan_constant_hazard())
        return self._chf

    def _scan_constant_hazard(self) -> int | None:
        if math.isfinite(self.last):
            if self.last > MAX_HAZARD_SCAN:  # the scan would need a table of 2 * last steps
                return None
            big_k = max(int(self.last), 1)
        else:
            found = self._first_step_survival_at_most(NEGLIGIBLE_TAIL, MAX_HAZARD_SCAN)
            if found is None:
                return None
            big_k = max(found, 1)
        end = 2 * big_k
        ref = float(self._hazard_pos(np.array([end], dtype=np.int64))[0])
        # cheap rejection first: the hazard must already be flat on [K, 2K]
        probe = np.unique(np.linspace(big_k, end, 65).astype(np.int64))
        if not _close(self._hazard_pos(probe), ref).all():
            return None
        h = self._hazard_pos(np.arange(1, end + 1, dtype=np.int64))
        k0 = _constant_from(_close(h, ref))
        return k0 if k0 <= big_k else None


@dataclass(frozen=True, slots=True, eq=False)
class _ShiftedDiscrete(_ScipyBased):
    """``K = X + shift`` for a scipy discrete ``X``: ``mu(k) = P(X = k - shift)``,
    ``S(k) = P(X > k - shift)`` (scipy ``sf``), ``h(k) = exp(logpmf_X(k-shift) -
    logsf_X(k-1-shift))``."""

    shift: int = 0

    def _pmf_pos(self, k: IntArray) -> FloatArray:
        return np.asarray(self.dist.pmf(k - self.shift), dtype=np.float64)

    def _cdf_pos(self, k: IntArray) -> FloatArray:
        return np.asarray(self.dist.cdf(k - self.shift), dtype=np.float64)

    def _sf_pos(self, k: IntArray) -> FloatArray:
        return np.asarray(self.dist.sf(k - self.shift), dtype=np.float64)

    def _hazard_pos(self, k: IntArray) -> FloatArray:
        x = k - self.shift
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            log_before = np.asarray(self.dist.logsf(x - 1), dtype=np.float64)
            h = np.exp(np.asarray(self.dist.logpmf(x), dtype=np.float64) - log_before)
        return np.where(np.isneginf(log_before), 1.0, np.minimum(h, 1.0))


@dataclass(frozen=True, slots=True, eq=False)
class _Discretised(_ScipyBased):
    """``K = ceil(X)`` for a scipy continuous ``X >= 0``: ``mu(k) = F(k) - F(k-1)``,
    ``S(k) = 1 - F(k)`` (scipy ``sf``), ``h(k) = -expm1(logsf(k) - logsf(k-1))``."""

    def _pmf_pos(self, k: IntArray) -> FloatArray:
        kf = k.astype(np.float64)
        cdf_k = np.asarray(self.dist.cdf(kf), dtype=np.float64)
        head = cdf_k - np.asarray(self.dist.cdf(kf - 1), dtype=np.float64)
        tail = np.asarray(self.dist.sf(kf - 1), dtype=np.float64) - np.asarray(
            self.dist.sf(kf), dtype=np.float64
        )
        return np.maximum(np.where(cdf_k <= 0.5, head, tail), 0.0)

    def _cdf_pos(self, k: IntArray) -> FloatArray:
        return np.asarray(self.dist.cdf(k.astype(np.float64)), dtype=np.float64)

    def _sf_pos(self, k: IntArray) -> FloatArray:
        return np.asarray(self.dist.sf(k.astype(np.float64)), dtype=np.float64)

    def _hazard_pos(self, k: IntArray) -> FloatArray:
        kf = k.astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            log_before = np.asarray(self.dist.logsf(kf - 1), dtype=np.float64)
            log_now = np.asarray(self.dist.logsf(kf), dtype=np.float64)
            h = -np.expm1(log_now - log_before)
        h = np.where(h > 0, np.minimum(h, 1.0), 0.0)  # also turns -expm1(0) = -0.0 into 0.0
        return np.where(np.isneginf(log_before), 1.0, h)


# --------------------------------------------------------------------------- constructors


def geometric(p: float) -> FirstOccurrence:
    """``P(K = k) = (1-p)^(k-1) p`` for ``k >= 1``, ``p in (0, 1]``: probability ``p`` at
    every step (hazard ``p``), the memoryless case of the paper's case study."""
    label = _label("geometric", p)
    pf = _real(label, "p", p)
    if not 0 < pf <= 1:
        raise DistributionError(label, "p must be in (0, 1]")
    return _Geometric(label, pf)


def pmf(masses: Sequence[float] | npt.NDArray[Any]) -> FirstOccurrence:
    """``P(K = k) = masses[k-1]`` for ``k = 1..n``; ``never = 1 - sum(masses)``.

    Masses must be finite and ``>= 0`` with sum ``<= 1``; a sum within ``MASS_TOLERANCE``
    of 1 is treated as exactly 1 (the masses are rescaled, no never-mass).  At most
    :data:`MAX_TABLE_STEPS` masses (checked before the table is made).
    """
    count = masses.size if isinstance(masses, np.ndarray) else len(masses)
    if count > MAX_TABLE_STEPS:
        raise DistributionError(
            f"pmf(... {count} masses)",
            f"has {count} masses; a table is limited to MAX_TABLE_STEPS = {MAX_TABLE_STEPS} "
            "steps",
        )
    values = np.asarray(masses).ravel().tolist() if isinstance(masses, np.ndarray) else list(masses)
    label = _label("pmf", *values)
    if not values:
        raise DistributionError(
            label, "needs at least one mass (for an event that never happens write pmf(0))"
        )
    m = np.empty(len(values))
    for i, x in enumerate(values, start=1):
        v = _real(label, f"mass m{i} (step {i})", x)
        if math.isnan(v) or math.isinf(v):
            raise DistributionError(label, f"mass m{i} (step {i}) must be finite, got {v!r}")
        if v < 0:
            raise DistributionError(label, f"mass m{i} (step {i}) is negative: {v!r}")
        m[i - 1] = v
    try:
        total = math.fsum(m.tolist())
    except OverflowError:  # finite masses whose exact sum is beyond the largest float
        raise DistributionError(label, "masses sum to more than the largest float > 1") from None
    if total > 1 + MASS_TOLERANCE:
        raise DistributionError(label, f"masses sum to {total:.12g} > 1")
    return _Finite(label, m)


def uniform(a: int, b: int) -> FirstOccurrence:
    """Equally likely on the steps ``a..b`` inclusive, ``1 <= a <= b <= MAX_STEP``:
    ``P(K = k) = 1/(b-a+1)``, hazard ``1/(b-k+1)`` for ``a <= k <= b``.

    Up to :data:`MAX_TABLE_STEPS` steps it is a table like :func:`pmf`; beyond, the
    closed forms (no per-step memory)."""
    label = _label("uniform", a, b)
    lo = _integer(label, "a", a)
    hi = _integer(label, "b", b)
    if lo < 1:
        raise DistributionError(label, f"a must be >= 1 (step 0 is not allowed), got {lo}")
    if hi < lo:
        raise DistributionError(label, f"b must be >= a = {lo}, got {hi}")
    if hi > MAX_STEP:
        raise DistributionError(label, f"b = {hi} is beyond the last step 2**62 = {MAX_STEP}")
    if hi > MAX_TABLE_STEPS:
        return _Uniform(label, lo, hi)
    m = np.zeros(hi)
    m[lo - 1 :] = 1.0 / (hi - lo + 1)
    return _Finite(label, m)


def poisson(lam: float) -> FirstOccurrence:
    """``K = 1 + X`` with ``X ~ Poisson(lam)``, ``lam > 0``:
    ``P(K = k) = exp(-lam) lam^(k-1) / (k-1)!``."""
    label = _label("poisson", lam)
    lf = _positive(label, "lam", lam)
    return _ShiftedDiscrete(label, _stats().poisson(lf), math.inf, shift=1)


def _scipy_generator(label: str, name: object) -> Any:
    if not isinstance(name, str) or not name.isidentifier() or name.startswith("_"):
        raise DistributionError(label, f"scipy distribution name must be a name, got {name!r}")
    gen = getattr(_stats(), name, None)
    if not isinstance(gen, _stats().rv_discrete | _stats().rv_continuous):
        raise DistributionError(label, f"unknown scipy.stats distribution {name!r}")
    return gen


def _freeze(
    label: str, name: str, gen: Any, args: Sequence[float], kwargs: dict[str, float]
) -> tuple[Any, float, float]:
    try:
        with np.errstate(all="ignore"):
            frozen = gen(*args, **kwargs)
            lo, hi = (float(x) for x in frozen.support())
    except (TypeError, ValueError, ArithmeticError) as exc:
        raise DistributionError(label, f"wrong arguments for scipy.stats.{name}: {exc}") from exc
    if math.isnan(lo) or math.isnan(hi):
        raise DistributionError(
            label, f"invalid parameters for scipy.stats.{name} (scipy rejects them)"
        )
    return frozen, lo, hi


def _scipy_args(label: str, args: Sequence[object]) -> list[float]:
    out = []
    for i, a in enumerate(args, start=1):
        v = _real(label, f"argument {i}", a)
        if math.isnan(v):
            raise DistributionError(label, f"argument {i} is nan")
        out.append(v)
    return out


def scipy_discrete(name: str, *args: float) -> FirstOccurrence:
    """Any ``scipy.stats`` discrete distribution ``X`` (shape arguments, then ``loc``):
    ``K = 1 + X`` if its support starts at 0, ``K = X`` if it starts at 1 or later
    (e.g. ``geom``).  A support reaching below 0 is an error."""
    label = _label("scipy", name, *args)
    gen = _scipy_generator(label, name)
    if not isinstance(gen, _stats().rv_discrete):
        raise DistributionError(label, f"scipy.stats.{name} is continuous, not discrete")
    frozen, lo, hi = _freeze(label, name, gen, _scipy_args(label, args), {})
    if lo < 0:
        raise DistributionError(
            label, f"support starts at {lo:g} < 0 (steps start at 1; 0 is shifted to 1)"
        )
    if lo != math.floor(lo):
        raise DistributionError(label, f"support must start at an integer, got {lo:g}")
    shift = 1 if lo == 0 else 0
    return _ShiftedDiscrete(label, frozen, hi + shift, shift=shift)


def _discretised(
    label: str, name: str, gen: Any, args: Sequence[float], kwargs: dict[str, float]
) -> FirstOccurrence:
    frozen, lo, hi = _freeze(label, name, gen, args, kwargs)
    if lo < 0:
        raise DistributionError(
            label, f"support starts at {lo:g} < 0: mass on step 0 (needs support in [0, inf))"
        )
    f0 = float(frozen.cdf(0.0))
    if f0 > 0:
        raise DistributionError(label, f"mass on step 0: F(0) = {f0:.6g} > 0")
    return _Discretised(label, frozen, float(math.ceil(hi)) if math.isfinite(hi) else math.inf)


def discretised(name: str, *args: float) -> FirstOccurrence:
    """A ``scipy.stats`` continuous distribution ``X`` with support in ``[0, inf)`` (shape
    arguments, then ``loc``, ``scale``) read at whole steps: ``K = ceil(X)``,
    ``P(K = k) = F(k) - F(k-1)``."""
    label = _label("scipy", name, *args)
    gen = _scipy_generator(label, name)
    if not isinstance(gen, _stats().rv_continuous):
        raise DistributionError(label, f"scipy.stats.{name} is discrete, not continuous")
    return _discretised(label, name, gen, _scipy_args(label, args), {})


def exponential(rate: float) -> FirstOccurrence:
    """Discretised ``Exp(rate)``: ``P(K = k) = e^(-rate (k-1)) (1 - e^(-rate))``, i.e.
    ``geometric(1 - exp(-rate))``."""
    label = _label("exponential", rate)
    r = _positive(label, "rate", rate)
    return _discretised(label, "expon", _stats().expon, [], {"scale": 1.0 / r})


def weibull(shape: float, scale: float) -> FirstOccurrence:
    """Discretised Weibull: ``S(k) = exp(-(k/scale)^shape)``; shape 1 is geometric."""
    label = _label("weibull", shape, scale)
    c = _positive(label, "shape", shape)
    s = _positive(label, "scale", scale)
    return _discretised(label, "weibull_min", _stats().weibull_min, [c], {"scale": s})


def gamma(shape: float, scale: float) -> FirstOccurrence:
    """Discretised Gamma(shape, scale): ``P(K = k) = F(k) - F(k-1)``; shape 1 is
    ``exponential(1/scale)``."""
    label = _label("gamma", shape, scale)
    a = _positive(label, "shape", shape)
    s = _positive(label, "scale", scale)
    return _discretised(label, "gamma", _stats().gamma, [a], {"scale": s})


# --------------------------------------------------------------------------- specs


@dataclass(frozen=True, slots=True)
class Family:
    """One family of laws: how it is written and how it is built.  :data:`FAMILIES` is
    the one table that the parser (shapes of ``D[family(args)]``), the model loader
    (``{ family = value }``, :func:`from_table`) and :func:`from_spec` consult.

    Attributes:
        name: the family name as written.
        params: the names of its numeric parameters, in order; for a variadic family the
            numbers are any count of at least ``len(params)``.
        build: the constructor, called with the arguments as written; it validates the
            values and raises :class:`DistributionError`.
        description: the law in one line, for messages and documentation.
        variadic: any number of numbers (pmf masses, scipy shape arguments).
        named: the first argument is a name, not a number (``scipy(nbinom, 3, 0.5)``).
        integers: the numbers must be integers (``uniform``).
    """

    name: str
    params: tuple[str, ...]
    build: Callable[..., FirstOccurrence]
    description: str
    variadic: bool = False
    named: bool = False
    integers: bool = False

    @property
    def min_numbers(self) -> int:
        return len(self.params)

    @property
    def max_numbers(self) -> int | None:
        return None if self.variadic else len(self.params)

    @property
    def takes_list(self) -> bool:
        """Whether a model file writes its arguments as a list (one number otherwise)."""
        return self.variadic or self.named or len(self.params) != 1

    def shape(self) -> str:
        """How a literal of this family is written, e.g. ``uniform(a, b)``."""
        parts = ["name"] if self.named else []
        parts += list(self.params)
        if self.variadic:
            parts.append("...")
        return f"{self.name}({', '.join(parts)})"

    def arity_error(self, n_args: int) -> str | None:
        """Why ``n_args`` arguments do not fit this family (None when they do)."""
        if self.named and n_args == 0:
            return f"{self.name} needs a distribution name, e.g. {self.name}(nbinom, 3, 0.5)"
        n = n_args - int(self.named)
        hi = self.max_numbers
        if n >= self.min_numbers and (hi is None or n <= hi):
            return None
        s = "s" if self.min_numbers != 1 else ""
        at_least = "at least " if hi is None else ""
        return (f"{self.name} takes {at_least}{self.min_numbers} argument{s} "
                f"({', '.join(self.params)}), got {n_args}")


def _build_scipy(name: object, *args: Any) -> FirstOccurrence:
    gen = _scipy_generator(_label("scipy", name, *args), name)
    assert isinstance(name, str)  # _scipy_generator checked it
    if isinstance(gen, _stats().rv_discrete):
        return scipy_discrete(name, *args)
    return discretised(name, *args)


#: Every family, by name (in the order the documentation lists them).
FAMILIES: Mapping[str, Family] = MappingProxyType({
    f.name: f
    for f in (
        Family("geometric", ("p",), geometric,
               "P(K = k) = (1-p)^(k-1) p, p in (0, 1]; hazard p (memoryless)"),
        Family("pmf", ("m1",), lambda *m: pmf(m),
               "P(K = k) = m_k for k = 1..n; masses >= 0 summing to at most 1 (the rest: "
               "never)", variadic=True),
        Family("poisson", ("lam",), poisson, "K = 1 + X, X ~ Poisson(lam), lam > 0"),
        Family("uniform", ("a", "b"), uniform,
               "equally likely on the steps a..b, 1 <= a <= b; hazard 1/(b-k+1)",
               integers=True),
        Family("exponential", ("rate",), exponential,
               "K = ceil(X), X ~ Exp(rate), rate > 0 (geometric(1 - exp(-rate)))"),
        Family("weibull", ("shape", "scale"), weibull,
               "K = ceil(X), S(k) = exp(-(k/scale)^shape), shape, scale > 0"),
        Family("gamma", ("shape", "scale"), gamma,
               "K = ceil(X), X ~ Gamma(shape, scale), shape, scale > 0"),
        Family("scipy", (), _build_scipy,
               "any scipy.stats law: discrete K = X (+1 if its support starts at 0), "
               "continuous K = ceil(X)", variadic=True, named=True),
    )
})


def _build(family: str, args: Sequence[Any], label: str) -> FirstOccurrence:
    """Look ``family`` up in :data:`FAMILIES` and build it from ``args``; unknown
    families and arity errors are reported at ``label``."""
    fam = FAMILIES.get(family)
    if fam is None:
        raise DistributionError(
            label,
            f"unknown distribution family {family!r}; expected one of {', '.join(FAMILIES)}",
        )
    why = fam.arity_error(len(args))
    if why is not None:
        raise DistributionError(label, why)
    return fam.build(*args)


def from_spec(spec: DistLiteral) -> FirstOccurrence:
    """The distribution of an inline formula literal such as ``geometric(0.3)``,
    ``pmf(0.1, 0.3, 0.6)`` or ``scipy(nbinom, 3, 0.5)``.  Its label is ``str(spec)``."""
    from mitld_lp.logic.syntax import DistLiteral

    if not isinstance(spec, DistLiteral):
        raise DistributionError(
            str(spec), "is a name, not a distribution literal; bind it in the model file"
        )
    return _build(spec.family, spec.args, str(spec))


def from_table(value: object, path: str) -> FirstOccurrence:
    """The distribution of a model file's inline table with exactly one key, e.g.
    ``{ geometric = 0.8 }``, ``{ pmf = [0.1, 0.3, 0.6] }``, ``{ poisson = 2.5 }``,
    ``{ uniform = [1, 6] }``, ``{ exponential = 0.5 }``, ``{ weibull = [1.5, 3.0] }``,
    ``{ gamma = [2.0, 1.5] }``, ``{ scipy = ["nbinom", 3, 0.5] }``.

    Errors name the key path: ``distributions.mu2.pmf: masses sum to 1.2 > 1``.
    """
    example = "{ geometric = 0.8 }"
    if not isinstance(value, Mapping):
        raise DistributionError(
            path,
            f"must be an inline table with one distribution key such as {example}, got {value!r}",
        )
    if len(value) != 1:
        keys = ", ".join(str(k) for k in value) or "none"
        raise DistributionError(
            path, f"must have exactly one distribution key ({', '.join(FAMILIES)}), got {keys}"
        )
    ((family, arg),) = value.items()
    where = f"{path}.{family}"
    if family not in FAMILIES:
        raise DistributionError(
            path, f"unknown distribution {family!r}; expected one of {', '.join(FAMILIES)}"
        )
    if FAMILIES[family].takes_list:
        if not isinstance(arg, list | tuple):
            raise DistributionError(where, f"must be a list, got {arg!r}")
        args = list(arg)
    else:
        if isinstance(arg, list | tuple | Mapping | str):
            raise DistributionError(where, f"must be a number, got {arg!r}")
        args = [arg]
    try:
        return _build(str(family), args, where)
    except DistributionError as exc:
        raise DistributionError(where, exc.reason) from exc
