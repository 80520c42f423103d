"""A camera on a band whose hazard may stay positive for ever while its laws' never
masses differ (issue 43): no truncation point serves such a band, which stopped the
sensed routes; now the candidates' information states are built at their point laws and
each controller's interval chain lets nature pick the hazard of every step past a step
``K`` in a constant interval holding every later one of the band (the outer band:
``lower`` sound), or for the best law within every later one (the inner band).

The world and task of tests/test_false_alarms_never_band.py: a robot waits at ``mid``
or goes to ``A``, reached the next step and left for good; the task asks it at ``A``
exactly one step after the bus ``b`` comes, at a step ``k <= 3`` (so it must go the
step the bus comes, which only the camera tells).  A bus at step 4 or later, or never,
fails the task: the enumeration below over steps 1..3 is exact, whatever the tail.

Two bands:

* ``SURE``: the middle law ``pmf [0.5, 0.5]`` surely happens, beside ``pmf [0.2, 0.3]``
  and ``pmf [0.4, 0.3]`` (never 0.5 and 0.3).  By hand: at step 1 the hazard is in
  ``[1/5, 1/2]``; at step 2 in ``[3/8, 1]`` (0.3 / 0.8, 0.3 / 0.6, and 0.5 / 0.5); from
  step 3 on in ``[0, 1]`` (the two tables' hazard is 0 past their support, the sure
  law's 1 by convention): constant, so the chain's outer band is the band.
* ``POISSON``: the middle law ``pmf [0.3, 0.3]`` beside ``pmf [0.2, 0.3]`` and a Poisson
  law (hazard positive for ever); its hazards from the law's own pmf by SciPy.

Independent routes: an enumeration in fractions over the bus's step (or none by step
3), nature's hazard at every step at either end of the true interval (nature sees
everything; a step's value is linear in its hazard, so the ends suffice) and the
camera's report, with the returned controller replayed; every deterministic
observation-based controller by brute force; Storm's robust check of the exported
interval chain."""

from __future__ import annotations

import importlib.util
import itertools
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path
from typing import Any

import pytest
from test_false_alarms_never_band import GAME, SPEC, replayed

from mitld_lp import ExplicitGame, Model, synthesize
from mitld_lp.distributions import pmf, poisson
from mitld_lp.distributions.band import band_of_laws
from mitld_lp.sensing import Sensor

DETECT = Fraction(7, 10)
LAST = 3  # the last step at which the bus serves the task

Hazards = Callable[[int], tuple[Fraction, Fraction]]


def sure_hazards(k: int) -> tuple[Fraction, Fraction]:
    """``SURE``'s interval at step ``k``, by hand (module docs)."""
    return {1: (Fraction(1, 5), Fraction(1, 2)),
            2: (Fraction(3, 8), Fraction(1))}.get(k, (Fraction(0), Fraction(1)))


def poisson_hazards(lam: float) -> Hazards:
    """``POISSON``'s interval at each step: the two tables' hazards by hand (``[1/5,
    3/10]`` at step 1, ``[3/8, 3/7]`` at step 2: 0.3 / 0.7 and 0.3 / 0.8; 0 after) and
    the Poisson law's from SciPy's pmf of the step (the law counts steps from 1: ``k -
    1`` is Poisson)."""
    from scipy.stats import poisson as sp_poisson

    tables = {1: (Fraction(1, 5), Fraction(3, 10)), 2: (Fraction(3, 8), Fraction(3, 7))}

    def at(k: int) -> tuple[Fraction, Fraction]:
        survived = Fraction(sp_poisson.sf(k - 2, lam)) if k >= 2 else Fraction(1)
        h = Fraction(sp_poisson.pmf(k - 1, lam)) / survived
        lo, hi = tables.get(k, (Fraction(0), Fraction(0)))
        return min(lo, h), max(hi, h)

    return at


def sure_band() -> Any:
    return band_of_laws("mu", pmf([0.5, 0.5]), [pmf([0.2, 0.3]), pmf([0.4, 0.3])])


def poisson_band(lam: float = 2.0) -> Any:
    return band_of_laws("mu", pmf([0.3, 0.3]), [pmf([0.2, 0.3]), poisson(lam)])


def model(band: Any, spec: str = SPEC, game: Any = GAME) -> Model:
    return Model.from_game(game, spec, distributions={"mu": band},
                           sensors={"b": Sensor(float(DETECT))})


