"""A sensor with false alarms and a band whose laws may never happen (issue 43), the two
cells that were refused or stopped: the band read for its best law (``bands = "best"``)
with constraints, ``then`` or the trade-off curve (route sensed-constrained,
mitld_lp/routes/sensed_optimistic_constrained.py, bracketed by
mitld_lp/routes/sensed_never.py), and a sensor that detects surely (``detect = 1``)
with false alarms, whose informed end reports surely and at once and stays on the
sensed routes (``KeptSensor``), which truncate such a band.

Independent routes: the two ends solved separately (the sensor blind; the informed
sensor ``d' = (d - f) / (1 - f)``); an enumeration in exact arithmetic, written here, of
every hidden scenario (the step the bus comes or that it never does, the report or
silence of every step, the world's moves) at the law nature chose, held fixed as the
optimistic constrained answer holds it, with the returned randomised controller's
mixed decision after each observation replayed; Storm, in exact arithmetic, on the
plain chain ``export --chain`` writes; and for ``detect = 1`` the fully observed band
optimum by brute force over every deterministic controller (written apart from the
robust route, which solves this band too since a band of mass tables is constant after
its laws' last support).

The world and band are tests/test_false_alarms_never_band.py's: the bus ``b`` comes at
step 1 or 2 or never (0.4 at every law of the band), the robot must be at ``A`` the
step after it comes; the constraint ``P(F A) <= 0.3`` bounds going to ``A`` at all."""

from __future__ import annotations

import dataclasses
import importlib.util
from fractions import Fraction
from pathlib import Path
from types import MappingProxyType
from typing import Any

import pytest
import test_false_alarms_never_band as band_case
from test_false_alarms_never_band import GAME, INFORMED, POSED, _model, best_deterministic

from mitld_lp import synthesize
from mitld_lp.routes.sensed_never import KeptSensor

CONSTRAINT = "P(F A) <= 0.3"
#: each law the optimistic constrained route tries, as ``(P(K = 1), P(K = 2))`` by hand
#: from the band's laws: its middle law and its two ends (tests/test_false_alarms_never_
#: band.py), the rest never
LAWS = {"middle law": (Fraction(3, 10), Fraction(3, 10)),
        "low ends": (Fraction(1, 5), Fraction(2, 5)),
        "high ends": (Fraction(2, 5), Fraction(1, 5))}
#: steps enumerated: the bus is decided by step 2; a run still open after this many
#: steps (the robot waiting at ``mid``) is counted both ways
DEPTH = 40


def at_law(plan: Any, law: tuple[Fraction, Fraction]) -> tuple[Fraction, Fraction, Fraction]:
    """The randomised ``plan``'s task probability, its ``P(F A)`` and the mass of runs
    still open after :data:`DEPTH` steps, at the constant law ``law`` (nature's choice
    held fixed), every step's report drawn (:data:`band_case.DETECT` from the step the
    bus comes, :data:`band_case.ALARM` before it and for ever if it never does) and
    handed to the controller, in exact arithmetic."""
    p1, p2 = law
    hazard = {1: p1, 2: p2 / (1 - p1)}  # after step 2 none (the law's rest is never)
    detect, alarm = band_case.DETECT, band_case.ALARM
    memo: dict[tuple[Any, ...], tuple[Fraction, Fraction, Fraction]] = {}

    def node(t: int, w: str, k: int | None, memory: Any) -> tuple[Fraction, Fraction,
                                                                   Fraction]:
        if "A" in GAME.propositions(w):  # at A: F A holds; the task if the bus came a
            return (Fraction(int(k is not None and t == k + 1)), Fraction(1), Fraction(0))
        if w == "gone":  # left without passing A: neither
            return Fraction(0), Fraction(0), Fraction(0)
        if t >= DEPTH:
            return Fraction(0), Fraction(0), Fraction(1)
        key = (t, w, k, memory)
        if key in memo:
            return memo[key]
        d = plan.decision(w, memory)
        # a stay: the robot waits at mid for ever (the only moves inside), so neither the
        # task nor F A; its mass is what the weights of the moves leave
        assert not d.stay or tuple(d.inside) == ("wait",)
        if d.lost or (d.weights is None and not d.actions):
            drawn = [(plan.fallback(w), Fraction(1))]
        elif d.weights is None:
            drawn = [(d.actions[0], Fraction(1))]
        else:
            weights = [Fraction(float(x)) for x in d.weights]
            total = sum(weights) + Fraction(float(d.stay))
            drawn = [(a, x / total) for a, x in zip(d.actions, weights, strict=True)
                     if x > 0]
        out = [Fraction(0)] * 3
        for action, p_action in drawn:
            h = hazard.get(t + 1, Fraction(0)) if k is None else None
            comes = [(k, Fraction(1))] if k is not None else [(t + 1, h), (None, 1 - h)]
            for k2, p_event in comes:
                if p_event == 0:
                    continue
                q = detect if k2 is not None else alarm  # this step's report
                for told, p_told in ((True, q), (False, 1 - q)):
                    seen = frozenset({"b"}) if told else frozenset()
                    for w2, p_world in GAME.successors(w, action, frozenset()):
                        after, _ = plan.follow(memory, w2, seen, action)
                        sub = node(t + 1, w2, k2, after)
                        weight = p_action * p_event * p_told * Fraction(str(p_world))
                        out = [o + weight * s for o, s in zip(out, sub, strict=True)]
        memo[key] = (out[0], out[1], out[2])
        return memo[key]

    return node(0, GAME.initial, None, plan.start(GAME.initial))


