"""Laws in closed form or as a finite table, evaluated without scipy: the geometric,
a table of masses (pmf, and uniform up to ``MAX_TABLE_STEPS`` steps) and a long uniform.

Survival is computed directly (``q^k`` for the geometric, a reverse cumulative sum for a
table), never as ``1 - cdf``, so tails far below machine epsilon stay accurate; a table's
hazard is ``pmf/S`` from the same arrays.  Built and validated by :mod:`.families`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np

from mitld_lp.distributions.law import (
    MASS_TOLERANCE,
    FirstOccurrence,
    FloatArray,
    IntArray,
    constant_from,
)
from mitld_lp.util.decimals import exact_value

__all__ = ["Geometric", "Finite", "Uniform"]


# --------------------------------------------------------------------------- geometric


@dataclass(frozen=True, slots=True, eq=False)
class Geometric(FirstOccurrence):
    """``mu(k) = q^(k-1) p``, ``S(k) = q^k``, ``h(k) = p`` with ``q = 1 - p``."""

    p: float
    _q: float = field(init=False, repr=False)
    _log_q: float = field(init=False, repr=False)
    _q_exact: bool = field(init=False, repr=False)
    written: Any = field(default=None, repr=False)  # p as given: its exact value (None: p)

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

    @property
    def exact_hazards(self) -> bool:
        return True

    def exact_hazard(self, k: int) -> Fraction:
        """``p`` as written (:func:`mitld_lp.util.decimals.exact_value`), at every step."""
        return exact_value(self.p if self.written is None else self.written)

    def exact_constant_from(self) -> int:
        return 1

    def _sample_from(self, v: FloatArray) -> FloatArray:
        # S(k) = q^k < v  <=>  k > log(v)/log(q)
        with np.errstate(divide="ignore", invalid="ignore"):
            k = np.floor(np.log(v) / self._log_q) + 1.0
        return np.where(np.isnan(k), 1.0, k)


# --------------------------------------------------------------------------- finite tables


@dataclass(frozen=True, slots=True, eq=False)
class Finite(FirstOccurrence):
    """A finite table: ``mu(k) = masses[k-1]`` for ``1 <= k <= n``, 0 beyond."""

    masses: FloatArray = field(repr=False)
    _cum: FloatArray = field(init=False, repr=False)  # _cum[k] = P(K <= k), k = 0..n
    _surv: FloatArray = field(init=False, repr=False)  # _surv[k] = P(K > k), k = 0..n
    _never_mass: float = field(init=False, repr=False)
    # the masses as written: ("masses", values as given) or ("uniform", (a, b)); None:
    # the float masses themselves.  Read only by the exact hazards, made when first asked
    written: tuple[str, Any] | None = field(default=None, repr=False)
    _exact: tuple[tuple[Fraction, ...], tuple[Fraction, ...]] | None = field(
        default=None, init=False, repr=False)

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
        return constant_from(h == h[-1])

    @property
    def exact_hazards(self) -> bool:
        return True

    def _exact_table(self) -> tuple[tuple[Fraction, ...], tuple[Fraction, ...]]:
        """``(masses, survival)`` in rational arithmetic, ``survival[k] = P(K > k)`` for
        ``k = 0..n``: the masses as written, rescaled to total 1 exactly where the float
        table was (a total within ``MASS_TOLERANCE`` of 1), else the rest is never."""
        if self._exact is None:
            kind, given = self.written or ("masses", self.masses.tolist())
            if kind == "uniform":
                a, b = given
                m = [Fraction(0)] * (a - 1) + [Fraction(1, b - a + 1)] * (b - a + 1)
            else:
                m = [exact_value(x) for x in given]
            total = sum(m, Fraction(0))
            never = Fraction(0)
            if self._never_mass == 0.0 and total != 1:  # the float table was rescaled
                m = [x / total for x in m]
            elif self._never_mass != 0.0:
                never = 1 - total
            surv = [never] * (len(m) + 1)
            for k in range(len(m) - 1, -1, -1):
                surv[k] = surv[k + 1] + m[k]
            object.__setattr__(self, "_exact", (tuple(m), tuple(surv)))
        assert self._exact is not None
        return self._exact

    def exact_hazard(self, k: int) -> Fraction:
        """``m_k / S(k-1)`` in rationals (1 where ``S(k-1) = 0``; 0 or 1 after the table)."""
        m, surv = self._exact_table()
        before = surv[min(k - 1, len(m))]
        if before == 0:
            return Fraction(1)
        return (m[k - 1] if k <= len(m) else Fraction(0)) / before

    def exact_constant_from(self) -> int:
        h = [self.exact_hazard(k) for k in range(1, self._n + 2)]
        return constant_from(np.array([x == h[-1] for x in h], dtype=bool))

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
class Uniform(FirstOccurrence):
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

    @property
    def exact_hazards(self) -> bool:
        return True

    def exact_hazard(self, k: int) -> Fraction:
        if k < self.a:
            return Fraction(0)
        return Fraction(1, self.b - k + 1) if k <= self.b else Fraction(1)

    def exact_constant_from(self) -> int:
        return self.b
