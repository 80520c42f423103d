"""A sensor with false alarms that detects surely (``detect = 1``) and a band whose laws
may never happen (issue 43): it stopped with exit 2, the informed end (a sensor without
false alarms at least as informative: here one that reports surely and at once) posed on
the fully observed robust route, which cannot truncate such a band.  The informed end
now stays on the sensed routes (``KeptSensor``, mitld_lp/routes/sensed_never.py), which
truncate it.

Independent routes: the two ends solved separately (the sensor blind; the kept sensor),
and the fully observed band optimum by brute force over every deterministic controller
(tests/test_false_alarms_never_band.py's enumeration in exact arithmetic, the bus seen
the step it comes), which the kept sensor's controller attains; the posed optimum, by
the same brute force over every step's report, within the bracket.

The world and band are tests/test_false_alarms_never_band.py's: the bus ``b`` comes at
step 1 or 2 or never (0.4 at every law of the band), the robot must be at ``A`` the
step after it comes; the constraint ``P(F A) <= 0.3`` bounds going to ``A`` at all."""

from __future__ import annotations

import dataclasses
from fractions import Fraction
from types import MappingProxyType
from typing import Any

import pytest
import test_false_alarms_never_band as band_case
from test_false_alarms_never_band import _model, best_deterministic

from mitld_lp import synthesize
from mitld_lp.routes.sensed_never import KeptSensor

CONSTRAINT = "P(F A) <= 0.3"


def _kept(detect: float = 1.0) -> Any:
    """The model with the sensor ``KeptSensor(detect)``: no false alarm, kept sensed."""
    model = _model(0.5)
    return dataclasses.replace(model, sensors=MappingProxyType({"b": KeptSensor(detect)}))


@pytest.mark.parametrize("bands, pick", [("worst", min), ("best", max)])
def test_detect_one_with_false_alarms(bands: str, pick: Any, monkeypatch: Any) -> None:
    """``detect = 1``, ``false_alarm = 0.2`` (it stopped with exit 2: the informed sensor
    reports surely and at once, and the fully observed robust route cannot truncate the
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