@pytest.fixture(scope="module")
def constrained() -> Any:
    return synthesize(_model(*POSED), bands="best", constraints=[CONSTRAINT])


@pytest.mark.parametrize("extra", [{"constraints": [CONSTRAINT]}, {"then": "min-steps"},
                                   {"constraints": [CONSTRAINT], "objective": "min"}])
def test_the_ends_are_the_separate_optimistic_constrained_solves(extra: dict[str, Any]
                                                                 ) -> None:
    """Not refused: ``lower`` (for a minimum ``upper``) the blind optimistic constrained
    solve's, done separately, and the other end the informed one's; the constraint met,
    ``then``'s steps the blind controller's; the reports' information not read, so for
    the maximum the check names the gap and nothing is certified."""
    r = synthesize(_model(*POSED), bands="best", **extra)
    assert r.route == "sensed-constrained" and r.status == "optimal"
    assert r.summary()["bands_reading"] == "best"
    blind = synthesize(_model(0.0), bands="best", **extra)
    informed = synthesize(_model(INFORMED), bands="best", **extra)
    if extra.get("objective") == "min":
        assert abs(r.upper - blind.upper) <= 1e-12 and abs(r.lower - informed.lower) <= 1e-12
    else:
        assert abs(r.lower - blind.lower) <= 1e-12 and abs(r.upper - informed.upper) <= 1e-12
        assert r.lower < r.upper and not r.certified
        check = next(c for c in r.checks
                     if c.name == "false alarms, law that may never happen")
        assert not check.passed and "not read" in check.detail
    assert all(v.holds for v in r.constraints)
    if "then" in extra:
        assert abs(r.secondary - blind.secondary) <= 1e-9 and r.secondary < float("inf")
        assert "at the band's law it is played with" in r.checks[-1].detail


def test_the_enumeration_at_nature_s_law_gives_lower(constrained: Any, monkeypatch: Any
                                                     ) -> None:
    """The returned randomised controller, replayed with every step's report handed to
    it, at the law nature chose (the answer's model; held fixed): its task probability
    is ``lower``, its ``P(F A)`` within the bound (and the bound binds: without the
    constraint the blind best law does better); it is the blind controller (the same
    value with reports never given); its law is the one the answer names."""
    r = constrained
    assert r.controller is not None and r.controller.randomised
    law = LAWS[r.part.chosen_at]
    chosen = r.model.distributions["b"]  # the event's law, at nature's choice
    assert [Fraction(str(float(m))) for m in chosen.masses] == list(law)
    task, visits, open_ = at_law(r.controller.plan, law)
    assert open_ <= Fraction(1, 10**12)  # the runs open that long: none worth counting
    assert abs(task - Fraction(r.lower)) <= Fraction(1, 10**9)
    assert visits + open_ <= Fraction(3, 10) + Fraction(1, 10**9)
    (v,) = r.constraints
    assert v.holds and abs(Fraction(v.value) - visits) <= Fraction(1, 10**8)
    assert r.lower < synthesize(_model(0.0), bands="best").lower - 1e-3
    monkeypatch.setattr(band_case, "DETECT", Fraction(0))  # no report ever given
    monkeypatch.setattr(band_case, "ALARM", Fraction(0))
    assert at_law(r.controller.plan, law) == (task, visits, open_)


@pytest.mark.skipif(importlib.util.find_spec("stormpy") is None, reason="needs stormpy")
def test_storm_on_the_exported_plain_chain(constrained: Any, tmp_path: Path) -> None:
    """The plain chain at nature's chosen law, every step's report drawn and dropped:
    Storm's exact ``P=? [F "accept"]`` is ``lower``, its ``P=? [F "c1"]`` within 0.3."""
    from storm_exact import drn_reach

    from mitld_lp.running.chain import write_chain

    path = write_chain(constrained, tmp_path / "c.drn")
    assert abs(drn_reach(path, "accept") - Fraction(constrained.lower)) <= Fraction(1, 10**9)
    assert drn_reach(path, "c1") <= Fraction(3, 10) + Fraction(1, 10**9)


def test_the_trade_off_curve() -> None:
    """``pareto`` against the expected steps with the best law: each point bracketed,
    its bound met, the task's ``lower`` never falling as the bound loosens, each at most
    the best law's blind answer without the constraint."""
    from mitld_lp import pareto

    points = pareto(_model(*POSED), against="steps", bands="best", points=3)
    free = synthesize(_model(0.0), bands="best").lower
    assert len(points) == 3 and all(p.status == "optimal" for p in points)
    assert all(p.achieved <= p.bound + 1e-9 and p.lower <= free + 1e-9 for p in points)
    assert all(a.lower <= b.lower + 1e-9 for a, b in zip(points, points[1:], strict=False))


