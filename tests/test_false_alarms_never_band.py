"""A sensor with false alarms and a law known only within a band whose laws may never
happen (issue 43): bracketed on the sensed route (mitld_lp/routes/sensed_never.py,
``solve_never_band``) between the band's problem with the sensor blind, its controller
dropping the reports, and the band's problem with a sensor without false alarms at
least as informative.

Independent routes: the two ends solved separately, each as its own model (a blind
sensor; the informed sensor ``d' = (d - f) / (1 - f)``); an enumeration in exact
arithmetic of every hidden scenario (the step the bus comes or that it never does, the
report or silence of every step, the world's branches) and of nature's choice at every
step between the band's two hazards at that step, nature seeing everything, with a
controller asked for its action after each observation history (the returned one
replayed, and every deterministic controller of the horizon by brute force); and Storm's
robust check of the exported interval chain.

The world: a robot waits at ``mid`` or goes to ``A`` (reached the next step), from where
it is gone for good; the task asks it at ``A`` exactly one step after the bus ``b``
comes, so it must go the step the bus comes, which only the reports tell.  The band: the
laws between ``pmf [0.2, 0.4]`` and ``pmf [0.4, 0.2]`` (middle law ``pmf [0.3, 0.3]``),
each leaving the bus a chance 0.4 of never coming: at step 1 its hazard is in ``[1/5,
2/5]``, at step 2 in ``[1/3, 1/2]``, after step 2 it is 0.  The task is decided by step
3, so "never" and "after the horizon" are the same to it: the enumeration over steps
0..3 is exact."""

from __future__ import annotations

import importlib.util
import itertools
from fractions import Fraction
from pathlib import Path
from typing import Any

import pytest

from mitld_lp import ExplicitGame, Model, synthesize
from mitld_lp.distributions import pmf
from mitld_lp.distributions.band import band_of_laws
from mitld_lp.sensing import Sensor

GAME = ExplicitGame(initial="mid", labels={"sa": {"A"}}, transitions={
    "mid": {"go": {"sa": 1.0}, "wait": {"mid": 1.0}},
    "sa": {"back": {"gone": 1.0}}, "gone": {"back": {"gone": 1.0}}})
SPEC = "D[mu] b & F[0,3] (b & F[1,1] A)"  # b at a step k <= 3, A at step k + 1
DETECT, ALARM = Fraction(7, 10), Fraction(1, 5)
#: nature's two hazards at steps 1 and 2 (by hand from the two pmfs: 0.2 and 0.4; then
#: 0.4 / 0.8 and 0.2 / 0.6); none after
HAZARDS = {1: (Fraction(1, 5), Fraction(2, 5)), 2: (Fraction(1, 3), Fraction(1, 2))}
HORIZON = 3


def _band() -> Any:
    return band_of_laws("mu", pmf([0.3, 0.3]), [pmf([0.2, 0.4]), pmf([0.4, 0.2])])


def _model(detect: float, false_alarm: float = 0.0) -> Model:
    return Model.from_game(GAME, SPEC, distributions={"mu": _band()},
                           sensors={"b": Sensor(detect, false_alarm=false_alarm)})


POSED = (float(DETECT), float(ALARM))
INFORMED = float((DETECT - ALARM) / (1 - ALARM))  # 5/8


