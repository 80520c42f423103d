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
    # a geometric(0.5) and a Poisson law beside a table leaving mass to never: past K
    # the lower ends are 0 and the upper ones at least max(0.5, h_P(K+1)): an inner
    # interval exists
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


# ------------------------------------------------------------------ the routes
# The three-state world: at "mid" the robot goes (to "d", labelled h, or to "sa", where
# it is stuck, each w.p. 1/2) or waits; the task: h or the bus b within N steps.

def three(spec: str, band=UNSETTLED):
    from mitld_lp import ExplicitGame, Model

    game = ExplicitGame(initial="mid", labels={"d": {"h"}}, transitions={
        "mid": {"go": {"sa": 0.5, "d": 0.5}, "wait": {"mid": 1.0}},
        "sa": {"stay": {"sa": 1.0}}, "d": {"stay": {"d": 1.0}}})
    return Model.from_game(game, spec, distributions={"mu": band})


def table_hazard(masses: list[float], k: int):
    """``h(k)`` of a table of masses in fractions: ``m_k / (1 - sum_{j<k} m_j)``, 0
    past its support (the mass left is never's)."""
    from fractions import Fraction

    m = [Fraction(str(x)) for x in masses]
    if k > len(m):
        return Fraction(0)
    return m[k - 1] / (1 - sum(m[: k - 1]))


def true_intervals(n: int):
    """The true band's ``[lo_k, hi_k]``, ``k = 1..n``: the least and greatest of the
    three laws' hazards (the Poisson one's by hand, as a fraction of its float)."""
    from fractions import Fraction

    out = []
    for k in range(1, n + 1):
        h = [table_hazard([0.3, 0.3], k), table_hazard([0.2, 0.3], k),
             Fraction(poisson_hazard(2.0, k))]
        out.append((min(h), max(h)))
    return out


def brute(n: int, worst: bool, go_at: int | None = None):
    """The max over the robot's policies of nature's min (``worst``) or max over its
    choice of hazard at every step within the true intervals, of P(b happens, and h or
    b within n steps) (``D[mu] b`` asks that b happens), by backward induction in
    fractions (nature's best choice is an end of the interval: the value is linear in
    the hazard); ``go_at``: the robot's policy fixed, waiting at "mid" until that step
    and going there.  The tail past step n by hand: once h is reached, b may still come at
    any later step; nature's least hazards are 0 from step 3 on (the tables' past their
    support), so the worst law's chance of it from step t is ``1 - prod_{t < k <= 2}
    (1 - lo_k)``; its greatest are the Poisson law's at least, which tend to 1, so
    ``prod (1 - hi_k) = 0``: the best law brings it surely."""
    from fractions import Fraction

    bands = true_intervals(max(n, 2))

    def later(t: int) -> Fraction:  # P(b at some step after t), b pending
        if not worst:
            return Fraction(1)
        stay = Fraction(1)
        for lo, _ in bands[t:2]:
            stay *= 1 - lo
        return 1 - stay

    def value(w: str, t: int) -> Fraction:
        if w == "d":
            return later(t)
        if t >= n:
            return Fraction(0)
        lo, hi = bands[t]  # the hazard of step t + 1
        moves = {"mid": {"go": {"sa": Fraction(1, 2), "d": Fraction(1, 2)},
                         "wait": {"mid": Fraction(1)}}, "sa": {"stay": {"sa": Fraction(1)}}}
        best = Fraction(0)
        allowed = moves[w] if w != "mid" or go_at is None else {
            a: moves[w][a] for a in (("go",) if t == go_at else ("wait",))}
        for succ in allowed.values():
            after = sum(p * value(v, t + 1) for v, p in succ.items())
            ends = [h + (1 - h) * after for h in (lo, hi)]
            best = max(best, min(ends) if worst else max(ends))
        return best

    return value("mid", 0)


@pytest.mark.parametrize("bands", ["worst", "best"])
def test_bracket_holds_the_brute_force_value_and_meets(bands):
    from mitld_lp import synthesize

    r = synthesize(three("D[mu] b & F[0,5] (h | b)"), bands=bands)
    exact = float(brute(5, bands == "worst"))
    assert r.route == "robust" and r.certified  # 5 < K: the tail does not matter
    assert r.lower == pytest.approx(exact, abs=1e-9) == r.upper
    tail = [c for c in r.checks if c.name.startswith("band's tail past step")]
    assert len(tail) == 1 and tail[0].passed


@pytest.mark.parametrize("bands", ["worst", "best"])
def test_deadline_past_the_step_bracketed_by_both_tails(bands):
    """The deadline past K: the outer tail [0, 1] lets nature bring the bus at once,
    the inner [0, h_P(K+1)] not; the bracket holds the brute-force value, and the two
    ends meet within epsilon (a law of the band that surely happens has survived past
    K with probability at most epsilon), so it is certified."""
    from mitld_lp import synthesize

    K = tail_step(UNSETTLED, 0.01)
    n = K + 4
    r = synthesize(three(f"D[mu] b & F[0,{n}] b"), bands=bands)
    exact = float(brute_bus(n, bands == "worst"))
    assert r.lower - 1e-9 <= exact <= r.upper + 1e-9
    assert r.certified and r.upper - r.lower <= 0.01
    tail = next(c for c in r.checks if c.name.startswith("band's tail past step"))
    assert tail.passed and f"past step {K}" in tail.detail