def value(act: Any, hazards: Hazards, pick: Any, last: int = LAST,
          alarm: Fraction = Fraction(0)) -> Fraction:
    """The task's probability under the controller ``act`` (observation history ->
    action) with nature choosing each step's hazard at an end of ``hazards(step)`` by
    ``pick`` (``min``: the worst case; ``max``: the best), seeing everything.  The camera
    reports the bus with probability ``DETECT`` the step it comes (a later report comes
    after the task is decided), and with probability ``alarm`` at every step before."""

    def go(t: int, state: str, k: int | None, seen: tuple[Any, ...]) -> Fraction:
        if k is not None and t == k + 1:
            return Fraction(int("A" in GAME.propositions(state)))
        if k is None and t >= last:
            return Fraction(0)  # no bus by the last step: the task fails
        action = act(seen)
        if action is None:
            return Fraction(0)
        if k is not None:
            comes: list[list[tuple[int | None, Fraction]]] = [[(k, Fraction(1))]]
        else:
            comes = [[(t + 1, h), (None, 1 - h)] for h in hazards(t + 1)]
        values = []
        for branches in comes:
            v = Fraction(0)
            for k2, pe in branches:
                if pe == 0:
                    continue
                p = DETECT if k2 is not None else alarm  # k2 is t + 1 or None here
                for told, pr in (((True, p), (False, 1 - p)) if k is None
                                 else ((False, Fraction(1)),)):
                    if pr == 0:
                        continue
                    for nxt, pw in GAME.successors(state, action, frozenset()):
                        v += pe * pr * Fraction(str(pw)) * go(
                            t + 1, nxt, k2, (*seen, (nxt, told)))
            values.append(v)
        return pick(values)

    return go(0, GAME.initial, None, ((GAME.initial, False),))


def best_deterministic(hazards: Hazards, pick: Any) -> Fraction:
    """The best worst (``pick = min``) or best (``max``) case over every deterministic
    observation-based controller: a choice at each history that ends at ``mid`` with no
    earlier report (a report the robot did not act on has lost the task), by brute
    force over the 2^7 tables."""
    quiet = [(("mid", False),) * n for n in range(1, LAST + 2)]
    histories = quiet + [(*h[:-1], ("mid", True)) for h in quiet[1:]]
    best = None
    for choice in itertools.product(("go", "wait"), repeat=len(histories)):
        table = dict(zip(histories, choice, strict=True))
        v = value(lambda seen, table=table: table.get(seen, "back"), hazards, pick)
        best = v if best is None else max(best, v)
    assert best is not None
    return best


TOL = Fraction(1, 10**9)


@pytest.mark.parametrize("bands, pick", [("worst", min), ("best", max)])
def test_a_sure_middle_law_beside_laws_that_may_never_happen(bands: str, pick: Any) -> None:
    """``SURE``: the band is constant past step 2, so the chain's tail is the band and
    ``lower`` is the returned controller's worst (best) case by the enumeration; the
    best deterministic controller's lies in the bracket; nothing is truncated."""
    r = synthesize(model(sure_band()), bands=bands)
    assert r.route == "sensed" and r.bands and r.controller is not None
    ours = value(replayed(r.controller), sure_hazards, pick)
    assert abs(ours - Fraction(r.lower)) <= TOL
    best = best_deterministic(sure_hazards, pick)
    assert Fraction(r.lower) <= best + TOL and best <= Fraction(r.upper) + TOL
    assert r.width["truncation"] == 0.0


def test_false_alarms_beside_a_sure_middle_law() -> None:
    """``SURE`` with a camera that also gives false alarms (0.2 a step): the middle law
    surely happens, so the candidate there reads every report; those at the ends may
    never happen, built blind, their upper bounds not used.  ``lower`` is the returned
    controller's worst case by the enumeration with every step's report drawn; ``upper``
    at most the fully observed optimum by hand (a robot seeing the bus goes the step it
    comes: ``1 - 4/5 * 5/8 = 1/2``, nature bringing it at step 3 not at all)."""
    alarm = Fraction(1, 5)
    m = Model.from_game(GAME, SPEC, distributions={"mu": sure_band()},
                        sensors={"b": Sensor(float(DETECT), false_alarm=float(alarm))})
    r = synthesize(m)
    assert r.route == "sensed" and r.controller is not None
    ours = value(replayed(r.controller), sure_hazards, min, alarm=alarm)
    assert abs(ours - Fraction(r.lower)) <= TOL
    assert Fraction(r.upper) <= Fraction(1, 2) + TOL
    assert all(c.passed for c in r.checks if c.name != "worst case over the band")