def value(act: Any, pick: Any) -> Fraction:
    """The task's probability for the controller ``act`` (observation history -> action)
    with nature choosing each step's hazard among the band's two by ``pick`` (``min``:
    its worst case; ``max``: its best), seeing everything; every step's report drawn,
    ``DETECT`` from the step the bus comes, ``ALARM`` before (and for ever if it never
    does)."""

    def go(t: int, state: str, k: int | None, seen: tuple[Any, ...]) -> Fraction:
        if k is not None and t == k + 1 and "A" in GAME.propositions(state):
            return Fraction(1)
        if t >= HORIZON or (k is not None and t >= k + 1):
            return Fraction(0)  # no bus by step 2 (so none ever), or its window missed
        action = act(seen)
        if action is None:  # the controller's task is lost (none of its moves matter)
            return Fraction(0)
        choices = HAZARDS.get(t + 1, (Fraction(0),)) if k is None else (None,)
        values = []
        for h in choices:
            v = Fraction(0)
            comes = [(k, Fraction(1))] if k is not None else [(t + 1, h), (None, 1 - h)]
            for k2, pe in comes:
                if pe == 0:
                    continue
                p = DETECT if k2 is not None else ALARM
                for told, pr in ((True, p), (False, 1 - p)):
                    for nxt, pw in GAME.successors(state, action, frozenset()):
                        v += pe * pr * Fraction(str(pw)) * go(
                            t + 1, nxt, k2, (*seen, (nxt, told)))
            values.append(v)
        return pick(values)

    return go(0, GAME.initial, None, ((GAME.initial, False),))


def replayed(controller: Any) -> Any:
    """The returned controller as a function of the observation history."""
    from mitld_lp.controllers.observation import Observation

    def act(seen: tuple[Any, ...]) -> str:
        controller.reset()
        action = controller.act(Observation(seen[0][0]))
        for state, told in seen[1:]:
            action = controller.act(Observation(state, reports=frozenset({"b"} if told
                                                                          else ())))
        return action

    return act


def best_deterministic(pick: Any) -> Fraction:
    """The best worst (``pick = min``) or best (``max``) case over every deterministic
    controller of the horizon: a choice of "go" or "wait" at each history ending in
    ``mid`` (the only state with a choice), by brute force."""
    mids = [((GAME.initial, False),)]  # the histories at mid after 0, 1, 2 steps
    for _ in range(HORIZON - 1):
        mids += [(*h, ("mid", told)) for h in mids if len(h) == len(mids[-1])
                 for told in (False, True)]
    best = None
    for choice in itertools.product(("go", "wait"), repeat=len(mids)):
        table = dict(zip(mids, choice, strict=True))
        v = value(lambda seen, table=table: table.get(seen, "back"), pick)
        best = v if best is None else max(best, v)
    assert best is not None
    return best


@pytest.mark.parametrize("bands, pick", [("worst", min), ("best", max)])
def test_bracket_ends_are_the_blind_and_informed_band_solves(bands: str, pick: Any) -> None:
    """``lower`` is the blind band solve's, done separately, and the returned controller's
    worst (best) case by the enumeration; ``upper`` the informed band solve's, done
    separately; the best deterministic controller reading every report lies inside."""
    r = synthesize(_model(*POSED), bands=bands)
    assert r.route == "sensed" and r.bands
    blind = synthesize(_model(0.0), bands=bands)
    informed = synthesize(_model(INFORMED), bands=bands)
    # the same controller's worst case, read on chains with and without the reports
    # drawn, and the same informed problem (each to its rounding)
    assert abs(r.lower - blind.lower) <= 1e-12 and abs(r.upper - informed.upper) <= 1e-12
    ours = value(replayed(r.controller), pick)
    assert abs(ours - Fraction(r.lower)) <= Fraction(1, 10**9)
    exact = best_deterministic(pick)
    assert Fraction(r.lower) <= exact <= Fraction(r.upper)
    check = next(c for c in r.checks if c.name == "false alarms, law that may never happen")
    # the reports are worth reading (the brute force beats the blind controller: 53/150
    # against 1/5 for the worst case, 13/25 against 2/5 for the best), so the ends do
    # not meet and nothing is certified
    assert exact > ours and not check.passed and not r.certified
    assert "not read" in check.detail and r.width["information"] > 1e-3
    assert exact == (Fraction(53, 150) if pick is min else Fraction(13, 25))


