"""A camera on a band whose laws' never masses differ (issue 43): the band of ``pmf
[0.3, 0.3]`` (never 0.4) and its neighbours ``pmf [0.2, 0.3]`` (never 0.5) and ``pmf
[0.4, 0.3]`` (never 0.3).  No step has every law's survival within a share of the
middle law's never mass, which stopped the sensed route; every hazard of the band is 0
after step 2, so the route truncates there and cuts nothing
(:func:`mitld_lp.distributions.band.last_event_step`).

The world and task of tests/test_false_alarms_never_band.py (the robot must go to ``A``
the step the bus comes, which only the camera's reports tell), with a camera that
detects 0.7 and gives no false alarm.  By hand from the three pmfs: at step 1 the
hazard is in ``[1/5, 2/5]``, at step 2 in ``[3/8, 1/2]`` (0.3 / 0.8, 0.3 / 0.6), none
after.

Independent routes: that file's enumeration in exact arithmetic of the bus's step (or
never), the reports and nature's choice at every step between the band's two hazards,
nature seeing everything (the returned controller replayed; every deterministic
observation-based controller of the horizon by brute force); the fully observed robust
optimum by hand (a robot seeing the bus goes the step it comes: the least and the most
probable it comes, ``1 - 4/5 * 5/8 = 1/2`` and ``1 - 3/5 * 1/2 = 7/10``); Storm's robust
check of the exported interval chain."""

from __future__ import annotations

import importlib.util
from fractions import Fraction
from pathlib import Path
from typing import Any

import pytest
import test_false_alarms_never_band as world

from mitld_lp import Model, synthesize
from mitld_lp.distributions import pmf
from mitld_lp.distributions.band import band_of_laws
from mitld_lp.sensing import Sensor

HAZARDS = {1: (Fraction(1, 5), Fraction(2, 5)), 2: (Fraction(3, 8), Fraction(1, 2))}
FULL = {min: Fraction(1, 2), max: Fraction(7, 10)}  # the fully observed optima, by hand


def _model(false_alarm: float = 0.0) -> Model:
    band = band_of_laws("mu", pmf([0.3, 0.3]), [pmf([0.2, 0.3]), pmf([0.4, 0.3])])
    return Model.from_game(world.GAME, world.SPEC, distributions={"mu": band},
                           sensors={"b": Sensor(float(world.DETECT), false_alarm=false_alarm)})


@pytest.fixture
def enumeration(monkeypatch: Any) -> Any:
    """The other file's enumeration on this band, with no false alarm."""
    monkeypatch.setattr(world, "HAZARDS", HAZARDS)
    monkeypatch.setattr(world, "ALARM", Fraction(0))
    return world


@pytest.mark.parametrize("bands, pick", [("worst", min), ("best", max)])
def test_the_camera_s_answer_on_the_band(enumeration: Any, bands: str, pick: Any) -> None:
    """``lower`` is the returned controller's worst (best) case by the enumeration;
    ``upper`` is at least the best deterministic controller's and at most the fully
    observed optimum; nothing is truncated past the band's last step.  Under the worst
    law the bracket closes on the best controller's worst case (the band's low end,
    ``pmf [0.2, 0.3]``, is nature's worst at every step, and a candidate); under the best
    the fully observed optimum stays above it, and the answer says so."""
    r = synthesize(_model(), bands=bands)
    assert r.route == "sensed" and r.bands and r.status == "optimal"
    clock = r.sta.clocks["b"]
    assert clock.truncation == 2 and clock.keeps_never and r.width["truncation"] == 0.0
    ours = enumeration.value(world.replayed(r.controller), pick)
    assert abs(ours - Fraction(r.lower)) <= Fraction(1, 10**9)
    best = enumeration.best_deterministic(pick)
    assert Fraction(r.lower) <= best <= Fraction(r.upper) + Fraction(1, 10**9)
    assert Fraction(r.upper) <= FULL[pick] + Fraction(1, 10**9)
    if pick is min:
        assert r.certified and abs(Fraction(r.upper) - best) <= Fraction(1, 10**9)
    else:
        assert not r.certified and abs(Fraction(r.upper) - FULL[max]) <= Fraction(1, 10**9)


@pytest.mark.skipif(importlib.util.find_spec("stormpy") is None, reason="needs stormpy")
def test_storm_on_the_exported_interval_chain_gives_lower(tmp_path: Path) -> None:
    """Storm's robust check (nature minimising) of the controller's interval chain gives
    ``lower``."""
    from test_band_chain import storm_worst

    from mitld_lp.running.sensed_band_chain import write_sensed_band_chain

    r = synthesize(_model())
    path = write_sensed_band_chain(r, tmp_path / "c.drn")
    assert abs(storm_worst(path) - r.lower) <= 1e-9


@pytest.mark.skipif(importlib.util.find_spec("stormpy") is None, reason="needs stormpy")
def test_a_constraint_on_the_band(tmp_path: Path) -> None:
    """Route sensed-constrained takes the band unchanged (its candidates are point laws,
    its chain the same): Storm's ``Pmin [F "accept"]`` of the exported chain is
    ``lower``, its ``Pmax [F "c1"]`` (nature maximising) within the bound, which binds:
    ``upper`` is below the unconstrained worst case."""
    from test_band_chain import storm_robust

    from mitld_lp.running.sensed_band_chain import write_sensed_band_chain

    r = synthesize(_model(), constraints=["P(F A) <= 0.3"])
    assert r.route == "sensed-constrained" and r.status == "optimal"
    assert all(v.holds for v in r.constraints)
    path = write_sensed_band_chain(r, tmp_path / "c.drn")
    assert abs(storm_robust(path, 'Pmin=? [F "accept"]') - r.lower) <= 1e-9
    assert storm_robust(path, 'Pmax=? [F "c1"]', maximise=True) <= 0.3 + 1e-9
    assert r.lower <= r.upper < synthesize(_model()).lower - 1e-3


@pytest.mark.parametrize("bands, pick", [("worst", min), ("best", max)])
def test_false_alarms_on_the_band(monkeypatch: Any, bands: str, pick: Any) -> None:
    """A camera that also gives false alarms (0.2 a step): the bracket of
    routes/sensed_never.py, its ``lower`` the returned controller's worst (best) case by
    the enumeration with every step's report drawn, the best deterministic
    controller reading every report inside the bracket, ``upper`` at most the fully
    observed optimum."""
    monkeypatch.setattr(world, "HAZARDS", HAZARDS)
    r = synthesize(_model(float(world.ALARM)), bands=bands)
    assert r.route == "sensed" and r.bands and r.status == "optimal"
    ours = world.value(world.replayed(r.controller), pick)
    assert abs(ours - Fraction(r.lower)) <= Fraction(1, 10**9)
    best = world.best_deterministic(pick)
    assert Fraction(r.lower) <= best <= Fraction(r.upper) + Fraction(1, 10**9)
    assert Fraction(r.upper) <= FULL[pick] + Fraction(1, 10**9)