@pytest.mark.parametrize("bands, pick", [("worst", min), ("best", max)])
def test_a_poisson_law_beside_tables_that_may_never_happen(bands: str, pick: Any) -> None:
    """``POISSON``: the chain's step ``K`` is past step 3 at the default epsilon (the
    Poisson law's own truncation point), so ``lower`` is the returned controller's worst
    (best) case by the enumeration; the best deterministic controller's lies in the
    bracket."""
    r = synthesize(model(poisson_band()), bands=bands)
    assert r.route == "sensed" and r.bands and r.controller is not None
    ours = value(replayed(r.controller), poisson_hazards(2.0), pick)
    assert abs(ours - Fraction(r.lower)) <= TOL
    best = best_deterministic(poisson_hazards(2.0), pick)
    assert Fraction(r.lower) <= best + TOL and best <= Fraction(r.upper) + TOL


@pytest.mark.parametrize("bands, pick", [("worst", min), ("best", max)])
def test_a_short_tail_is_a_sound_lower_bound(bands: str, pick: Any) -> None:
    """``POISSON`` with a Poisson law of mean 0.5 and epsilon 0.1: no truncation serves
    the band (its upper survival stays at 0.5, above the middle law's never mass 0.4 and
    half the budget), and the Poisson law has survived step 2 with probability 0.09, so
    the chain's step ``K`` is 2: from step 3 on nature picks in ``[0, 1]`` for the worst
    law (the outer band: more than the true ``[0, h(3)]``, ``h(3)`` about 0.84), in the
    inner ``[0, h(3)]`` for the best.  Either way ``lower`` is at most the returned
    controller's true worst (best) case, and the bracket holds the best deterministic
    controller's; for the worst law ``lower`` is the enumeration's with nature free to
    bring the bus surely at step 3, for the best the true best case (the inner band is
    the band at step 3)."""
    hazards = poisson_hazards(0.5)
    r = synthesize(model(poisson_band(0.5)), bands=bands, epsilon=0.1)
    assert r.route == "sensed" and r.controller is not None
    clock = r.sta.clocks["b"]
    assert clock.distribution.step == 2 and (clock.distribution.lo, clock.distribution.hi) \
        == (0.0, 1.0)
    ours = value(replayed(r.controller), hazards, pick)
    assert Fraction(r.lower) <= ours + TOL
    best = best_deterministic(hazards, pick)
    assert Fraction(r.lower) <= best + TOL and best <= Fraction(r.upper) + TOL
    if pick is min:  # nature bringing the bus surely at step 3 is not a law of the band
        outer = value(replayed(r.controller),
                      lambda k: (Fraction(0), Fraction(1)) if k >= 3 else hazards(k), min)
        assert abs(outer - Fraction(r.lower)) <= TOL
    else:
        assert abs(ours - Fraction(r.lower)) <= TOL


#: a robot that must reach ``A`` before the bus comes (the bus at the step it arrives
#: is fine): each ``go`` arrives with probability 1/2
RACE = ExplicitGame(initial="mid", labels={"sa": {"A"}}, transitions={
    "mid": {"go": {"sa": 0.5, "mid": 0.5}, "wait": {"mid": 1.0}},
    "sa": {"stay": {"sa": 1.0}}})
RACE_SPEC = "(D[mu] b & false) | (!b U[0,5] A)"  # b a law, not asked for


def race(act: Any, hazards: Hazards, pick: Any) -> Fraction:
    """The race's probability under ``act`` with nature choosing each step's hazard at an
    end of ``hazards(step)`` by ``pick``: reaching ``A`` at step ``j <= 5`` with no bus at
    a step before ``j``.  While the task is undecided the bus has not come, so the camera
    has nothing to report."""

    def go(t: int, state: str, seen: tuple[Any, ...]) -> Fraction:
        if state == "sa":
            return Fraction(1)
        if t >= 5:
            return Fraction(0)
        action = act(seen)
        values = []
        for h in hazards(t + 1):
            v = Fraction(0)
            for nxt, pw in RACE.successors(state, action, frozenset()):
                # the bus at step t + 1 ends the race, won if the robot arrives then
                won = Fraction(int(nxt == "sa"))
                v += Fraction(str(pw)) * (h * won + (1 - h) * go(t + 1, nxt,
                                                                 (*seen, (nxt, False))))
            values.append(v)
        return pick(values)

    return go(0, "mid", (("mid", False),))


def test_the_outer_tail_is_nature_s_more_for_the_worst_law() -> None:
    """The race under ``POISSON`` with a Poisson law of mean 0.5 at epsilon 0.1 (the
    chain's step ``K`` 2, as above): nature wants the bus early, so its worst is the
    band's highest hazard at every step; past step 2 the chain lets it bring the bus
    surely (the outer ``[0, 1]``), more than any law of the band (``h(k) < 1``).
    ``lower`` is the enumeration's with that tail and below the controller's true worst
    case (which the controller keeping ``go`` has: it is also the best)."""
    hazards = poisson_hazards(0.5)
    r = synthesize(model(poisson_band(0.5), RACE_SPEC, RACE), epsilon=0.1)
    assert r.route == "sensed" and r.controller is not None
    true = race(replayed(r.controller), hazards, min)
    outer = race(replayed(r.controller),
                 lambda k: (Fraction(0), Fraction(1)) if k >= 3 else hazards(k), min)
    assert abs(outer - Fraction(r.lower)) <= TOL
    assert Fraction(r.lower) < true - Fraction(1, 10**4)
    always_go = race(lambda seen: "go", hazards, min)
    assert Fraction(r.lower) <= always_go <= Fraction(r.upper) + TOL


