"""A sensor with false alarms and a law known only within a band whose laws surely happen
(issue 43): the band's worst case on the sensed route, as without false alarms
(mitld_lp/routes/sensed_band.py), its controller reading every step's report.

Independent routes: an enumeration in exact arithmetic of every hidden scenario (the
step the event comes, the report or silence of every step, the world's branches) and of
nature's choices of each step's hazard among the band's ends after seeing everything
(tests/test_sensed_band.py's ``worst_over_nature`` with ``alarm``),
the returned controller asked for its action after replaying each observation history
(no automaton, no information states, no chain); the point-law answers with false
alarms at the band's ends (nature may play either end at every step, so the worst-case
optimum is at most each); and Storm's robust check of the exported interval chain."""

from __future__ import annotations

import importlib.util
from fractions import Fraction
from pathlib import Path
from typing import Any

import pytest
from test_sensed_band import GAME, SPEC, worst_over_nature

from mitld_lp import Model, synthesize
from mitld_lp.distributions import from_table
from mitld_lp.running.sensed_band_chain import write_sensed_band_chain
from mitld_lp.sensing import Sensor

BAND, DETECT, ALARM = ("0.1", "0.9"), "0.7", "0.2"


def _model(law: Any) -> Model:
    return Model.from_game(GAME, SPEC, distributions={"mu": from_table({"geometric": law},
                                                                         "mu")},
                           sensors={"b": Sensor(float(DETECT), false_alarm=float(ALARM))})


def test_band_with_false_alarms_is_the_controllers_worst_case_and_a_sound_bracket() -> None:
    r = synthesize(_model([float(x) for x in BAND]))
    assert r.route == "sensed" and r.bands
    worst = worst_over_nature(r.controller, *BAND, DETECT, alarm=ALARM)
    assert Fraction(r.lower) <= worst <= Fraction(r.upper)
    assert abs(worst - Fraction(r.lower)) <= Fraction(1, 10**9)
    # the worst-case optimum is at most each end's point-law optimum (nature may play it
    # at every step): solved as point laws with false alarms
    for end in BAND:
        point = synthesize(_model(float(end)))
        assert point.route == "sensed" and not point.bands
        assert r.lower <= point.upper + 1e-12
    # nature does hurt, and the false alarms are read: without them the answer differs
    assert r.lower < r.part.nominal_upper
    quiet = synthesize(Model.from_game(GAME, SPEC, distributions={
        "mu": from_table({"geometric": [float(x) for x in BAND]}, "mu")},
        sensors={"b": Sensor(float(DETECT))}))
    assert r.lower < quiet.lower - 1e-6  # 0.1879 against 0.1959
    assert r.certified == (r.upper - r.lower - r.width["truncation"] <= r.precision * r.lower)


def test_a_minimum_with_false_alarms_under_a_band() -> None:
    """``objective = "min"``: ``upper`` is the returned controller's worst case (nature
    making the task as likely as it can), by the same enumeration with nature maximising;
    at least each end's point-law minimum."""
    r = synthesize(_model([float(x) for x in BAND]), objective="min")
    assert r.route == "sensed" and r.bands
    worst = worst_over_nature(r.controller, *BAND, DETECT, alarm=ALARM, pick=max)
    assert Fraction(r.lower) <= worst <= Fraction(r.upper)
    assert abs(worst - Fraction(r.upper)) <= Fraction(1, 10**9)
    for end in BAND:
        assert r.upper >= synthesize(_model(float(end)), objective="min").lower - 1e-12


@pytest.mark.skipif(importlib.util.find_spec("stormpy") is None, reason="needs stormpy")
def test_storm_on_the_exported_interval_chain_with_false_alarms_gives_lower(
        tmp_path: Path) -> None:
    from test_band_chain import storm_worst  # Storm's Pmin, uncertainty MINIMIZE

    r = synthesize(_model([float(x) for x in BAND]))
    path = write_sensed_band_chain(r, tmp_path / "c.drn")
    assert abs(storm_worst(path) - r.lower) <= 1e-9


def test_a_band_that_may_never_happen_is_bracketed_by_the_sensed_routes_only() -> None:
    """A law that may never happen (here ``pmf(0.3, 0.3)``: never with 0.4, by hand)
    under a band: the information state is not finite; the sensed routes bracket it
    (``never``: tests/test_false_alarms_never_band.py), a route that does not is refused
    by name, the routes that bracket it named."""
    from mitld_lp.distributions import pmf
    from mitld_lp.routes.sensed import false_alarm_refusal

    said = false_alarm_refusal("b", 0.2, pmf([0.3, 0.3]), robust=True, worst=True)
    assert len(said) == 1 and "never happens with probability 0.4" in said[0]
    assert "with a band (route sensed, its worst or best law; with constraints" in said[0]
    assert false_alarm_refusal("b", 0.2, pmf([0.3, 0.3]), never=True, robust=True,
                               worst=True) == []
    assert false_alarm_refusal("b", 0.2, pmf([0.3, 0.7]), robust=True, worst=True) == []
