"""Independent checks of the stochastic timed automaton (``mitld_lp.automata.sta``).

Every expected probability is worked out here from the distributions' masses (plain
arithmetic, ``math``/``scipy.stats`` for the Poisson), never read back from
``mitld_lp.distributions``; the hazard is
``h(k) = mu(k) / (1 - sum_{j<k} mu(j))`` and events never happen at step 0.

Truncation at ``T``: a run in which a truncated event has not happened by step ``T``
goes to ``TRUNCATED``, so the mass that reaches the truncation sink is exactly
``P(K > T)``, the reported ``epsilon_achieved`` (a first version cut ``P(K > T + 1)``
while reporting ``P(K > T)``; these tests pin the exact cut).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy import stats

from mitld_lp.automata.sta import TRUNCATED, make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.distributions import geometric, pmf, poisson, uniform
from mitld_lp.logic import parse

E = frozenset


# --------------------------------------------------------------------------- hand formulas


def masses_geometric(p: float, n: int) -> list[float]:
    return [(1 - p) ** (k - 1) * p for k in range(1, n + 1)]


def masses_poisson(lam: float, n: int) -> list[float]:
    # K = 1 + X, X ~ Poisson(lam): P(K = k) = e^-lam lam^(k-1) / (k-1)!
    return [math.exp(-lam + (k - 1) * math.log(lam) - math.lgamma(k)) for k in range(1, n + 1)]


def survival_from_masses(masses: list[float], k: int, never: float = 0.0) -> float:
    """P(K > k) as the never-mass plus the tail sum (no cancellation in 1 - cdf); the
    tables are long enough that the mass beyond them is below 1e-30."""
    return never + math.fsum(masses[k:])


def hazard_from_masses(masses: list[float], k: int, never: float = 0.0) -> float:
    """P(K = k | K > k-1) from the masses m_1, m_2, ... (0 beyond the table)."""
    alive = survival_from_masses(masses, k - 1, never)
    m = masses[k - 1] if k <= len(masses) else 0.0
    if alive <= 0.0:
        return 1.0  # unreachable condition; the package's convention
    return m / alive


TABLES = {
    # name: (distribution, masses long enough for every step used, never-mass, first
    #        step from which the hazard is constant: the event needs the clock up to
    #        that step minus 1)
    "geometric(0.8)": (lambda: geometric(0.8), masses_geometric(0.8, 300), 0.0, 1),
    "geometric(0.3)": (lambda: geometric(0.3), masses_geometric(0.3, 300), 0.0, 1),
    # h = 0.1, 0.3/0.9, 0.6/0.6 = 1: constant (1) from step 3
    "pmf(0.1,0.3,0.6)": (lambda: pmf([0.1, 0.3, 0.6]), [0.1, 0.3, 0.6], 0.0, 3),
    # never-mass 0.2: h = 0.1, 1/3, 0.4/0.6, then 0 forever: constant from step 4
    "pmf(0.1,0.3,0.4)": (lambda: pmf([0.1, 0.3, 0.4]), [0.1, 0.3, 0.4], 0.2, 4),
    # h = 0, 1/3, 1/2, 1: constant from step 4
    "uniform(2,4)": (lambda: uniform(2, 4), [0.0, 1 / 3, 1 / 3, 1 / 3], 0.0, 4),
}


def sta_for(events: dict, epsilon: float = 0.01, **kw):
    spec = " & ".join(f"F {a}" for a in sorted(events))
    return make_sta(to_dta(parse(spec)), events, epsilon, **kw)


# --------------------------------------------------------------------------- Example 1


def test_paper_example_1_geometric():
    """The run of Example 1, one step later (no event can happen at step 0, so the
    paper's sigma_0 is certain): nothing at step 1, bus 1 at step 2, nothing at step 3,
    A at step 4.  Geometric hazards are the constant p: mu1 = geometric(0.8),
    mu2 = geometric(0.3)."""
    dta = to_dta(parse("(D[mu1] b1 & F(b1 & F[0,3] A)) | (D[mu2] b2 & F(b2 & F[0,3] B))"))
    sta = make_sta(dta, {"b1": geometric(0.8), "b2": geometric(0.3)}, 0.01)
    p0 = (1 - 0.8) * (1 - 0.3)  # no bus at step 1
    p1 = 0.8 * (1 - 0.3)  # bus 1, not bus 2, at step 2
    p2 = 1 - 0.3  # bus 2 still not at step 3
    p3 = 1 - 0.3  # nor at step 4
    pending, clock = E({"b1", "b2"}), 0
    q = dta.step(dta.initial, E())  # step 0: the robot's label, no events
    got = []
    for events, robot in [(E(), E()), (E({"b1"}), E()), (E(), E()), (E(), E({"A"}))]:
        (out,) = [o for o in sta.outcomes(pending, clock) if o.occurred == events]
        got.append(out.probability)
        pending, clock = out.pending, out.clock
        q = dta.step(q, robot | events)
    assert got == pytest.approx([p0, p1, p2, p3], rel=1e-12, abs=0)
    assert pending == E({"b2"}) and clock == 0  # geometric: no clock is kept
    assert dta.is_accepting(q)
    run_probability = p0 * p1 * p2 * p3
    assert math.prod(got) == pytest.approx(run_probability, rel=1e-12)


def test_paper_example_1_with_a_non_memoryless_bus():
    """Same run with mu2 = pmf(0.1, 0.3, 0.4) (never-mass 0.2): the paper's formula
    would use 1 - mu2(k); the hazard fix uses 1 - h2(k)."""
    dta = to_dta(parse("(D[mu1] b1 & F(b1 & F[0,3] A)) | (D[mu2] b2 & F(b2 & F[0,3] B))"))
    m2 = [0.1, 0.3, 0.4]
    sta = make_sta(dta, {"b1": geometric(0.8), "b2": pmf(m2)}, 0.01)
    p0 = (1 - 0.8) * (1 - 0.1)
    p1 = 0.8 * (1 - 0.3 / 0.9)
    p2 = 1 - 0.4 / 0.6
    p3 = 1 - 0.0 / 0.2  # only the never-mass is left: bus 2 surely not at step 4
    pending, clock = E({"b1", "b2"}), 0
    got = []
    for events in [E(), E({"b1"}), E(), E()]:
        (out,) = [o for o in sta.outcomes(pending, clock) if o.occurred == events]
        got.append(out.probability)
        pending, clock = out.pending, out.clock
    assert got == pytest.approx([p0, p1, p2, p3], rel=1e-12, abs=1e-15)
    # the uncorrected reading differs from step 2 on
    paper = [(1 - 0.8) * (1 - m2[0]), 0.8 * (1 - m2[1]), 1 - m2[2]]
    assert got[1] != pytest.approx(paper[1]) and got[2] != pytest.approx(paper[2])
    # total over the chain of "bus 2 never came in 4 steps" = P(K2 > 4) = 0.2
    assert (1 - 0.1) * (1 - 0.3 / 0.9) * p2 * p3 == pytest.approx(0.2)


# --------------------------------------------------------------------------- single events


@pytest.mark.parametrize("name", sorted(TABLES))
def test_single_event_conditional_probabilities(name):
    make, masses, never, _ = TABLES[name]
    sta = sta_for({"a": make()})
    pending, clock = E({"a"}), 0
    for k in range(1, 12):
        outs = {o.occurred: o for o in sta.outcomes(pending, clock)}
        expect = hazard_from_masses(masses, k, never)
        got = outs[E({"a"})].probability if E({"a"}) in outs else 0.0
        assert got == pytest.approx(expect, abs=1e-12), k
        if E({"a"}) in outs:
            assert outs[E({"a"})].pending == E() and outs[E({"a"})].clock == 0
        if E() not in outs:
            assert expect == pytest.approx(1.0)
            break  # the event has surely happened
        pending, clock = E({"a"}), outs[E()].clock


def test_poisson_conditional_probabilities():
    lam = 2.5
    masses = masses_poisson(lam, 80)
    sta = sta_for({"a": poisson(lam)}, epsilon=1e-9)
    T = sta.truncation_points["a"]
    pending, clock = E({"a"}), 0
    for k in range(1, T + 1):
        outs = {o.occurred: o for o in sta.outcomes(pending, clock)}
        assert outs[E({"a"})].probability == pytest.approx(hazard_from_masses(masses, k), rel=1e-9)
        if k < T:
            assert outs[E()].clock == k  # the clock is the age while below T
        else:
            assert outs[E()].clock == TRUNCATED  # not happened by step T: cut
        clock = outs[E()].clock


# ------------------------------------------------------------------- reachable (pending, clock)


def _walk(sta, events: dict, steps: int):
    """All (pending, clock, true step) reachable in ``steps`` steps, each with the true
    step count t, so the hazards can be checked at the true age."""
    start = (E(events), 0, 0)
    frontier, seen = [start], {start}
    while frontier:
        nxt = []
        for pending, clock, t in frontier:
            yield pending, clock, t
            if t == steps:
                continue
            for o in sta.outcomes(pending, clock):
                if o.clock == TRUNCATED:
                    continue
                key = (o.pending, o.clock, t + 1)
                if key not in seen:
                    seen.add(key)
                    nxt.append(key)
        frontier = nxt


@pytest.mark.parametrize(
    "names",
    [
        ("geometric(0.3)", "pmf(0.1,0.3,0.6)"),
        ("pmf(0.1,0.3,0.4)", "uniform(2,4)"),
        ("geometric(0.8)", "pmf(0.1,0.3,0.4)", "uniform(2,4)"),
    ],
)
def test_outcomes_are_exact_products_and_clocks_are_capped(names):
    events = {f"e{i}": TABLES[n][0]() for i, n in enumerate(names)}
    masses = {f"e{i}": TABLES[n][1] for i, n in enumerate(names)}
    nevers = {f"e{i}": TABLES[n][2] for i, n in enumerate(names)}
    needs = {f"e{i}": TABLES[n][3] - 1 for i, n in enumerate(names)}
    sta = sta_for(events)
    assert sta.truncation_points == {}  # all have a constant hazard eventually: exact
    for pending, clock, t in _walk(sta, events, 10):
        # every pending event has age t (pending since step 0); the clock keeps only
        # what the pending events' hazards need
        assert clock == min(t, max((needs[a] for a in pending), default=0))
        outs = sta.outcomes(pending, clock)
        assert math.fsum(o.probability for o in outs) == pytest.approx(1.0, abs=1e-12)
        assert len({o.occurred for o in outs}) == len(outs)
        hz = {a: hazard_from_masses(masses[a], t + 1, nevers[a]) for a in pending}
        expect = {}
        for r in range(len(pending) + 1):
            for happened in itertools.combinations(sorted(pending), r):
                p = math.prod(hz[a] if a in happened else 1 - hz[a] for a in pending)
                if p > 1e-14:
                    expect[E(happened)] = p
        got = {o.occurred: o.probability for o in outs}
        assert set(got) == set(expect)
        for key, p in expect.items():
            assert got[key] == pytest.approx(p, abs=1e-12)
        for o in outs:
            assert o.pending == pending - o.occurred
            assert o.occurred <= pending
            assert 0 <= o.clock <= max((needs[a] for a in o.pending), default=0)


def test_independence_of_two_events():
    lam, m = 1.7, [0.2, 0.5, 0.3]
    sta = sta_for({"a": poisson(lam), "b": pmf(m)}, epsilon=1e-6)
    ma = masses_poisson(lam, 60)
    for clock in range(3):  # b surely happens by step 3
        t = clock + 1
        ha, hb = hazard_from_masses(ma, t), hazard_from_masses(m, t)
        got = {o.occurred: o.probability for o in sta.outcomes(E({"a", "b"}), clock)}
        assert got.get(E(), 0.0) == pytest.approx((1 - ha) * (1 - hb), abs=1e-12)
        assert got.get(E({"a"}), 0.0) == pytest.approx(ha * (1 - hb), abs=1e-12)
        assert got.get(E({"b"}), 0.0) == pytest.approx((1 - ha) * hb, abs=1e-12)
        assert got.get(E({"a", "b"}), 0.0) == pytest.approx(ha * hb, abs=1e-12)


# --------------------------------------------------------------------------- truncation


@pytest.mark.parametrize(("lam", "eps", "m"), [(2.5, 0.01, 1), (4.0, 1e-3, 1), (1.5, 0.02, 2)])
def test_poisson_truncation_point_and_sink(lam, eps, m):
    masses = masses_poisson(lam, 200)
    events = {"a": poisson(lam)}
    if m == 2:
        events["b"] = poisson(lam + 1)
    sta = sta_for(events, epsilon=eps)
    T = sta.truncation_points["a"]
    # smallest T with P(K > T) <= eps / m (the budget is shared by the m truncated events)
    assert survival_from_masses(masses, T) <= eps / m
    assert survival_from_masses(masses, T - 1) > eps / m
    assert survival_from_masses(masses, T) == pytest.approx(stats.poisson.sf(T - 1, lam))
    # walk a alone: the sink appears exactly from clock T - 1, for the outcomes where
    # a is still pending after step T
    only = sta_for({"a": poisson(lam)}, truncation={"a": T})
    mass_alive, trunc = 1.0, 0.0
    for clock in range(T):
        outs = only.outcomes(E({"a"}), clock)
        sink = [o for o in outs if o.clock == TRUNCATED]
        if clock < T - 1:
            assert not sink
        else:
            (o,) = sink
            assert o.pending == E({"a"}) and o.occurred == E()
            assert o.probability == pytest.approx(1 - hazard_from_masses(masses, T))
            trunc = mass_alive * o.probability
        stay = [o for o in outs if o.occurred == E() and o.clock != TRUNCATED]
        mass_alive *= stay[0].probability if stay else 0.0
    assert trunc == pytest.approx(survival_from_masses(masses, T), rel=1e-9)
    assert trunc <= eps
    assert only.epsilon_achieved == pytest.approx(trunc, rel=1e-9)


def test_truncation_with_two_events_only_when_the_truncated_one_is_pending():
    lam = 2.0
    ma = masses_poisson(lam, 60)
    sta = sta_for({"a": poisson(lam), "b": geometric(0.4)}, truncation={"a": 3})
    assert sta.truncation_points == {"a": 3}
    ha = hazard_from_masses(ma, 3)
    outs = {o.occurred: o for o in sta.outcomes(E({"a", "b"}), 2)}
    # a still pending after step 3 -> sink, whatever b does
    assert outs[E()].clock == TRUNCATED and outs[E({"b"})].clock == TRUNCATED
    assert outs[E()].probability == pytest.approx((1 - ha) * 0.6)
    assert outs[E({"b"})].probability == pytest.approx((1 - ha) * 0.4)
    assert outs[E({"a"})].clock != TRUNCATED and outs[E({"a"})].pending == E({"b"})
    assert outs[E({"a", "b"})].clock == 0 and outs[E({"a", "b"})].pending == E()
    # b alone (a has happened) is never truncated and needs no clock
    for clock in range(5):
        for o in sta.outcomes(E({"b"}), clock):
            assert o.clock == 0


def test_clock_reduction_off_truncates_every_event():
    sta = sta_for(
        {"a": geometric(0.5), "b": pmf([0.2] * 5)},
        clock_reduction=False,
        truncation={"a": 2, "b": 4},
    )
    assert sta.truncation_points == {"a": 2, "b": 4}
    outs = {o.occurred: o for o in sta.outcomes(E({"a", "b"}), 1)}
    assert outs[E({"a"})].clock == 2  # b still pending, its clock runs on
    assert outs[E({"b"})].clock == TRUNCATED


# --------------------------------------------------------------------------- simulation


def _sample(cdf: np.ndarray, rng: np.random.Generator, n: int) -> np.ndarray:
    """First-occurrence steps by inverse cdf over the table cdf[k-1] = P(K <= k); a draw
    above the table's total is 'never' (inf)."""
    u = rng.random(n)
    k = np.searchsorted(cdf, u, side="right") + 1.0
    k[k > len(cdf)] = np.inf
    return k


def test_simulation_matches_the_chain_of_outcomes():
    n, steps = 200_000, 6
    rng = np.random.default_rng(20210)
    tables = {
        "a": np.cumsum(masses_geometric(0.3, 100)),
        "b": np.cumsum([0.1, 0.3, 0.4]),  # never-mass 0.2
        "c": stats.poisson.cdf(np.arange(0, 100), 1.5),  # K = 1 + Poisson(1.5)
    }
    draws = {a: _sample(cdf, rng, n) for a, cdf in tables.items()}
    sta = sta_for({"a": geometric(0.3), "b": pmf([0.1, 0.3, 0.4]), "c": poisson(1.5)}, epsilon=1e-9)
    assert sta.truncation_points["c"] > steps
    dist = {(E("abc"), 0): 1.0}
    for t in range(1, steps + 1):
        per_set: dict[frozenset, float] = {}
        nxt: dict[tuple, float] = {}
        for (pending, clock), w in dist.items():
            for o in sta.outcomes(pending, clock):
                assert o.clock != TRUNCATED
                per_set[o.occurred] = per_set.get(o.occurred, 0.0) + w * o.probability
                key = (o.pending, o.clock)
                nxt[key] = nxt.get(key, 0.0) + w * o.probability
        dist = nxt
        assert math.fsum(per_set.values()) == pytest.approx(1.0)
        for r in range(4):
            for s in itertools.combinations("abc", r):
                mask = np.ones(n, dtype=bool)
                for a in "abc":
                    mask &= (draws[a] == t) if a in s else (draws[a] != t)
                emp = mask.mean()
                p = per_set.get(E(s), 0.0)
                se = math.sqrt(max(p * (1 - p), 1e-12) / n)
                assert abs(emp - p) <= 5 * se + 2e-5, (t, s, emp, p)


def test_advance_counts_caps_and_flags_the_truncation_point():
    # a: pmf on 1..3 (hazard constant, = 1, from step 3: cap 2); b truncated at T = 4.
    sta = sta_for({"a": pmf([0.2, 0.3, 0.5]), "b": poisson(1.0)}, truncation={"b": 4})
    assert sta.clocks["a"].cap == 2 and sta.clocks["b"].cap == 3
    both, a_only, b_only = E({"a", "b"}), E({"a"}), E({"b"})
    # t -> t + 1 capped at the largest cap of the pending events
    assert [sta.advance(a_only, t).clock for t in range(5)] == [1, 2, 2, 2, 2]
    assert [sta.advance(both, t).clock for t in range(3)] == [1, 2, 3]
    assert sta.advance(E(), 7).clock == 0
    # the step into t + 1 >= T_b crosses b's truncation point while b is pending
    assert [sta.advance(b_only, t).truncated for t in range(5)] == [False] * 3 + [True] * 2
    assert sta.advance(b_only, 3).clock == 3  # held at the last modelled value
    assert not any(sta.advance(a_only, t).truncated for t in range(6))
