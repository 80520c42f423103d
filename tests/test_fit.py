"""Fitting laws to observed (right-censored) times and the bands they give; interval
parameters.  Expected values come from closed forms, hand calculations and scipy."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import optimize, stats

from mitld_lp.distributions import DistributionError, from_table, geometric, poisson
from mitld_lp.distributions.band import ConstantBand, EnvelopeBand, TableBand
from mitld_lp.distributions.fit import (
    MIN_OBSERVATIONS,
    fit_law,
    kaplan_meier,
    observations,
    read_observations,
)


def _censored_geometric(rng: np.random.Generator, p: float, n: int, watch: int):
    """``n`` geometric(p) times, each watched for a uniform 1..watch steps."""
    k = rng.geometric(p, n)
    c = rng.integers(1, watch + 1, n)
    cens = k > c
    return np.where(cens, c, k), cens


# --------------------------------------------------------------------------- geometric


def test_geometric_mle_is_events_over_exposure_and_scipy_agrees() -> None:
    rng = np.random.default_rng(7)
    t, cens = _censored_geometric(rng, 0.25, 60, 6)
    fit = fit_law(t, cens, family="geometric")
    d, exposure = int(np.sum(~cens)), int(np.sum(t))
    assert fit.parameters[0].estimate == pytest.approx(d / exposure, rel=1e-15)
    assert fit.point.hazard(1) == pytest.approx(d / exposure, rel=1e-15)

    # scipy's numeric maximum of the censored likelihood, written with scipy.stats.geom
    def nll(p: float) -> float:
        return -(stats.geom.logpmf(t[~cens], p).sum() + stats.geom.logsf(t[cens], p).sum())

    best = optimize.minimize_scalar(nll, bounds=(1e-6, 1 - 1e-6), method="bounded",
                                    options={"xatol": 1e-12})
    assert best.x == pytest.approx(d / exposure, abs=1e-7)
    assert fit.log_likelihood == pytest.approx(-nll(d / exposure), rel=1e-12)


def test_censored_observations_are_not_dropped_nor_events() -> None:
    t = [2, 3, 1, 4, 5, 2, 6, 3, 1, 2, 8, 8]
    cens = [False] * 10 + [True, True]
    fit = fit_law(t, cens)
    # exposure 29 + 16 = 45: dropped would give 10/29, read as events 12/45
    assert fit.parameters[0].estimate == pytest.approx(10 / 45, rel=1e-15)


def test_geometric_band_is_clopper_pearson() -> None:
    t = [1] * 3 + [4] * 9
    fit = fit_law(t, family="geometric", confidence=0.9)
    d, e = 12, 39
    lo = stats.beta.ppf(0.05, d, e - d + 1)
    hi = stats.beta.ppf(0.95, d + 1, e - d)
    band = fit.band
    assert isinstance(band, ConstantBand)
    assert band.hazard_band(5) == (pytest.approx(lo), pytest.approx(hi))
    assert band.is_memoryless


def test_geometric_band_covers_the_truth() -> None:
    rng = np.random.default_rng(11)
    p, runs, hits = 0.3, 300, 0
    for _ in range(runs):
        t, cens = _censored_geometric(rng, p, 40, 5)
        if cens.all():
            continue
        lo, hi = fit_law(t, cens).band.hazard_band(1)
        hits += lo <= p <= hi
    # 95% nominal; Clopper-Pearson is conservative: below 92% would be a broken band
    assert hits / runs >= 0.92


def test_exponential_fit_is_the_geometric_of_its_discretisation() -> None:
    # K = ceil(X), X ~ Exp(rate), is geometric(1 - exp(-rate)): the MLE is
    # rate = -log(1 - d / E) by the geometric closed form.
    rng = np.random.default_rng(3)
    t, cens = _censored_geometric(rng, 0.4, 80, 5)
    fit = fit_law(t, cens, family="exponential")
    d, e = int(np.sum(~cens)), int(np.sum(t))
    assert fit.parameters[0].estimate == pytest.approx(-math.log(1 - d / e), rel=1e-6)
    assert isinstance(fit.band, ConstantBand)


def test_poisson_fit_matches_scipy_numeric_mle() -> None:
    rng = np.random.default_rng(5)
    k = 1 + rng.poisson(3.0, 70)
    c = rng.integers(2, 9, 70)
    cens = k > c
    t = np.where(cens, c, k)
    fit = fit_law(t, cens, family="poisson")

    def nll(lam: float) -> float:  # K = 1 + X: pmf at t-1, survival P(X > c-1)
        return -(stats.poisson.logpmf(t[~cens] - 1, lam).sum()
                 + stats.poisson.logsf(t[cens] - 1, lam).sum())

    best = optimize.minimize_scalar(nll, bounds=(0.01, 20), method="bounded",
                                    options={"xatol": 1e-10})
    assert fit.parameters[0].estimate == pytest.approx(best.x, rel=1e-5)
    lo, hi = fit.parameters[0].lo, fit.parameters[0].hi
    q = stats.chi2.ppf(0.95, 1)
    for end in (lo, hi):  # the ends of the likelihood-ratio interval
        assert 2 * (nll(end) - best.fun) == pytest.approx(q, abs=1e-4)
    assert isinstance(fit.band, EnvelopeBand)


def test_two_parameter_fit_brackets_its_estimate() -> None:
    rng = np.random.default_rng(9)
    x = stats.weibull_min.rvs(1.5, scale=4.0, size=120, random_state=rng)
    k = np.ceil(x).astype(int)
    c = rng.integers(3, 10, 120)
    cens = k > c
    fit = fit_law(np.where(cens, c, k), cens, family="weibull")
    for par in fit.parameters:
        assert par.lo < par.estimate < par.hi
    shape, scale = (p.estimate for p in fit.parameters)
    assert 1.1 < shape < 2.0 and 3.0 < scale < 5.0


# --------------------------------------------------------------------------- empirical


def test_kaplan_meier_hand_example() -> None:
    # events at 1, 2, 2, 4; censored at 2, 3 and four times at 10 (n = 10).
    # step 1: 10 at risk, 1 event  -> S = 9/10
    # step 2:  9 at risk (the censoring at 2 still counts), 2 events -> 9/10 * 7/9 = 7/10
    # step 3:  6 at risk, no event -> 7/10
    # step 4:  5 at risk, 1 event  -> 7/10 * 4/5 = 14/25, then constant
    times = np.array([1, 2, 2, 4, 2, 3, 10, 10, 10, 10])
    cens = np.array([0, 0, 0, 0, 1, 1, 1, 1, 1, 1], dtype=bool)
    s = kaplan_meier(observations(times, cens))
    np.testing.assert_allclose(s, [1, 0.9, 0.7, 0.7] + [0.56] * 7, rtol=1e-14)
    fit = fit_law(times, cens, family="empirical")
    np.testing.assert_allclose(fit.point.pmf([1, 2, 3, 4, 5]), [0.1, 0.2, 0, 0.14, 0],
                               atol=1e-15)
    assert fit.point.never == pytest.approx(0.56)


def test_kaplan_meier_without_censoring_is_the_empirical_survival() -> None:
    t = np.array([3, 1, 4, 1, 5, 9, 2, 6, 5, 3, 5])
    s = kaplan_meier(observations(t))
    for k in range(10):
        assert s[k] == pytest.approx(np.mean(t > k), abs=1e-14)


def test_empirical_band_is_simultaneous_and_covers_the_truth() -> None:
    rng = np.random.default_rng(2)
    law = poisson(2.0)
    horizon = np.arange(0, 15)
    truth = law.survival(horizon)
    runs, hits = 200, 0
    for _ in range(runs):
        k = law.sample(rng, 30).astype(int)
        c = rng.integers(1, 8, 30)
        cens = k > c
        band = fit_law(np.where(cens, c, k), cens, family="empirical").band
        assert isinstance(band, TableBand)
        s_lo = band.s_lo[np.minimum(horizon, band.s_lo.size - 1)]
        s_hi = band.survival_upper(horizon)
        hits += bool(np.all((s_lo <= truth + 1e-12) & (truth <= s_hi + 1e-12)))
    assert hits / runs >= 0.95


def test_hazard_band_contains_every_law_of_the_survival_band() -> None:
    band = from_table({"poisson": [2.0, 3.0]}, "d.mu")
    k = np.arange(1, 12)
    lo, hi = band.hazard_band(k)
    for lam in np.linspace(2.0, 3.0, 9):
        h = poisson(lam).hazard(k)
        assert np.all(lo <= h + 1e-12) and np.all(h <= hi + 1e-12)
        assert np.all(poisson(lam).survival(k) <= band.survival_upper(k) + 1e-12)


def test_interval_parameter_laws() -> None:
    g = from_table({"geometric": [0.2, 0.4]}, "distributions.mu")
    assert g.is_ambiguous and g.is_memoryless
    assert g.hazard_band([1, 7]) == (pytest.approx([0.2, 0.2]), pytest.approx([0.4, 0.4]))
    assert g.survival_upper(3) == pytest.approx(0.8**3)
    assert str(g) == "geometric([0.2, 0.4])"
    assert not from_table({"geometric": [0.3, 0.3]}, "d.mu").is_ambiguous
    assert not geometric(0.3).is_ambiguous
    for bad, msg in [([0.4, 0.2], "exceeds"), ([0.2, 1.5], r"p must be in \(0, 1\]")]:
        with pytest.raises(DistributionError, match=msg):
            from_table({"geometric": bad}, "d.mu")


# --------------------------------------------------------------------------- bad data


@pytest.mark.parametrize(
    ("times", "censored", "message"),
    [
        ([1, 2, 3], None, f"3 observations; a fit needs at least {MIN_OBSERVATIONS}"),
        ([4] * 12, [True] * 12, "all 12 observations are censored"),
        ([1, 2, -3] + [1] * 9, None, "observation 3: time must be >= 0, got -3"),
        ([1, 2.5] + [1] * 10, None, "observation 2: time must be an integer, got 2.5"),
        ([0] + [1] * 11, None, "observation 1: an event time must be >= 1"),
    ],
)
def test_bad_observations_are_one_line(times, censored, message) -> None:
    with pytest.raises(DistributionError) as info:
        fit_law(times, censored)
    assert message in str(info.value)
    assert "\n" not in str(info.value)


def test_csv_errors_name_the_line(tmp_path: Path) -> None:
    f = tmp_path / "a.csv"
    f.write_text("# arrivals\ntime,censored\n3,0\n\n2.5,1\n")
    with pytest.raises(DistributionError, match=r"a.csv:5: time must be an integer"):
        read_observations(f)
    f.write_text("when\n3\n")
    with pytest.raises(DistributionError, match=r"a.csv:1: the header must name"):
        read_observations(f)
    f.write_text("time,censored\n" + "3,maybe\n" * 12)
    with pytest.raises(DistributionError, match=r"a.csv:2: censored must be"):
        read_observations(f)
    f.write_text("time\n" + "3\n" * 12)
    obs = read_observations(f)
    assert obs.n == 12 and obs.events == 12 and obs.exposure == 36


def test_fit_table_reads_data_beside_the_model(tmp_path: Path) -> None:
    (tmp_path / "arrivals.csv").write_text("time,censored\n" + "2,0\n4,1\n" * 6)
    law = from_table({"fit": "geometric", "data": "arrivals.csv", "confidence": 0.9},
                     "distributions.bus", base=tmp_path)
    assert law.is_ambiguous
    assert law.label == "fit(geometric, arrivals.csv, 0.9)"
    lo, hi = law.hazard_band(1)
    assert lo < 6 / 36 < hi
    with pytest.raises(DistributionError, match=r"distributions.bus.confidence: confidence "
                       r"must be in \(0, 1\)"):
        from_table({"fit": "geometric", "data": "arrivals.csv", "confidence": 1.5},
                   "distributions.bus", base=tmp_path)
    with pytest.raises(DistributionError, match=r"nope.csv: cannot read"):
        from_table({"fit": "geometric", "data": "nope.csv"}, "distributions.bus",
                   base=tmp_path)
    with pytest.raises(DistributionError, match=r"distributions.bus.extra: unknown key"):
        from_table({"fit": "geometric", "data": "a.csv", "extra": 1}, "distributions.bus")
