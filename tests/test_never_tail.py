"""A band whose hazard may stay positive for ever while its laws' never masses differ
(issue 43): its tail bounded by a constant interval past a step, once holding every
interval of the band (outer) and once lying within every one (inner), instead of the
refusal; expected values by hand (the Poisson pmf written out, hazards of mass tables)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mitld_lp.distributions import pmf, poisson
from mitld_lp.distributions.band import (
    UnboundedBand,
    band_of_laws,
    needs_tail,
    tail_bands,
    tail_intervals,
    tail_step,
)


def poisson_hazard(lam: float, k: int) -> float:
    """``h(k)`` of ``K = 1 + X``, ``X ~ Poisson(lam)``, by hand: ``P(X = k-1) /
    P(X >= k-1)``, the tail summed until its terms vanish."""
    x = k - 1
    term = math.exp(-lam) * lam ** x / math.factorial(x)
    tail, t, j = 0.0, term, x
    while t > 1e-300 * max(tail, 1e-300) and j < x + 400:
        tail += t
        j += 1
        t *= lam / j
    return term / tail


def poisson_truncation(lam: float, eps: float) -> int:
    """The smallest ``T`` with ``P(1 + X > T) = P(X >= T) <= eps``, by hand."""
    T, below = 0, 0.0  # below = P(X < T)
    while 1.0 - below > eps:
        below += math.exp(-lam) * lam ** T / math.factorial(T)
        T += 1
    return T


UNSETTLED = band_of_laws("mu", pmf([0.3, 0.3]), [pmf([0.2, 0.3]), poisson(2.0)])
SURE_TOO = band_of_laws("mu", pmf([0.3, 0.3]), [pmf([0.5, 0.5]), poisson(2.0)])


def test_hazard_range_of_laws_by_hand():
    assert pmf([0.3, 0.3]).hazard_range_from(3) == (0.0, 0.0)  # never mass 0.4 left
    assert pmf([0.5, 0.5]).hazard_range_from(3) == (1.0, 1.0)  # past a sure law's support
    assert pmf([0.5, 0.5]).hazard_range_from(1) == (0.5, 1.0)  # h(1) = 0.5, h(2) = 1
    lo, hi = poisson(2.0).hazard_range_from(6)
    assert lo == pytest.approx(poisson_hazard(2.0, 6), rel=1e-9) and hi == 1.0
    # the Poisson hazard increases (its pmf is log-concave), towards 1
    h = [poisson_hazard(2.0, k) for k in range(1, 60)]
    assert all(a <= b for a, b in zip(h, h[1:], strict=False)) and h[-1] > 0.95


def test_outer_and_inner_intervals_by_hand():
    K = 10
    outer, inner = tail_intervals(UNSETTLED, K)
    # the table's hazard past its support is 0, the Poisson's in [h(K+1), 1)
    assert outer == (0.0, 1.0)
    assert inner is not None and inner[0] == 0.0
    assert inner[1] == pytest.approx(poisson_hazard(2.0, K + 1), rel=1e-9)
    # a sure law (hazard 1 past its support) beside a never one: every interval is [0, 1]
    assert tail_intervals(SURE_TOO, K) == ((0.0, 1.0), (0.0, 1.0))
    # a mass table with never mass 0.2 (hazard 0) beside a Poisson and a sure law: the
    # inner interval [min sup, max inf] = [0, 1] still lies within every [0, 1]
    geo = band_of_laws("mu", pmf([0.5, 0.5]), [pmf([0.4, 0.3]), poisson(3.0)])
    assert tail_intervals(geo, 4) == ((0.0, 1.0), (0.0, 1.0))


def test_no_inner_interval_where_none_lies_within_all():
    # two Poisson laws beside a table: past K every interval is [0, max of Poisson
    # hazards]; with a law of hazard 0.3 for ever (a geometric) and one of 0 the lower
    # ends reach 0 and the upper ends stay >= h_P; an inner one exists ([0, h_P(K+1)])
    from mitld_lp.distributions import geometric

    b = band_of_laws("mu", pmf([0.3, 0.3]), [geometric(0.5), poisson(2.0)])
    outer, inner = tail_intervals(b, 3)
    # lo(k) = min(0, 0.5, h_P(k)) = 0, hi(k) = max(0, 0.5, h_P) >= max(0.5, h_P(4))
    assert outer == (0.0, 1.0)
    assert inner == (0.0, pytest.approx(max(0.5, poisson_hazard(2.0, 4)), rel=1e-9))
    # a law of a family without a bound on its hazard (a Weibull law: (0, 1) assumed)
    # beside a Poisson law: lo(k) may be anything up to 1, hi(k) as low as h_P(K+1)
    # (sup lo <= min(1, 1) = 1 > inf hi >= max(h_P, 0)): no inner interval
    from mitld_lp.distributions import weibull

    assert weibull(0.5, 3.0).hazard_range_from(6) == (0.0, 1.0)
    b2 = band_of_laws("mu", poisson(2.0), [weibull(0.5, 3.0)])
    assert tail_intervals(b2, 5) == ((0.0, 1.0), None)
    # beside a geometric(0.5) instead: sup lo <= 0.5 <= inf hi: the inner point [0.5, 0.5]
    b3 = band_of_laws("mu", geometric(0.5), [weibull(0.5, 3.0)])
    assert tail_intervals(b3, 5) == ((0.0, 1.0), (0.5, 0.5))


def test_tail_bands_hold_and_lie_within_the_band():
    K = tail_step(UNSETTLED, 1e-6)
    outer, inner = tail_bands(UNSETTLED, K)
    assert inner is not None
    ks = np.arange(1, K + 300)
    lo, hi = UNSETTLED.hazard_band(ks)
    olo, ohi = outer.hazard_band(ks)
    ilo, ihi = inner.hazard_band(ks)
    head = ks <= K
    assert np.array_equal(olo[head], lo[head]) and np.array_equal(ohi[head], hi[head])
    assert np.array_equal(ilo[head], lo[head]) and np.array_equal(ihi[head], hi[head])
    assert np.all(olo <= lo) and np.all(hi <= ohi)  # the outer holds every interval
    assert np.all(lo <= ilo) and np.all(ihi <= hi)  # the inner lies within every one
    assert outer.constant_hazard_from == K + 1 == inner.constant_hazard_from
    # nothing to truncate: the clock stops at K + 1; the nominal law keeps its never mass
    assert outer.nominal.never == pytest.approx(0.4) and outer.nominal.pmf(2) == 0.3


def test_tail_step_and_the_refusal_kept_apart():
    # the Poisson law surely happens: K its truncation point at eps, by hand
    assert tail_step(UNSETTLED, 1e-6) == poisson_truncation(2.0, 1e-6)
    assert needs_tail(UNSETTLED, 1e-6)
    with pytest.raises(UnboundedBand, match="allows an event that never happens"):
        UNSETTLED.truncation_point(1e-6)
    tables = band_of_laws("mu", pmf([0.3, 0.3]), [pmf([0.2, 0.3]), pmf([0.4, 0.3])])
    assert not needs_tail(tables, 1e-6)  # constant from step 3: solved exactly
    same = band_of_laws("mu", poisson(2.0), [poisson(3.0)])  # no never mass: truncated
    assert not needs_tail(same, 1e-6)