def _kept(detect: float = 1.0) -> Any:
    """The model with the sensor ``KeptSensor(detect)``: no false alarm, kept sensed."""
    model = _model(0.5)
    return dataclasses.replace(model, sensors=MappingProxyType({"b": KeptSensor(detect)}))


@pytest.mark.parametrize("bands, pick", [("worst", min), ("best", max)])
def test_detect_one_with_false_alarms(bands: str, pick: Any, monkeypatch: Any) -> None:
    """``detect = 1``, ``false_alarm = 0.2`` (it stopped with exit 2: the informed sensor
    reports surely and at once, and the fully observed robust route then stopped on the
    band): the informed end is the band's solve with that sensor kept sensed, done
    separately, whose controller attains the fully observed optimum (every deterministic
    controller by brute force, the bus seen the step it comes: 7/15 for the worst law,
    7/10 for the best); ``lower`` the blind solve's; the posed optimum, by brute force
    over every report, within the bracket."""
    r = synthesize(_model(1.0, 0.2), bands=bands)
    assert r.route == "sensed" and r.status == "optimal"
    informed = synthesize(_kept(), bands=bands)
    blind = synthesize(_model(0.0), bands=bands)
    assert abs(r.lower - blind.lower) <= 1e-12 and abs(r.upper - informed.upper) <= 1e-12
    monkeypatch.setattr(band_case, "DETECT", Fraction(1))
    monkeypatch.setattr(band_case, "ALARM", Fraction(1, 5))
    posed = best_deterministic(pick)
    assert Fraction(r.lower) - Fraction(1, 10**9) <= posed <= Fraction(r.upper)
    monkeypatch.setattr(band_case, "ALARM", Fraction(0))
    full = best_deterministic(pick)
    assert full == (Fraction(7, 15) if pick is min else Fraction(7, 10))
    assert abs(Fraction(informed.lower) - full) <= Fraction(1, 10**9)
    assert abs(band_case.value(band_case.replayed(informed.controller), pick) - full) \
        <= Fraction(1, 10**9)


def test_detect_one_with_false_alarms_and_a_constraint() -> None:
    """The worst law with a constraint and ``detect = 1``: the informed end is the band
    constrained solve with the sensor kept sensed, done separately; ``lower`` the blind
    one's, the constraint met under every law."""
    r = synthesize(_model(1.0, 0.2), constraints=[CONSTRAINT])
    assert r.route == "sensed-constrained" and r.status == "optimal"
    informed = synthesize(_kept(), constraints=[CONSTRAINT])
    blind = synthesize(_model(0.0), constraints=[CONSTRAINT])
    assert abs(r.lower - blind.lower) <= 1e-9 and abs(r.upper - informed.upper) <= 1e-12
    assert all(v.holds for v in r.constraints)


def test_infeasible_only_where_proved(monkeypatch: pytest.MonkeyPatch) -> None:
    """``P(F (b & A)) >= 0.45``: no law of the band lets the robot meet it (by hand: it is
    at ``A`` at one step only, and the bus comes at any one step with at most 0.4: at
    step 1 its hazard is at most 2/5, at step 2 at most ``(1 - 1/5) * 1/2``).  The route
    proves that through the fully observed bound (a band of mass tables is constant after
    its laws' last support): ``infeasible``.  Where that bound cannot be computed (left
    out, NaN) nothing proves it: ``failed``, no controller, no constraint said to hold (the
    middle law's LP is infeasible, which alone proves nothing of the band).  A band whose
    laws surely happen keeps ``infeasible`` where the fully observed problem is (tests/
    test_false_alarms_best.py's world with contradictory bounds).  ``>= 0.35``: met at an
    end law (0.4 there, going the step before the bus's likelier step), not at the middle
    law."""
    from test_false_alarms_best import model as surely

    import mitld_lp.routes.sensed_optimistic_constrained as soc

    r = synthesize(_model(*POSED), bands="best", constraints=["P(F (b & A)) >= 0.45"])
    assert str(r.status) == "infeasible" and r.controller is None
    monkeypatch.setattr(soc, "_full_bound", lambda posed: (float("nan"), False))
    r = synthesize(_model(*POSED), bands="best", constraints=["P(F (b & A)) >= 0.45"])
    assert str(r.status) == "failed" and r.controller is None
    assert not any(v.holds for v in r.constraints) and not r.certified
    monkeypatch.undo()
    s = synthesize(surely("max"), bands="best",
                   constraints=["P(F[0,1] A) >= 0.5", "P(F[0,1] A) <= 0.2"])
    assert str(s.status) == "infeasible" and s.controller is None
    r = synthesize(_model(*POSED), bands="best", constraints=["P(F (b & A)) >= 0.35"])
    assert r.status == "optimal" and r.part.chosen_at in ("low ends", "high ends")
    assert all(v.holds for v in r.constraints)