def brute_bus(n: int, worst: bool):
    """P(b within n steps) (it then happens too) at nature's least (``worst``) or
    greatest hazard at every step, in fractions: the robot has no say."""
    from fractions import Fraction

    stay = Fraction(1)
    for lo, hi in true_intervals(n):
        stay *= 1 - (lo if worst else hi)
    return 1 - stay


def test_storm_on_the_exported_chain_gives_lower(tmp_path):
    from test_band_chain import storm_worst

    from mitld_lp import synthesize
    from mitld_lp.running.band_chain import write_band_chain

    r = synthesize(three("D[mu] b & F[0,9] (h | b)"))
    path = write_band_chain(r, tmp_path / "c.drn")
    assert storm_worst(path) == pytest.approx(r.lower, abs=1e-9)
    assert r.lower == pytest.approx(float(brute(9, True)), abs=1e-9)


def test_a_constraint_met_under_every_law_and_the_cli(tmp_path):
    """P(F h) <= 0.25: the robot may go only with probability 1/2 (h is reached w.p.
    1/2 of going): the constrained optimum under every law; the worst case of the
    constraint for the returned policy is within its bound; the command line solves
    the problem it refused before (exit 0, not 2)."""
    from mitld_lp import synthesize

    r = synthesize(three("D[mu] b & F[0,5] (h | b)"), constraints=["P(F h) <= 0.25"])
    assert r.status.value == "optimal"
    (v,) = r.constraints
    assert v.certified <= 0.25 + 1e-9
    # never more than the unconstrained worst case, never less than waiting for the bus
    wait = 1 - float(np.prod([1 - float(lo) for lo, _ in true_intervals(5)]))
    assert wait - 1e-9 <= r.lower <= float(brute(5, True)) + 1e-9


@pytest.mark.parametrize("bands", ["worst", "best"])
def test_the_returned_controller_replayed_reaches_lower(bands):
    """The controller's first "go" at "mid" found by replaying it (the bus not come),
    that fixed policy's value by backward induction against nature's choice at every
    step within the true band is ``lower`` (the policy side's value is exact: 9 < K's
    tail does not matter, the deadline before it)."""
    from mitld_lp import Observation, synthesize

    r = synthesize(three("D[mu] b & F[0,6] (h | b)"), bands=bands)
    c = r.controller
    c.reset()
    go_at = None
    for t in range(7):
        if c.act(Observation("mid")) == "go":
            go_at = t
            break
    assert r.lower == pytest.approx(float(brute(6, bands == "worst", go_at)), abs=1e-9)


def test_storm_on_the_constrained_chain(tmp_path):
    """The randomised constrained controller's interval chain (the outer tail's, which
    holds every law of the band): Storm's worst case of "accept" is ``lower`` and its
    greatest probability of the constraint's formula is within the bound, so the
    constraint holds under every law of the true band."""
    from test_band_chain import storm_robust

    from mitld_lp import synthesize
    from mitld_lp.running.band_mixture_chain import write_mixture_chain

    r = synthesize(three("D[mu] b & F[0,5] (h | b)"), constraints=["P(F h) <= 0.25"])
    path = write_mixture_chain(r, tmp_path / "c.drn")
    assert storm_robust(path, 'Pmin=? [F "accept"]') == pytest.approx(r.lower, abs=1e-9)
    assert storm_robust(path, 'Pmax=? [F "c1"]', maximise=True) <= 0.25 + 1e-9


def test_the_exported_interval_mdp_is_the_policy_side_s(tmp_path):
    """``export --drn`` of such a model is no longer refused: the outer tail's interval
    MDP, the one ``lower`` is solved on (same states and choices), with the tail's
    interval [0, 1] past K (which reaches 0: Storm reads it but will not check it,
    docs/robust.md); with ``--upper`` the inner tail's, ``[0, h_P(K+1)]``."""
    from mitld_lp import synthesize
    from mitld_lp.routes.robust import interval_export
    from mitld_lp.solvers.robust_export import write_interval_drn

    m = three("D[mu] b & F[0,9] (h | b)")
    r = synthesize(m)
    imdp, target = interval_export(m)
    assert imdp.n_states == r.mdp.n_states and imdp.n_choices == r.mdp.n_choices
    write_interval_drn(imdp, target, tmp_path / "m.drn")  # written, not refused
    intervals = set(zip(imdp.band_lo.tolist(), imdp.band_hi.tolist(), strict=True))
    assert (0.0, 1.0) in intervals  # the outer tail past K
    upper, _ = interval_export(m, upper=True)
    h = poisson_hazard(2.0, tail_step(UNSETTLED, 0.01) + 1)
    inner = set(zip(upper.band_lo.tolist(), upper.band_hi.tolist(), strict=True))
    assert (0.0, 1.0) not in inner
    assert any(lo == 0.0 and hi == pytest.approx(h, rel=1e-9) for lo, hi in inner)


@pytest.mark.parametrize("bands", ["worst", "best"])
def test_a_minimum_bracketed(bands):
    """``objective = "min"``: the robot keeps away from h (reaching it satisfies the
    task once the bus comes), so the task holds iff the bus comes within 5 steps:
    against the worst law nature brings it at the greatest hazards (``upper``, the
    controller's worst case, the outer tail's), with the best at the least."""
    from mitld_lp import synthesize

    r = synthesize(three("D[mu] b & F[0,5] (h | b)"), objective="min", bands=bands)
    exact = float(brute_bus(5, bands == "best"))
    assert r.certified and r.lower == pytest.approx(exact, abs=1e-9) == r.upper
