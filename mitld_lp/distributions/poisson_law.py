"""The Poisson law in closed form, without ``scipy.stats`` (whose import is about 1 s of a
small model file's process; :func:`mitld_lp.distributions.families.poisson` uses this).

:class:`PoissonX` answers what :class:`~mitld_lp.distributions.scipy_laws.ShiftedDiscrete`
asks of a frozen ``scipy.stats.poisson(lam)``: ``pmf``, ``cdf``, ``sf``, ``logpmf`` and
``logsf`` at integer arrays ``x`` (``x < 0`` included).

* The pmf by Loader's saddle-point form (C. Loader, "Fast and accurate computation of
  binomial probabilities", 2000; R's ``dpois_raw``): ``exp(-stirlerr(x) - bd0(x, lam)) /
  sqrt(2 pi x)``, with Stirling's error in exact decimals for ``x <= 15`` and its series
  beyond, and ``bd0 = x log(x/lam) + lam - x`` by its series where ``x`` is near ``lam``
  (no cancellation): accurate to a few units in the last place where
  ``lam^x e^-lam / x!`` by logarithms would lose ``|log pmf|`` ulps.
* The head ``cdf(x) = sum_{j<=x} pmf(j)`` and the tail ``sf(x) = sum_{j>x} pmf(j)`` are
  summed from ``pmf(x)`` (``pmf(x+1)``) by a running product of the ratios ``j/lam``
  (``lam/j``), largest term first, until the terms no longer count; each side is
  computed directly where it is at most one half and is ``1 -`` the other beyond, so a
  tail far below machine epsilon keeps its relative accuracy.

The values agree with SciPy's to a relative 1e-13 (``tests/test_start_lean.py``), not to
the bit: a law built on them moves in its last bits against SciPy's.
"""

from __future__ import annotations

import math
from decimal import Context, Decimal
from functools import cache
from typing import Any

import numpy as np

__all__ = ["PoissonX"]

_LOG_SQRT_2PI = 0.918938533204672741780329736406  # log(2 pi) / 2
_PI = "3.14159265358979323846264338327950288419716939937510"
_S0, _S1, _S2, _S3, _S4 = 1 / 12, 1 / 360, 1 / 1260, 1 / 1680, 1 / 1188
_NEGLIGIBLE = 2.0**-60  # a term below this share of its sum no longer counts
_MAX_TERMS = 1 << 22


@cache
def _stirlerr_small() -> np.ndarray:
    """``log(n!) - (n + 1/2) log n + n - log(2 pi)/2`` for ``n = 0 .. 15`` (0 at ``n = 0``),
    in 40-digit decimals rounded once to floats."""
    ctx = Context(prec=40)
    half_log_2pi = ctx.divide(ctx.ln(ctx.multiply(Decimal(2), Decimal(_PI))), Decimal(2))
    out = [0.0]
    log_fact = Decimal(0)
    for n in range(1, 16):
        ln_n = ctx.ln(Decimal(n))
        log_fact = ctx.add(log_fact, ln_n)
        value = log_fact - (Decimal(n) + Decimal("0.5")) * ln_n + Decimal(n) - half_log_2pi
        out.append(float(ctx.plus(value)))
    return np.array(out)


def _stirlerr(n: np.ndarray) -> np.ndarray:
    """Stirling's error at integers ``n >= 1`` (Loader's series beyond 15)."""
    small = n <= 15
    nf = np.where(small, 16.0, n.astype(np.float64))
    nn = nf * nf
    big = np.where(
        nf > 500, (_S0 - _S1 / nn) / nf,
        np.where(nf > 80, (_S0 - (_S1 - _S2 / nn) / nn) / nf,
                 np.where(nf > 35, (_S0 - (_S1 - (_S2 - _S3 / nn) / nn) / nn) / nf,
                          (_S0 - (_S1 - (_S2 - (_S3 - _S4 / nn) / nn) / nn) / nn) / nf)))
    return np.where(small, _stirlerr_small()[np.minimum(n, 15)], big)


def _bd0(x: np.ndarray, lam: float) -> np.ndarray:
    """``x log(x/lam) + lam - x`` for floats ``x > 0``, by its series where ``x`` is near
    ``lam`` (each term at most a hundredth of the one before)."""
    near = np.abs(x - lam) < 0.1 * (x + lam)
    out = x * np.log(x / lam) + lam - x
    if near.any():
        xn = x[near]
        v = (xn - lam) / (xn + lam)
        s = (xn - lam) * v
        ej = 2 * xn * v
        v = v * v
        for j in range(1, 1000):
            ej = ej * v
            s1 = s + ej / (2 * j + 1)
            if np.array_equal(s1, s):
                break
            s = s1
        out[near] = s
    return out


def _running_sum(x: np.ndarray, step: Any) -> np.ndarray:
    """``1 + t_1 + t_2 + ...`` at each ``x``, ``t_i = t_(i-1) * factor`` with ``(factor,
    more, rising) = step(x, i)``: summed largest term first while ``more`` and until a
    term no longer counts, unless the terms may still be ``rising``."""
    s = np.ones(x.shape)
    term = np.ones(x.shape)
    live = np.ones(x.shape, dtype=bool)
    for i in range(1, _MAX_TERMS):
        idx = np.flatnonzero(live)
        if idx.size == 0:
            break
        factor, more, rising = step(x[idx], i)
        t = term[idx] * factor
        term[idx] = t
        s[idx] += t
        live[idx] = more & ((t >= _NEGLIGIBLE * s[idx]) | rising)
    return s