def test_the_inner_tail_is_nature_s_less_for_the_best_law() -> None:
    """The bus task with its window widened to step 5 under the band of the test above,
    its best law: nature wants the bus to come while the robot waits, and past step 2 the
    chain lets it pick at most ``h(3)`` (the inner ``[0, h(3)]``, below the Poisson law's
    ``h(4), h(5)``).  ``lower`` is the enumeration's with that tail, at most the
    controller's true best case."""
    hazards = poisson_hazards(0.5)
    spec = "D[mu] b & F[0,5] (b & F[1,1] A)"
    r = synthesize(model(poisson_band(0.5), spec), bands="best", epsilon=0.1)
    assert r.route == "sensed" and r.controller is not None
    true = value(replayed(r.controller), hazards, max, last=5)
    inner = value(replayed(r.controller),
                  lambda k: (Fraction(0), hazards(3)[1]) if k >= 3 else hazards(k), max,
                  last=5)
    assert abs(inner - Fraction(r.lower)) <= TOL
    assert Fraction(r.lower) <= true + TOL


def test_the_chain_s_tail_for_each_reading() -> None:
    """The clocks the controller's chain keeps (``tail_sta``) for ``POISSON`` with a
    Poisson law of mean 0.5 at epsilon 0.1: the band's own intervals at steps 1 and 2
    (by hand and SciPy), then for the worst law ``[0, 1]`` (no law of the band has a
    hazard below the tables' 0 or above the Poisson law's, which tends to 1), for the
    best ``[0, h(3)]`` (the Poisson law's hazard increases: ``h(3)`` is its least after
    step 2); nothing truncated."""
    from mitld_lp.running.sensed_band_chain import tail_sta

    hazards = poisson_hazards(0.5)
    r = synthesize(model(poisson_band(0.5)), epsilon=0.1)
    for reading, past in (("worst", (0.0, 1.0)), ("best", (0.0, float(hazards(3)[1])))):
        clock = tail_sta(r.sta, reading).clocks["b"]
        assert clock.truncation is None and not clock.keeps_never
        for t in range(6):
            want = tuple(map(float, hazards(t + 1))) if t < 2 else past
            assert clock.band(t) == pytest.approx(want, abs=1e-12)


@pytest.mark.skipif(importlib.util.find_spec("stormpy") is None, reason="needs stormpy")
@pytest.mark.parametrize("band", [sure_band, poisson_band])
def test_storm_on_the_exported_interval_chain_gives_lower(band: Any, tmp_path: Path) -> None:
    """Storm's robust check (nature minimising) of the controller's interval chain, its
    tail included, gives ``lower``."""
    from test_band_chain import storm_worst

    from mitld_lp.running.sensed_band_chain import write_sensed_band_chain

    r = synthesize(model(band()))
    path = write_sensed_band_chain(r, tmp_path / "c.drn")
    assert abs(storm_worst(path) - r.lower) <= 1e-9


@pytest.mark.skipif(importlib.util.find_spec("stormpy") is None, reason="needs stormpy")
def test_a_constraint_met_under_every_law(tmp_path: Path) -> None:
    """Route sensed-constrained: a randomised controller whose ``P(F A) <= 0.3`` holds
    under every law of the band, by Storm's ``Pmax [F "c1"]`` on its exported interval
    chain (nature maximising over a tail holding every later interval); Storm's
    ``Pmin [F "accept"]`` there is ``lower``, and the bound binds."""
    from test_band_chain import storm_robust

    from mitld_lp.running.sensed_band_chain import write_sensed_band_chain

    r = synthesize(model(poisson_band()), constraints=["P(F A) <= 0.3"])
    assert r.route == "sensed-constrained" and r.status == "optimal"
    assert all(v.holds for v in r.constraints)
    path = write_sensed_band_chain(r, tmp_path / "c.drn")
    assert abs(storm_robust(path, 'Pmin=? [F "accept"]') - r.lower) <= 1e-9
    assert storm_robust(path, 'Pmax=? [F "c1"]', maximise=True) <= 0.3 + 1e-9
    assert r.lower <= r.upper < synthesize(model(poisson_band())).lower - 1e-3