def test_a_minimum_whose_ends_meet_is_certified() -> None:
    """``objective = "min"``: waiting for ever makes the task fail surely, whatever the
    reports say; both ends find it (0), and the answer is certified, its controller's
    worst case (nature making the task likely) 0 by the enumeration."""
    r = synthesize(_model(*POSED), objective="min")
    assert r.route == "sensed" and r.bands
    assert value(replayed(r.controller), max) == 0
    assert r.lower <= 1e-12 and r.upper <= 1e-9 and r.certified


@pytest.mark.skipif(importlib.util.find_spec("stormpy") is None, reason="needs stormpy")
def test_storm_on_the_exported_interval_chain_gives_lower(tmp_path: Path) -> None:
    """The blind controller's interval chain, every step's report drawn from the posed
    sensor and dropped: Storm's robust check (nature minimising) gives ``lower``."""
    from test_band_chain import storm_worst

    from mitld_lp.running.sensed_band_chain import write_sensed_band_chain

    r = synthesize(_model(*POSED))
    path = write_sensed_band_chain(r, tmp_path / "c.drn")
    assert abs(storm_worst(path) - r.lower) <= 1e-9


@pytest.mark.parametrize("extra", [{"constraints": ["P(F A) <= 0.3"]},
                                   {"then": "min-steps"}])
def test_constraints_and_then_under_the_worst_law(extra: dict[str, Any]) -> None:
    """Route sensed-constrained with the band: ``lower`` the blind band constrained solve's
    (a randomised controller ignoring the reports), ``upper`` the informed one's, each
    done separately; the constraint holds under every law, ``then`` gives the returned
    controller's worst expected steps, finite."""
    r = synthesize(_model(*POSED), **extra)
    assert r.route == "sensed-constrained" and r.bands and r.status == "optimal"
    blind = synthesize(_model(0.0), **extra)
    informed = synthesize(_model(INFORMED), **extra)
    assert abs(r.lower - blind.lower) <= 1e-9 and abs(r.upper - informed.upper) <= 1e-12
    assert r.lower < r.upper and not r.certified
    assert all(v.holds for v in r.constraints)
    if "then" in extra:
        assert abs(r.secondary - blind.secondary) <= 1e-9 and r.secondary < float("inf")


@pytest.mark.skipif(importlib.util.find_spec("stormpy") is None, reason="needs stormpy")
def test_storm_on_the_constrained_chain(tmp_path: Path) -> None:
    """The blind randomised controller's interval chain, every step's report drawn and
    dropped: Storm's ``Pmin [F "accept"]`` is ``lower``, its ``Pmax [F "c1"]`` (nature
    maximising) within the bound, and the bound binds: without it the blind band
    controller does better."""
    from test_band_chain import storm_robust

    from mitld_lp.running.sensed_band_chain import write_sensed_band_chain

    r = synthesize(_model(*POSED), constraints=["P(F A) <= 0.3"])
    path = write_sensed_band_chain(r, tmp_path / "c.drn")
    assert abs(storm_robust(path, 'Pmin=? [F "accept"]') - r.lower) <= 1e-9
    assert storm_robust(path, 'Pmax=? [F "c1"]', maximise=True) <= 0.3 + 1e-9
    assert r.lower < synthesize(_model(*POSED)).lower - 1e-3


def test_a_camera_without_false_alarms_on_such_a_band(monkeypatch: Any) -> None:
    """The blind end's route with a camera that gives no false alarms, on this band:
    solved (the fully observed robust bound, which the robust route cannot give for a
    band that may never happen, left out), its ``lower`` the controller's worst case by
    the enumeration with no false alarm (a report at each step from the bus on with
    ``DETECT``), the best deterministic controller within the bracket."""
    import test_false_alarms_never_band as here

    monkeypatch.setattr(here, "ALARM", Fraction(0))
    r = synthesize(_model(float(DETECT)))
    assert r.route == "sensed" and r.bands
    ours = value(replayed(r.controller), min)
    assert abs(ours - Fraction(r.lower)) <= Fraction(1, 10**9)
    assert Fraction(r.lower) <= best_deterministic(min) <= Fraction(r.upper)
