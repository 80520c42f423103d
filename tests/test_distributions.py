"""Tests of mitld_lp.distributions.

Expected values come from closed forms, hand calculations or scipy.stats called directly
here -- never from the module's own output.
"""

from __future__ import annotations

import math
import pickle
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy import stats

from mitld_lp import distributions as D
from mitld_lp.distributions import DistributionError, FirstOccurrence
from mitld_lp.distributions.closed import Uniform
from mitld_lp.logic.syntax import DistLiteral, DistRef

# --------------------------------------------------------------------------- helpers


def chi_square_pvalue(samples: np.ndarray, probs: np.ndarray, never: float) -> float:
    """Chi-square goodness of fit of first-occurrence samples (inf = never) against the
    pmf ``probs[k-1]`` on steps 1..len(probs), the rest (later steps and never) pooled."""
    n = samples.size
    rest = max(1.0 - float(np.sum(probs)), 0.0)
    cells_p: list[float] = []
    cells_o: list[int] = []
    acc_p, acc_o = 0.0, 0
    for k, pk in enumerate(probs, start=1):
        acc_p += pk
        acc_o += int(np.sum(samples == k))
        if acc_p * n >= 5:
            cells_p.append(acc_p)
            cells_o.append(acc_o)
            acc_p, acc_o = 0.0, 0
    tail_o = acc_o + int(np.sum(samples > len(probs)))  # includes inf
    tail_p = acc_p + rest
    if tail_p * n >= 5 or not cells_p:
        cells_p.append(tail_p)
        cells_o.append(tail_o)
    else:
        cells_p[-1] += tail_p
        cells_o[-1] += tail_o
    assert never <= rest + 1e-12
    f_exp = np.array(cells_p) / np.sum(cells_p) * n
    return float(stats.chisquare(np.array(cells_o), f_exp).pvalue)


def sample_through_hazards(
    dist: FirstOccurrence, n: int, rng: np.random.Generator, horizon: int
) -> np.ndarray:
    """Step-by-step Bernoulli trials with the hazards: the environment's view."""
    out = np.full(n, np.inf)
    alive = np.ones(n, dtype=bool)
    for k in range(1, horizon + 1):
        idx = np.flatnonzero(alive)
        if idx.size == 0:
            break
        fire = rng.random(idx.size) < dist.hazard(k)
        out[idx[fire]] = k
        alive[idx[fire]] = False
    return out


def geometric_pmf(p: float, k: np.ndarray) -> np.ndarray:
    return (1 - p) ** (k - 1) * p


def table_pmf(masses: list[float], k: np.ndarray) -> np.ndarray:
    padded = np.array([0.0, *masses])
    return np.where(k <= len(masses), padded[np.minimum(k, len(masses))], 0.0)


# (distribution, closed-form / scipy pmf on 1..H, never, horizon H)
CASES: list[tuple[str, Callable[[], FirstOccurrence], Callable[[np.ndarray], np.ndarray], float]]
CASES = [
    ("geometric", lambda: D.geometric(0.3), lambda k: geometric_pmf(0.3, k), 0.0),
    ("pmf", lambda: D.pmf([0.1, 0.3, 0.6]), lambda k: table_pmf([0.1, 0.3, 0.6], k), 0.0),
    (
        "pmf_never",
        lambda: D.pmf([0.2, 0.0, 0.3]),
        lambda k: table_pmf([0.2, 0.0, 0.3], k),
        0.5,
    ),
    ("uniform", lambda: D.uniform(2, 6), lambda k: np.where((k >= 2) & (k <= 6), 0.2, 0.0), 0.0),
    ("poisson", lambda: D.poisson(2.5), lambda k: stats.poisson.pmf(k - 1, 2.5), 0.0),
    (
        "weibull",
        lambda: D.weibull(1.5, 3.0),
        lambda k: np.exp(-(((k - 1) / 3.0) ** 1.5)) - np.exp(-((k / 3.0) ** 1.5)),
        0.0,
    ),
    (
        "nbinom",
        lambda: D.scipy_discrete("nbinom", 3, 0.5),
        lambda k: stats.nbinom.pmf(k - 1, 3, 0.5),
        0.0,
    ),
]
HORIZON = 60


# --------------------------------------------------------------------------- hazards