class PoissonX:
    """``X ~ Poisson(lam)``, ``lam > 0`` finite, at integer arrays (the methods of a frozen
    ``scipy.stats.poisson`` that the shifted law reads)."""

    __slots__ = ("lam",)

    def __init__(self, lam: float) -> None:
        self.lam = float(lam)

    def __repr__(self) -> str:
        return f"PoissonX({self.lam!r})"

    def __reduce__(self) -> tuple[Any, ...]:
        return (PoissonX, (self.lam,))

    def _logpmf_nonneg(self, x: np.ndarray) -> np.ndarray:
        """``log pmf`` at integers ``x >= 0``."""
        lam = self.lam
        out = np.full(x.shape, -lam)  # x = 0: e^-lam
        pos = x > 0
        if pos.any():
            xp = x[pos]
            xf = xp.astype(np.float64)
            with np.errstate(over="ignore"):
                out[pos] = -_stirlerr(xp) - _bd0(xf, lam) - (0.5 * np.log(xf) + _LOG_SQRT_2PI)
        return out

    def logpmf(self, x: Any) -> np.ndarray:
        xs = np.asarray(x, dtype=np.int64)
        out = np.full(xs.shape, -np.inf)
        ok = xs >= 0
        out[ok] = self._logpmf_nonneg(xs[ok])
        return out

    def pmf(self, x: Any) -> np.ndarray:
        xs = np.asarray(x, dtype=np.int64)
        out = np.zeros(xs.shape)
        ok = xs >= 0
        out[ok] = self._pmf_nonneg(xs[ok])
        return out

    def _pmf_nonneg(self, x: np.ndarray) -> np.ndarray:
        pos = x > 0
        xf = x[pos].astype(np.float64)
        out = np.full(x.shape, math.exp(-self.lam))
        if pos.any():
            # Loader: exp(-stirlerr - bd0) / sqrt(2 pi x), the root taken apart from the
            # exponent (R's R_D_fexp)
            with np.errstate(over="ignore"):
                out[pos] = np.exp(-_stirlerr(x[pos]) - _bd0(xf, self.lam)) / np.sqrt(
                    2 * math.pi * xf)
        return out

    def _head(self, x: np.ndarray) -> np.ndarray:
        """``sum_{j <= x} pmf(j)`` at integers ``x >= 0``: from ``pmf(x)`` down, each term
        ``j/lam`` times the one above (decreasing while ``j < lam``)."""
        lam = self.lam

        def step(xi: np.ndarray, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            j = xi - i + 1  # pmf(x - i) = pmf(x - i + 1) (x - i + 1)/lam
            return j / lam, j > 1, j > lam

        return self._pmf_nonneg(x) * _running_sum(x, step)

    def _tail(self, x: np.ndarray) -> np.ndarray:
        """``sum_{j > x} pmf(j) / pmf(x + 1)`` at integers ``x >= 0``: from 1 up, each term
        ``lam/j`` times the one below (decreasing once ``j > lam``), so that the tail's
        logarithm does not underflow where the tail does."""
        lam = self.lam

        def step(xi: np.ndarray, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            j = (xi + i + 1).astype(np.float64)  # pmf(x + i + 1) = pmf(x + i) lam/(x + i + 1)
            return lam / j, np.ones(j.shape, dtype=bool), j <= lam

        return _running_sum(x, step)

    def _both(self, x: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(cdf, sf, log sf)`` at ``x``: each side summed directly where it may be under
        one half, else one minus the other; the log of a direct tail as ``log pmf(x+1)
        + log(sum / pmf(x+1))``, finite (and the hazard near 1) where the tail underflows."""
        xs = np.asarray(x, dtype=np.int64)
        cdf = np.zeros(xs.shape)
        sf = np.ones(xs.shape)
        log_sf = np.zeros(xs.shape)
        ok = xs >= 0
        xo = xs[ok]
        head = np.full(xo.shape, np.nan)
        ratio = np.full(xo.shape, np.nan)  # the tail over pmf(x + 1)
        below = xo < self.lam
        head[below] = self._head(xo[below])
        ratio[~below] = self._tail(xo[~below])
        tail = self._pmf_nonneg(xo + 1) * ratio
        # the other side where this one is above one half (x near the mean)
        more = below & (head > 0.5)
        ratio[more] = self._tail(xo[more])
        tail[more] = self._pmf_nonneg(xo[more] + 1) * ratio[more]
        more = ~below & (tail > 0.5)
        head[more] = self._head(xo[more])
        direct = ~np.isnan(tail)
        cdf[ok] = np.where(np.isnan(head), 1.0 - tail, head)
        sf[ok] = np.where(direct, tail, 1.0 - head)
        with np.errstate(divide="ignore"):
            log_sf[ok] = np.where(direct, self._logpmf_nonneg(xo + 1) + np.log(ratio),
                                  np.log1p(-head))
        return cdf, sf, log_sf

    def cdf(self, x: Any) -> np.ndarray:
        return self._both(x)[0]

    def sf(self, x: Any) -> np.ndarray:
        return self._both(x)[1]

    def logsf(self, x: Any) -> np.ndarray:
        return self._both(x)[2]
