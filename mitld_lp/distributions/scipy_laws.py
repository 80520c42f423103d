"""Laws read from ``scipy.stats``: a discrete ``X`` shifted onto the steps, and a
continuous ``X >= 0`` read at whole steps.

* :class:`ShiftedDiscrete`: ``K = X + shift``; survival is scipy's ``sf``, the hazard
  ``exp(logpmf(k) - logsf(k-1))``.
* :class:`Discretised`: ``K = ceil(X)``, ``mu(k) = F(k) - F(k-1)``; the hazard is
  ``1 - S(k)/S(k-1) = -expm1(logsf(k) - logsf(k-1))``.

Survival is never computed as ``1 - cdf`` where it is small, so tails far below machine
epsilon stay accurate.  ``scipy.stats`` is imported on first use (:func:`stats`): the
import takes ~0.6-1 s, which ``import mitld_lp`` and a model with only geometric, table,
Poisson, exponential or Weibull laws should not pay (the last three give these adapters
a closed form in place of a frozen scipy law: :mod:`.poisson_law`, :mod:`.weibull_law`).
The families that use these adapters validate their numbers first (:mod:`.families`);
here the frozen law's support is checked, and its values at step 1
must be numbers (scipy accepts some parameters it then evaluates to nan).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mitld_lp.distributions.law import (
    MAX_HAZARD_SCAN,
    NEGLIGIBLE_TAIL,
    DistributionError,
    FirstOccurrence,
    FloatArray,
    IntArray,
    constant_from,
    hazards_close,
)

__all__ = ["stats", "generator", "ShiftedDiscrete", "Discretised", "shifted", "discretised",
           "evaluable"]


def stats() -> Any:
    """``scipy.stats``, imported when a law first needs it."""
    import scipy.stats

    return scipy.stats


def generator(label: str, name: object) -> Any:
    """The ``scipy.stats`` distribution called ``name`` (discrete or continuous)."""
    if not isinstance(name, str) or not name.isidentifier() or name.startswith("_"):
        raise DistributionError(label, f"scipy distribution name must be a name, got {name!r}")
    gen = getattr(stats(), name, None)
    if not isinstance(gen, stats().rv_discrete | stats().rv_continuous):
        raise DistributionError(label, f"unknown scipy.stats distribution {name!r}")
    return gen


_UNSET: Any = object()


@dataclass(frozen=True, slots=True, eq=False)
class ScipyBased(FirstOccurrence):
    """Shared by the scipy families: the numeric constant-hazard scan, cached."""

    dist: Any = field(repr=False)  # a frozen scipy.stats distribution
    last: float = field(repr=False)  # the last step with positive mass, or inf
    _chf: Any = field(init=False, repr=False, default=_UNSET)
    # the hazard never decreases and tends to 1 (a log-concave pmf, e.g. the Poisson's:
    # families.poisson), so its range from step k is (h(k), 1)
    increasing: bool = field(default=False, repr=False, kw_only=True)

    def _never(self) -> float:
        return 0.0

    def _last_step(self) -> float:
        return self.last

    def _constant_hazard_from(self) -> int | None:
        if self._chf is _UNSET:
            object.__setattr__(self, "_chf", self._scan_constant_hazard())
        return self._chf

    def _hazard_range_unsettled(self, k: int) -> tuple[float, float]:
        if self.increasing:
            return float(self.hazard(k)), 1.0
        return 0.0, 1.0

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
        if not hazards_close(self._hazard_pos(probe), ref).all():
            return None
        h = self._hazard_pos(np.arange(1, end + 1, dtype=np.int64))
        k0 = constant_from(hazards_close(h, ref))
        return k0 if k0 <= big_k else None


@dataclass(frozen=True, slots=True, eq=False)
class ShiftedDiscrete(ScipyBased):
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
class Discretised(ScipyBased):
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


# --------------------------------------------------------------------------- construction


def _freeze(
    label: str, name: str, gen: Any, args: Sequence[float], kwargs: dict[str, float]
) -> tuple[Any, float, float]:
    """``gen`` frozen at ``args``, ``kwargs`` and the bounds of its support."""
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


def evaluable(law: ScipyBased, name: str) -> ScipyBased:
    """``law``, once its pmf, survival and hazard at step 1 are numbers (a
    :class:`DistributionError` naming the first that is not).  ``law.dist`` may be any
    object with a frozen scipy law's ``pmf``, ``cdf``, ``sf``, ``logpmf`` and ``logsf``
    (:class:`~mitld_lp.distributions.poisson_law.PoissonX`)."""
    try:
        with np.errstate(all="ignore"):
            law.pmf(1)
            law.survival(1)
            law.hazard(1)
    except DistributionError as err:
        raise DistributionError(
            law.label, f"scipy.stats.{name} cannot evaluate these parameters: {err.reason}"
        ) from None
    return law


def shifted(label: str, name: str, gen: Any, args: Sequence[float]) -> FirstOccurrence:
    """The discrete ``gen`` at ``args`` as a first-occurrence law: ``K = 1 + X`` if its
    support starts at 0, ``K = X`` if it starts at 1 or later; below 0 is an error."""
    frozen, lo, hi = _freeze(label, name, gen, args, {})
    if lo < 0:
        raise DistributionError(
            label, f"support starts at {lo:g} < 0 (steps start at 1; 0 is shifted to 1)"
        )
    if lo != math.floor(lo):
        raise DistributionError(label, f"support must start at an integer, got {lo:g}")
    shift = 1 if lo == 0 else 0
    return evaluable(ShiftedDiscrete(label, frozen, hi + shift, shift=shift), name)


def discretised(
    label: str, name: str, gen: Any, args: Sequence[float], kwargs: dict[str, float]
) -> FirstOccurrence:
    """The continuous ``gen`` at ``args``, ``kwargs`` read at whole steps,
    ``K = ceil(X)``; its support must lie in ``[0, inf)`` with no mass at 0."""
    frozen, lo, hi = _freeze(label, name, gen, args, kwargs)
    if lo < 0:
        raise DistributionError(
            label, f"support starts at {lo:g} < 0: mass on step 0 (needs support in [0, inf))"
        )
    f0 = float(frozen.cdf(0.0))
    if f0 > 0:
        raise DistributionError(label, f"mass on step 0: F(0) = {f0:.6g} > 0")
    last = float(math.ceil(hi)) if math.isfinite(hi) else math.inf
    return evaluable(Discretised(label, frozen, last), name)