@pytest.mark.parametrize("p", [0.05, 0.3, 0.8, 1.0])
def test_geometric_closed_forms(p: float) -> None:
    d = D.geometric(p)
    k = np.arange(1, 40)
    np.testing.assert_allclose(d.hazard(k), p, rtol=1e-14)
    np.testing.assert_allclose(d.pmf(k), geometric_pmf(p, k), rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(d.survival(k), (1 - p) ** k, rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(d.cdf(k), 1 - (1 - p) ** k, rtol=1e-12)
    assert d.never == 0.0
    assert d.is_memoryless and d.constant_hazard_from == 1
    assert str(d) == f"geometric({p})"


@pytest.mark.parametrize(("a", "b"), [(1, 1), (1, 6), (3, 7)])
def test_uniform_hazard_is_one_over_remaining(a: int, b: int) -> None:
    d = D.uniform(a, b)
    for k in range(1, b + 3):
        expected_h = 1 / (b - k + 1) if a <= k <= b else (0.0 if k < a else 1.0)
        expected_m = 1 / (b - a + 1) if a <= k <= b else 0.0
        assert math.isclose(d.hazard(k), expected_h, rel_tol=1e-12)
        assert math.isclose(d.pmf(k), expected_m, rel_tol=1e-12)
    assert d.never == 0.0
    # hazard 1 at the last support step and (by convention) after it
    assert d.constant_hazard_from == b
    assert d.is_memoryless == (b == 1)


def test_pmf_hazards_by_hand() -> None:
    d = D.pmf([0.1, 0.3, 0.6])
    # h1 = 0.1/1, h2 = 0.3/0.9, h3 = 0.6/0.6, then 1 by convention (S = 0)
    np.testing.assert_allclose(d.hazard([1, 2, 3, 4, 10]), [0.1, 1 / 3, 1.0, 1.0, 1.0])
    np.testing.assert_allclose(d.survival([0, 1, 2, 3, 4]), [1.0, 0.9, 0.6, 0.0, 0.0], atol=1e-15)
    assert d.never == 0.0
    assert d.constant_hazard_from == 3
    assert not d.is_memoryless


def test_pmf_with_never_mass_by_hand() -> None:
    d = D.pmf([0.5, 0.25])
    # h1 = 0.5, h2 = 0.25/0.5, then the 0.25 left is "never": hazard 0
    np.testing.assert_allclose(d.hazard([1, 2, 3, 50]), [0.5, 0.5, 0.0, 0.0])
    assert math.isclose(d.never, 0.25)
    np.testing.assert_allclose(d.survival([2, 3, 100]), [0.25, 0.25, 0.25])
    assert d.constant_hazard_from == 3
    e = D.pmf([0.2, 0.0, 0.0])  # hazards 0.2, 0, 0, 0, ...
    assert e.constant_hazard_from == 2
    assert D.pmf([1.0]).is_memoryless  # surely at step 1: hazard 1 everywhere


def test_pmf_total_within_tolerance_counts_as_one() -> None:
    d = D.pmf([0.1, 0.2, 0.7])  # the float sum is 0.9999999999999999
    assert d.never == 0.0
    assert d.hazard(4) == 1.0
    assert d.truncation_point(0.0) == 3


def test_poisson_against_scipy() -> None:
    lam = 2.5
    d = D.poisson(lam)
    k = np.arange(1, 80)
    np.testing.assert_allclose(d.pmf(k), stats.poisson.pmf(k - 1, lam), rtol=1e-12)
    np.testing.assert_allclose(d.survival(k), stats.poisson.sf(k - 1, lam), rtol=1e-10)
    sf_before = np.where(k >= 2, stats.poisson.sf(k - 2, lam), 1.0)
    np.testing.assert_allclose(d.hazard(k), stats.poisson.pmf(k - 1, lam) / sf_before, rtol=1e-10)
    assert d.survival(60) > 0  # far tail not lost to 1 - cdf cancellation
    assert d.constant_hazard_from is None and not d.is_memoryless
    assert d.never == 0.0


@pytest.mark.parametrize("rate", [0.05, 0.5, 3.0])
def test_discretised_exponential_is_geometric(rate: float) -> None:
    p = 1 - math.exp(-rate)
    k = np.arange(1, 200)
    for d in (D.exponential(rate), D.weibull(1.0, 1 / rate), D.gamma(1.0, 1 / rate)):
        np.testing.assert_allclose(d.pmf(k), geometric_pmf(p, k), rtol=1e-9, atol=1e-300)
        np.testing.assert_allclose(d.survival(k), np.exp(-rate * k), rtol=1e-9, atol=1e-300)
        np.testing.assert_allclose(d.hazard(k), p, rtol=1e-9)
        assert d.is_memoryless, d.label


def test_discretised_continuous_against_closed_forms() -> None:
    d = D.weibull(1.5, 3.0)
    k = np.arange(1, 30)
    surv = np.exp(-((k / 3.0) ** 1.5))
    before = np.exp(-(((k - 1) / 3.0) ** 1.5))
    np.testing.assert_allclose(d.survival(k), surv, rtol=1e-12)
    np.testing.assert_allclose(d.pmf(k), before - surv, rtol=1e-9)
    np.testing.assert_allclose(d.hazard(k), 1 - surv / before, rtol=1e-9)
    assert d.constant_hazard_from is None
    g = D.gamma(2.0, 1.5)
    F = stats.gamma(2.0, scale=1.5).cdf
    np.testing.assert_allclose(g.pmf(k), F(k) - F(k - 1), rtol=1e-9)
    assert g.constant_hazard_from is None


def test_constant_hazard_from_later_step() -> None:
    # X = 2.5 + Exp(rate 0.5): no mass on steps 1, 2; F(3) = 1 - exp(-0.25); then geometric
    d = D.discretised("expon", 2.5, 2.0)
    np.testing.assert_allclose(d.hazard([1, 2]), [0.0, 0.0])
    assert math.isclose(d.hazard(3), 1 - math.exp(-0.25), rel_tol=1e-12)
    np.testing.assert_allclose(d.hazard(np.arange(4, 50)), 1 - math.exp(-0.5), rtol=1e-10)
    assert d.constant_hazard_from == 4


def test_scipy_discrete_support_rules() -> None:
    geom = D.scipy_discrete("geom", 0.3)  # support starts at 1: used as is
    k = np.arange(1, 30)
    np.testing.assert_allclose(geom.pmf(k), geometric_pmf(0.3, k), rtol=1e-12)
    assert geom.is_memoryless
    nb = D.scipy_discrete("nbinom", 3, 0.5)  # support starts at 0: K = 1 + X
    np.testing.assert_allclose(nb.pmf(k), stats.nbinom.pmf(k - 1, 3, 0.5), rtol=1e-12)
    assert nb.constant_hazard_from is None
    assert D.scipy_discrete("nbinom", 1, 0.4).is_memoryless  # nbinom(1, p) is geometric
    b = D.scipy_discrete("binom", 5, 0.3)  # K = 1 + X in 1..6: hazard 1 at step 6
    assert b.hazard(6) == 1.0 and b.hazard(7) == 1.0
    assert b.constant_hazard_from == 6
    shifted = D.scipy_discrete("poisson", 2.0, 3)  # loc 3: support starts at 3, used as is
    np.testing.assert_allclose(shifted.pmf(k), stats.poisson.pmf(k - 3, 2.0), rtol=1e-12)


def test_hazard_far_in_the_tail_is_stable() -> None:
    assert math.isclose(D.exponential(0.5).hazard(1500), 1 - math.exp(-0.5), rel_tol=1e-10)
    assert math.isclose(D.exponential(0.5).survival(1000), math.exp(-500), rel_tol=1e-10)
    assert D.geometric(0.5).survival(1000) == 2.0**-1000
    assert math.isclose(D.geometric(1e-9).hazard(10**6), 1e-9, rel_tol=1e-15)


# --------------------------------------------------------------------------- consistency


@pytest.mark.parametrize(("name", "make", "closed_pmf", "never"), CASES, ids=[c[0] for c in CASES])
def test_pmf_survival_cdf_consistency(
    name: str,
    make: Callable[[], FirstOccurrence],
    closed_pmf: Callable[[np.ndarray], np.ndarray],
    never: float,
) -> None:
    d = make()
    assert math.isclose(d.never, never, abs_tol=1e-12)
    k = np.arange(1, HORIZON + 1)
    m = d.pmf(k)
    expected = closed_pmf(k)
    np.testing.assert_allclose(m, expected, rtol=1e-9, atol=1e-15)
    # sum of pmf = 1 - never (the part beyond the horizon is the survival there)
    assert math.isclose(math.fsum(m) + d.survival(HORIZON), 1.0, abs_tol=1e-12)
    assert math.isclose(d.survival(10**6), never, abs_tol=1e-15)
    np.testing.assert_allclose(d.cdf(k) + d.survival(k), 1.0, atol=1e-12)
    np.testing.assert_allclose(d.survival(k - 1) - d.survival(k), m, atol=1e-12)
    np.testing.assert_allclose(d.survival(k - 1) * d.hazard(k), m, rtol=1e-9, atol=1e-15)
    assert d.survival(0) == 1.0 and d.survival(-4) == 1.0
    assert d.pmf(0) == 0.0 and d.pmf(-2) == 0.0 and d.cdf(0) == 0.0 and d.hazard(0) == 0.0


def test_scalar_and_array_returns() -> None:
    d = D.geometric(0.3)
    assert type(d.pmf(2)) is float
    assert type(d.hazard(np.int64(2))) is float
    out = d.survival(np.array([[1, 2], [3, 4]]))
    assert isinstance(out, np.ndarray) and out.shape == (2, 2)
    assert d.cdf([1, 2, 3]).shape == (3,)
    with pytest.raises(TypeError):
        d.pmf(1.5)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- truncation


@pytest.mark.parametrize("p", [0.05, 0.3, 0.8])
@pytest.mark.parametrize("eps", [0.1, 0.0123, 1e-3, 1e-9])
def test_truncation_point_geometric_closed_form(p: float, eps: float) -> None:
    t = D.geometric(p).truncation_point(eps)
    assert t == math.ceil(math.log(eps) / math.log(1 - p))
    assert (1 - p) ** t <= eps < (1 - p) ** (t - 1)


def test_truncation_point_by_hand_and_scipy() -> None:
    # uniform(1, 6): S(k) = (6-k)/6 <= 0.2  <=>  k >= 4.8
    assert D.uniform(1, 6).truncation_point(0.2) == 5
    assert D.uniform(1, 6).truncation_point(0.0) == 6
    d = D.pmf([0.1, 0.3, 0.6])  # S = 1, 0.9, 0.6, 0
    assert [d.truncation_point(e) for e in (1.0, 0.95, 0.9, 0.7, 0.6, 0.5, 0.0)] == [
        0,
        1,
        1,
        2,
        2,
        3,
        3,
    ]
    for eps in (0.1, 1e-3, 1e-8):
        t = D.poisson(2.5).truncation_point(eps)
        assert stats.poisson.sf(t - 1, 2.5) <= eps < stats.poisson.sf(t - 2, 2.5)
    assert D.pmf([0.5, 0.25]).truncation_point(0.25) == 2  # never = 0.25 = eps


def test_truncation_point_errors() -> None:
    with pytest.raises(DistributionError, match="eps must be >= 0"):
        D.geometric(0.3).truncation_point(-0.1)
    with pytest.raises(DistributionError, match=r"never happens with probability 0\.25"):
        D.pmf([0.5, 0.25]).truncation_point(0.1)
    with pytest.raises(DistributionError, match="eps must be > 0"):
        D.poisson(2.5).truncation_point(0.0)
    assert D.geometric(1.0).truncation_point(0.0) == 1


# --------------------------------------------------------------------------- sampling

SAMPLES = 20_000


@pytest.mark.parametrize(("name", "make", "closed_pmf", "never"), CASES, ids=[c[0] for c in CASES])
def test_sampling_through_hazards_reproduces_pmf(
    name: str,
    make: Callable[[], FirstOccurrence],
    closed_pmf: Callable[[np.ndarray], np.ndarray],
    never: float,
) -> None:
    d = make()
    rng = np.random.default_rng(20240601)
    samples = sample_through_hazards(d, SAMPLES, rng, HORIZON)
    k = np.arange(1, HORIZON + 1)
    probs = closed_pmf(k)
    assert chi_square_pvalue(samples, probs, never) > 1e-3


@pytest.mark.parametrize(("name", "make", "closed_pmf", "never"), CASES, ids=[c[0] for c in CASES])
def test_sample_reproduces_pmf(
    name: str,
    make: Callable[[], FirstOccurrence],
    closed_pmf: Callable[[np.ndarray], np.ndarray],
    never: float,
) -> None:
    d = make()
    samples = d.sample(np.random.default_rng(7), SAMPLES)
    assert samples.dtype == np.float64 and samples.shape == (SAMPLES,)
    finite = samples[np.isfinite(samples)]
    assert np.all(finite >= 1) and np.all(finite == np.floor(finite))
    k = np.arange(1, HORIZON + 1)
    probs = closed_pmf(k)
    assert chi_square_pvalue(samples, probs, never) > 1e-3
    if never > 0:
        assert abs(np.mean(np.isinf(samples)) - never) < 4 * math.sqrt(never / SAMPLES)


def test_sample_shapes_and_edge_cases() -> None:
    rng = np.random.default_rng(1)
    assert D.geometric(0.5).sample(rng, (3, 4)).shape == (3, 4)
    assert np.all(D.geometric(1.0).sample(rng, 100) == 1.0)
    assert np.all(np.isinf(D.pmf([0.0]).sample(rng, 100)))
    assert np.all(D.uniform(4, 4).sample(rng, 50) == 4.0)


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    ("make", "pattern"),
    [
        (lambda: D.geometric(1.5), r"^geometric\(1\.5\): p must be in \(0, 1\]$"),
        (lambda: D.geometric(0), r"geometric\(0\): p must be in"),
        (lambda: D.geometric(-0.2), r"p must be in"),
        (lambda: D.geometric(float("nan")), r"p must be in"),
        (lambda: D.geometric("x"), r"p must be a number"),  # type: ignore[arg-type]
        (lambda: D.geometric(True), r"p must be a number"),
        (lambda: D.pmf([0.5, -0.1]), r"mass m2 \(step 2\) is negative"),
        (lambda: D.pmf([0.7, 0.6]), r"^pmf\(0\.7, 0\.6\): masses sum to 1\.3 > 1$"),
        (lambda: D.pmf([0.2, float("nan")]), r"mass m2 .*must be finite"),
        (lambda: D.pmf([float("inf")]), r"mass m1 .*must be finite"),
        (lambda: D.pmf([]), r"at least one mass"),
        (lambda: D.pmf([0.1, "a"]), r"mass m2 .*must be a number"),  # type: ignore[list-item]
        (lambda: D.poisson(0), r"^poisson\(0\): lam must be a finite number > 0"),
        (lambda: D.poisson(-1.0), r"lam must be"),
        (lambda: D.poisson(float("nan")), r"lam must be"),
        (lambda: D.uniform(0, 3), r"uniform\(0, 3\): a must be >= 1"),
        (lambda: D.uniform(4, 2), r"b must be >= a = 4"),
        (lambda: D.uniform(1.5, 3), r"a must be an integer"),  # type: ignore[arg-type]
        (lambda: D.exponential(0.0), r"exponential\(0\.0\): rate must be"),
        (lambda: D.weibull(-1, 1), r"weibull\(-1, 1\): shape must be"),
        (lambda: D.weibull(1, 0), r"scale must be"),
        (lambda: D.gamma(0, 1), r"gamma\(0, 1\): shape must be"),
        (lambda: D.scipy_discrete("nosuchdist", 1), r"unknown scipy\.stats distribution"),
        (lambda: D.scipy_discrete("poisson", -1), r"scipy\(poisson, -1\): invalid parameters"),
        (lambda: D.scipy_discrete("poisson"), r"wrong arguments for scipy\.stats\.poisson"),
        (lambda: D.scipy_discrete("dlaplace", 0.5), r"support starts at -inf < 0"),
        (lambda: D.scipy_discrete("norm"), r"continuous, not discrete"),
        (lambda: D.scipy_discrete("poisson", float("nan")), r"argument 1 must be a finite.*nan"),
        (lambda: D.scipy_discrete("nbinom", math.inf, 0.5), r"argument 1 must be a finite.*inf"),
        (lambda: D.discretised("expon", 0, -math.inf), r"argument 2 must be a finite.*-inf"),
        (lambda: D.discretised("norm", 5, 1), r"mass on step 0"),
        (lambda: D.discretised("expon", -1.0), r"mass on step 0"),
        (lambda: D.discretised("poisson", 2), r"discrete, not continuous"),
        (lambda: D.discretised("gamma", -2.0), r"invalid parameters for scipy\.stats\.gamma"),
    ],
)
def test_invalid_parameters(make: Callable[[], FirstOccurrence], pattern: str) -> None:
    with pytest.raises(DistributionError, match=pattern):
        make()


# Every family's numeric parameters, one at a time set to a value no float holds
# (issue 16 item 9: poisson(10^400) was an OverflowError traceback).
_VALID = {
    "geometric": (0.5,), "pmf": (0.25, 0.75), "poisson": (2.0,), "uniform": (2, 4),
    "exponential": (0.5,), "weibull": (1.5, 3.0), "gamma": (2.0, 1.5),
    "scipy": ("nbinom", 3, 0.5),
}


@pytest.mark.parametrize("family", sorted(_VALID))
@pytest.mark.parametrize(
    ("huge", "digits"), [(10**400, 401), (-(10**400), 401), (10**5000, 5001)],
    ids=["1e400", "-1e400", "1e5000"],
)
def test_integers_beyond_the_float_range_are_distribution_errors(
    family: str, huge: int, digits: int
) -> None:
    args = _VALID[family]
    first = 1 if family == "scipy" else 0
    assert D.from_spec(DistLiteral(family, args)).pmf(3) >= 0  # the valid law builds
    for i in range(first, len(args)):
        bad = (*args[:i], huge, *args[i + 1 :])
        with pytest.raises(DistributionError) as info:
            D.from_spec(DistLiteral(family, bad))
        message = str(info.value)
        assert "\n" not in message and len(message) < 300, message
        assert f"integer of {digits} digits" in message


@pytest.mark.parametrize("family", sorted(_VALID))
@pytest.mark.parametrize(
    "value", [math.nan, math.inf, -math.inf, 10**400], ids=["nan", "inf", "-inf", "1e400"]
)
def test_model_file_tables_refuse_values_no_float_holds(family: str, value: float) -> None:
    """The model file route (``{ family = value }``): the error names the key path."""
    args = list(_VALID[family])
    at = 1 if family == "scipy" else 0
    args[at] = value
    table = {family: args if D.FAMILIES[family].takes_list else args[0]}
    with pytest.raises(DistributionError) as info:
        D.from_table(table, "distributions.mu")
    assert str(info.value).startswith(f"distributions.mu.{family}: ")


def test_scipy_parameters_it_evaluates_to_nan_are_refused() -> None:
    """scipy accepts hypergeom(M=1e300, n=5, N=10) but its pmf there is nan (by hand:
    the pmf of a hypergeometric is a number in [0, 1] at every step)."""
    assert math.isnan(stats.hypergeom(1e300, 5, 10).pmf(0))
    with pytest.raises(DistributionError, match=r"scipy\.stats\.hypergeom cannot evaluate"):
        D.scipy_discrete("hypergeom", 1e300, 5, 10)
    assert D.scipy_discrete("hypergeom", 20, 5, 10).pmf(1) == pytest.approx(
        stats.hypergeom(20, 5, 10).pmf(0)
    )


def test_a_value_that_is_not_a_number_is_an_error_at_its_step() -> None:
    """A law whose hazard is nan from step 3 on (as scipy gives far out for some laws):
    the nan never reaches the automaton, the error names the law and the step."""

    @dataclass(frozen=True, slots=True, eq=False)
    class NanAfterTwo(Uniform):
        def _hazard_pos(self, k: npt.NDArray[np.int64]) -> npt.NDArray[np.float64]:
            return np.where(k >= 3, math.nan, 0.5)

    law = NanAfterTwo("nan_after_two", 1, 10)
    assert law.hazard(2) == 0.5 and list(law.hazard([0, 1, 2])) == [0.0, 0.5, 0.5]
    with pytest.raises(DistributionError, match=r"^nan_after_two: the hazard at step 3 is not"):
        law.hazard([1, 2, 3, 4])


def test_a_long_label_is_quoted_as_an_excerpt() -> None:
    """A law of thousands of masses: the error line quotes its start and end only."""
    masses = [0.001] * 1001
    with pytest.raises(DistributionError) as info:
        D.pmf(masses)
    message = str(info.value)
    assert message.startswith("pmf(0.001, 0.001") and message.endswith("masses sum to 1.001 > 1")
    assert " ... " in message and len(message) < 150


def test_distribution_error_is_value_error_and_pickles() -> None:
    with pytest.raises(ValueError) as info:
        D.geometric(2)
    err = info.value
    assert isinstance(err, DistributionError)
    assert err.where == "geometric(2)" and err.reason == "p must be in (0, 1]"
    again = pickle.loads(pickle.dumps(err))
    assert str(again) == str(err)


# --------------------------------------------------------------------------- specs


SPEC_CASES = [
    (DistLiteral("geometric", (0.3,)), lambda k: geometric_pmf(0.3, k)),
    (DistLiteral("pmf", (0.1, 0.3, 0.6)), lambda k: table_pmf([0.1, 0.3, 0.6], k)),
    (DistLiteral("poisson", (2.5,)), lambda k: stats.poisson.pmf(k - 1, 2.5)),
    (DistLiteral("uniform", (1, 6)), lambda k: np.where(k <= 6, 1 / 6, 0.0)),
    (DistLiteral("exponential", (0.5,)), lambda k: geometric_pmf(1 - math.exp(-0.5), k)),
    (
        DistLiteral("weibull", (1.5, 3.0)),
        lambda k: (
            stats.weibull_min.cdf(k, 1.5, scale=3.0) - stats.weibull_min.cdf(k - 1, 1.5, scale=3.0)
        ),
    ),
    (
        DistLiteral("gamma", (2.0, 1.5)),
        lambda k: stats.gamma.cdf(k, 2.0, scale=1.5) - stats.gamma.cdf(k - 1, 2.0, scale=1.5),
    ),
    (DistLiteral("scipy", ("nbinom", 3, 0.5)), lambda k: stats.nbinom.pmf(k - 1, 3, 0.5)),
    (
        DistLiteral("scipy", ("expon", 0, 2)),
        lambda k: geometric_pmf(1 - math.exp(-0.5), k),
    ),
]


@pytest.mark.parametrize(("spec", "closed_pmf"), SPEC_CASES, ids=[str(c[0]) for c in SPEC_CASES])
def test_from_spec_every_family(
    spec: DistLiteral, closed_pmf: Callable[[np.ndarray], np.ndarray]
) -> None:
    d = D.from_spec(spec)
    assert d.label == str(spec)
    k = np.arange(1, 25)
    np.testing.assert_allclose(d.pmf(k), closed_pmf(k), rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize(
    ("spec", "pattern"),
    [
        (DistLiteral("binomial", (3,)), r"unknown distribution family 'binomial'"),
        (DistLiteral("geometric", (0.3, 0.4)), r"geometric takes 1 argument \(p\), got 2"),
        (DistLiteral("weibull", (1.5,)), r"weibull takes 2 arguments \(shape, scale\), got 1"),
        (DistLiteral("scipy", ()), r"scipy needs a distribution name"),
        (DistLiteral("scipy", (3, 0.5)), r"name must be a name"),
        (DistLiteral("scipy", ("nbinom", 3, 1.5)), r"scipy\(nbinom, 3, 1\.5\): invalid"),
        (DistLiteral("geometric", ("p",)), r"geometric\(p\): p must be a number"),
    ],
)
def test_from_spec_errors(spec: DistLiteral, pattern: str) -> None:
    with pytest.raises(DistributionError, match=pattern):
        D.from_spec(spec)


def test_from_spec_rejects_unbound_name() -> None:
    with pytest.raises(DistributionError, match="mu1: is a name"):
        D.from_spec(DistRef("mu1"))  # type: ignore[arg-type]


TABLE_CASES = [
    ({"geometric": 0.8}, "geometric(0.8)", lambda k: geometric_pmf(0.8, k)),
    ({"pmf": [0.1, 0.3, 0.6]}, "pmf(0.1, 0.3, 0.6)", lambda k: table_pmf([0.1, 0.3, 0.6], k)),
    ({"poisson": 2.5}, "poisson(2.5)", lambda k: stats.poisson.pmf(k - 1, 2.5)),
    ({"uniform": [1, 6]}, "uniform(1, 6)", lambda k: np.where(k <= 6, 1 / 6, 0.0)),
    (
        {"exponential": 0.5},
        "exponential(0.5)",
        lambda k: geometric_pmf(1 - math.exp(-0.5), k),
    ),
    (
        {"weibull": [1.5, 3.0]},
        "weibull(1.5, 3.0)",
        lambda k: np.exp(-(((k - 1) / 3.0) ** 1.5)) - np.exp(-((k / 3.0) ** 1.5)),
    ),
    (
        {"gamma": [2.0, 1.5]},
        "gamma(2.0, 1.5)",
        lambda k: stats.gamma.cdf(k, 2.0, scale=1.5) - stats.gamma.cdf(k - 1, 2.0, scale=1.5),
    ),
    (
        {"scipy": ["nbinom", 3, 0.5]},
        "scipy(nbinom, 3, 0.5)",
        lambda k: stats.nbinom.pmf(k - 1, 3, 0.5),
    ),
]


@pytest.mark.parametrize(
    ("table", "label", "closed_pmf"), TABLE_CASES, ids=[c[1] for c in TABLE_CASES]
)
def test_from_table_every_family(
    table: dict, label: str, closed_pmf: Callable[[np.ndarray], np.ndarray]
) -> None:
    d = D.from_table(table, "distributions.mu")
    assert d.label == label
    k = np.arange(1, 5)
    np.testing.assert_allclose(d.pmf(k), closed_pmf(k), rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ({"pmf": [0.5, 0.7]}, "distributions.mu2.pmf: masses sum to 1.2 > 1"),
        ({"geometric": 1.5}, "distributions.mu2.geometric: p must be in (0, 1]"),
        ({"geometric": [0.8]}, "distributions.mu2.geometric: must be a number, got [0.8]"),
        ({"pmf": 0.5}, "distributions.mu2.pmf: must be a list, got 0.5"),
        ({"uniform": [1]}, "distributions.mu2.uniform: uniform takes 2 arguments (a, b), got 1"),
        (
            {"scipy": ["nope", 1]},
            "distributions.mu2.scipy: unknown scipy.stats distribution 'nope'",
        ),
        ({"poisson": -2}, "distributions.mu2.poisson: lam must be a finite number > 0, got -2.0"),
        ({"binomial": 3}, "distributions.mu2: unknown distribution 'binomial'"),
        ({}, "distributions.mu2: must have exactly one distribution key"),
        ({"geometric": 0.5, "poisson": 1}, "got geometric, poisson"),
        (0.5, "distributions.mu2: must be an inline table"),
    ],
)
def test_from_table_errors_name_the_key_path(value: object, message: str) -> None:
    with pytest.raises(DistributionError) as info:
        D.from_table(value, "distributions.mu2")
    assert message in str(info.value)


# --------------------------------------------------------------------------- properties


@st.composite
def random_masses(draw: st.DrawFn) -> list[float]:
    raw = draw(
        st.lists(
            st.one_of(st.just(0.0), st.floats(1e-6, 1.0)),
            min_size=1,
            max_size=12,
        )
    )
    total = sum(raw)
    if total == 0:
        return raw
    scale = draw(st.sampled_from([1.0, 0.9, 0.5, 0.01])) / total
    return [x * scale for x in raw]


@given(random_masses())
def test_property_survival_times_hazard_is_pmf(masses: list[float]) -> None:
    d = D.pmf(masses)
    k = np.arange(1, len(masses) + 3)
    expected = np.array(masses + [0.0, 0.0])
    np.testing.assert_allclose(d.survival(k - 1) * d.hazard(k), expected, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(d.pmf(k), expected, rtol=1e-12, atol=1e-15)
    assert math.isclose(math.fsum(d.pmf(k)), 1 - d.never, abs_tol=1e-12)
    h = d.hazard(np.arange(1, len(masses) + 10))
    assert np.all((h >= 0) & (h <= 1))
    k0 = d.constant_hazard_from
    assert k0 is not None and np.all(h[k0 - 1 :] == h[k0 - 1])
    assert k0 == 1 or h[k0 - 2] != h[k0 - 1]


class _PmfAsHazard:
    """The paper's reading (the pmf used as the per-step probability), for a power check."""

    def __init__(self, d: FirstOccurrence) -> None:
        self.d = d

    def hazard(self, k: int) -> float:
        return self.d.pmf(k)


@pytest.mark.parametrize("make", [lambda: D.pmf([0.1, 0.3, 0.6]), lambda: D.poisson(2.5)])
def test_chi_square_rejects_pmf_used_as_hazard(make: Callable[[], FirstOccurrence]) -> None:
    d = make()
    wrong = _PmfAsHazard(d)
    samples = sample_through_hazards(wrong, SAMPLES, np.random.default_rng(3), HORIZON)  # type: ignore[arg-type]
    probs = d.pmf(np.arange(1, HORIZON + 1))
    assert chi_square_pvalue(samples, probs, 0.0) < 1e-6


def test_import_does_not_load_scipy_stats() -> None:
    """``import mitld_lp`` must not pay for ``scipy.stats`` (~0.6 s), nor the Poisson law
    (closed form); a family built on scipy imports it when first built."""
    import subprocess
    import sys

    code = (
        "import sys, mitld_lp; assert 'scipy.stats' not in sys.modules, 'at import'; "
        "mitld_lp.distributions.poisson(2.0); assert 'scipy.stats' not in sys.modules; "
        "mitld_lp.distributions.gamma(2.0, 1.0); assert 'scipy.stats' in sys.modules"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr


# --------------------------------------------------------------------------- budgets


def test_pmf_masses_beyond_float_range_are_a_distribution_error() -> None:
    with pytest.raises(DistributionError, match="masses sum to more than"):
        D.pmf([1e308, 1e308])


def test_uniform_beyond_the_last_step_is_refused_with_the_numbers() -> None:
    with pytest.raises(DistributionError, match=r"distributions\.mu\.uniform: b = 10{20}"):
        D.from_table({"uniform": [1, 1e20]}, "distributions.mu")


def test_pmf_table_budget_is_checked_before_the_table_is_made() -> None:
    with pytest.raises(DistributionError, match=f"{D.MAX_TABLE_STEPS + 1} masses"):
        D.pmf(np.zeros(D.MAX_TABLE_STEPS + 1))


def _peak_bytes(build: Callable[[], object]) -> int:
    import tracemalloc

    tracemalloc.start()
    try:
        build()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_huge_uniform_uses_its_closed_form() -> None:
    """uniform(1, 10**11): a table would be 745 GiB.  Hand values with n = b = 10**11:
    h(k) = 1/(b-k+1), S(k) = (b-k)/b, and S(T) <= 0.01 first at T = 0.99 b."""
    b = 10**11
    law = D.uniform(1, b)
    assert _peak_bytes(lambda: D.uniform(1, b).hazard(np.arange(1, 1000))) < 1_000_000
    assert law.hazard(1) == 1 / b
    assert law.hazard(b - 1) == 0.5
    assert law.hazard(b) == law.hazard(b + 7) == 1.0
    assert law.survival(b // 2) == 0.5
    assert law.pmf(12345) == 1 / b and law.pmf(b + 1) == 0.0
    assert law.cdf(b // 4) == 0.25
    assert law.constant_hazard_from == b
    assert law.truncation_point(0.01) == 99 * b // 100
    assert law.never == 0.0


@pytest.mark.parametrize(("a", "b"), [(1, 1), (1, 6), (12, 18), (3, 40)])
def test_closed_form_uniform_agrees_with_the_table(a: int, b: int) -> None:
    table = D.uniform(a, b)
    closed = Uniform(f"uniform({a}, {b})", a, b)
    k = np.arange(0, b + 5)
    for f in ("pmf", "cdf", "survival", "hazard"):
        assert np.allclose(getattr(closed, f)(k), getattr(table, f)(k), rtol=0, atol=1e-15), f
    assert closed.constant_hazard_from == table.constant_hazard_from
    for eps in (0.0, 0.05, 0.3, 0.9):
        assert closed.truncation_point(eps) == table.truncation_point(eps)


def test_long_finite_scipy_support_is_not_scanned_with_a_table() -> None:
    """zipfian's support ends at n: a constant-hazard scan would tabulate 2n steps
    (13 GB at n = 1e9); past MAX_HAZARD_SCAN the answer is None (use truncation)."""
    n = 4 * D.MAX_HAZARD_SCAN
    law = D.from_spec(DistLiteral("scipy", ("zipfian", 1.1, n)))
    assert _peak_bytes(lambda: law.constant_hazard_from) < 4_000_000
    assert law.constant_hazard_from is None


_ANY = st.one_of(
    st.integers(-(10**30), 10**30),
    st.integers(-(10**400), 10**400),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(["nbinom", "zipfian", "expon", "nonexistent", "_private", "rv_discrete"]),
)


@given(st.sampled_from(sorted(D.FAMILIES)), st.lists(_ANY, max_size=4))
def test_builders_raise_only_distribution_errors(family: str, args: list) -> None:
    try:
        law = D.from_spec(DistLiteral(family, tuple(args)))
    except DistributionError:
        return
    assert 0.0 <= law.never <= 1.0
