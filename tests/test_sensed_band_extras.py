"""Sensors that miss their event and a law known only within a band, with the extras
(issue 43): ``objective = "min"``, constraints, ``then``.

Independent routes: an enumeration in exact arithmetic of every hidden scenario (the
step the event comes, the steps its sensor reports it, the world's branches) with
nature's choice at every step among the band's two ends, nature seeing everything (the
worst for the robot at every node: a least probability of a maximised task, a greatest
of a minimised one or of a constraint's formula), the returned controller asked for its
action after replaying each observation history; and Storm's robust check of the
exported interval chain."""

from __future__ import annotations

import importlib.util
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path
from typing import Any

import pytest

from mitld_lp import ExplicitGame, Model, synthesize
from mitld_lp.distributions import from_table
from mitld_lp.sensing import Sensor

needs_storm = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                 reason="needs stormpy")

# the robot must move: "go" reaches A with 3/4, "hold" with 1/4; from A a round of three
# steps back; the task: the event at a step k <= 3 and A at a step in [k, k + 1]
GAME = ExplicitGame(initial="mid", labels={"sa": {"A"}}, transitions={
    "mid": {"go": {"sa": 0.75, "mid": 0.25}, "hold": {"sa": 0.25, "mid": 0.75}},
    "sa": {"back": {"trap": 1.0}}, "trap": {"back": {"mid": 1.0}}})
SPEC = "D[mu] b & F[0,3] (b & F[0,1] A)"


def model(band: tuple[str, str], detect: str, **kw: Any) -> Model:
    law = from_table({"geometric": [float(band[0]), float(band[1])]}, "mu")
    return Model.from_game(GAME, SPEC, distributions={"mu": law},
                           sensors={"b": Sensor(float(detect))}, **kw)


def by_nature(controller: Any, band: tuple[str, str], detect: str,
              pick: Callable[[list[Fraction]], Fraction]) -> Fraction:
    """The controller's probability of the task in :data:`GAME` with nature picking, at
    every step before the event, the hazard among the band's ends by ``pick``
    (tests/test_sensed_band.py's enumeration), in exact arithmetic."""
    from test_sensed_band import worst_over_nature

    return worst_over_nature(controller, *band, detect, pick=pick, game=GAME)


@pytest.mark.parametrize("band, detect", [(("0.3", "0.6"), "0.6"), (("0.1", "0.9"), "0.5"),
                                          (("0.2", "0.7"), "0")])
def test_a_minimum_upper_is_the_controllers_worst_case_over_nature(band, detect) -> None:
    """A minimum: nature makes the task as likely as it can; ``upper`` is the returned
    controller's worst case (the greatest probability over nature's choices), and
    ``lower`` is at most what the robot that sees the event achieves against nature
    (the robust route's minimum, no camera), below which no observation-based
    controller goes."""
    r = synthesize(model(band, detect, objective="min"))
    assert r.route == "sensed" and r.bands and r.complemented
    worst = by_nature(r.controller, band, detect, max)
    assert Fraction(r.lower) <= worst <= Fraction(r.upper)
    assert abs(worst - Fraction(r.upper)) <= Fraction(1, 10**9)
    law = from_table({"geometric": [float(band[0]), float(band[1])]}, "mu")
    seen = synthesize(Model.from_game(GAME, SPEC, distributions={"mu": law}, objective="min"))
    assert seen.route == "robust" and r.lower <= seen.upper + 1e-12
    assert r.complement == (pytest.approx(1 - r.upper, abs=1e-12),
                            pytest.approx(1 - r.lower, abs=1e-12))
    assert r.certified == (r.upper - r.lower <= r.precision * (1 - r.upper)
                           + r.width["truncation"] + 1e-15)


@needs_storm
def test_a_minimum_s_exported_chain_gives_its_complement_to_storm(tmp_path: Path) -> None:
    from test_band_chain import storm_worst

    from mitld_lp.running.sensed_band_chain import sensed_band_claim, write_sensed_band_chain

    r = synthesize(model(("0.3", "0.6"), "0.6", objective="min"))
    path = write_sensed_band_chain(r, tmp_path / "c.drn")
    bound, said = sensed_band_claim(r)
    assert bound == r.complement[0] and "complement" in said
    # the file's automaton is the complement's: "accept" marks the runs that fail
    assert abs(storm_worst(path) - (1 - r.upper)) <= 1e-9
