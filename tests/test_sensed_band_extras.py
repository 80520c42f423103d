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


CONSTRAINT = "P(F[0,2] A) <= 0.5"  # decided by step 2: no run is left undecided


def randomised_by_nature(controller: Any, band: tuple[str, str], detect: str,
                         won: Callable[[int, str, int | None], bool | None],
                         pick: Callable[[list[Fraction]], Fraction]) -> Fraction:
    """The probability that ``won(t, state, k)`` says True (None: not decided yet)
    under a randomised observation-based controller (its plan's mixed decision after
    each observation history), nature picking the hazard of each step among the band's
    ends by ``pick`` after seeing the robot's draw, in exact arithmetic
    (tests/test_sensed_band_keep.py's enumeration; no stay expected)."""
    from test_sensed_band_keep import enumerated

    return enumerated(controller.plan, GAME, band, detect,
                      lambda t, state, k, trace: won(t, state, k), pick)


def _task(t: int, state: str, k: int | None) -> bool | None:
    if k is not None and k <= t <= k + 1 and "A" in GAME.propositions(state):
        return True
    return False if (k is None and t >= 3) or (k is not None and t >= k + 1) else None


def _early_a(t: int, state: str, k: int | None) -> bool | None:
    if t <= 2 and "A" in GAME.propositions(state):
        return True
    return False if t >= 2 else None


@pytest.fixture(scope="module")
def constrained() -> Any:
    return synthesize(model(("0.3", "0.6"), "0.6"), constraints=[CONSTRAINT])


def test_a_constraint_holds_under_every_law_and_lower_is_the_worst_case(constrained) -> None:
    """The returned controller's constraint value with nature making ``A`` by step 2
    as likely as it can is within its bound, and the task's with nature against it is
    ``lower``; both by the exact enumeration."""
    r = constrained
    assert r.route == "sensed-constrained" and r.bands and r.controller is not None
    (v,) = r.constraints
    assert v.holds
    worst_a = randomised_by_nature(r.controller, ("0.3", "0.6"), "0.6", _early_a, max)
    assert worst_a <= Fraction(1, 2) and worst_a <= Fraction(v.bounds[1])
    assert abs(worst_a - Fraction(v.bounds[1])) <= Fraction(1, 10**8)
    task = randomised_by_nature(r.controller, ("0.3", "0.6"), "0.6", _task, min)
    assert abs(task - Fraction(r.lower)) <= Fraction(1, 10**9) and r.lower <= r.upper
    # the robot that sees the event, under the same band and constraint: no better
    seen = synthesize(Model.from_game(GAME, SPEC, distributions={"mu": from_table(
        {"geometric": [0.3, 0.6]}, "mu")}), constraints=[CONSTRAINT])
    assert r.lower <= seen.upper + 1e-9


@needs_storm
def test_storm_on_the_constrained_interval_chain(constrained, tmp_path: Path) -> None:
    """Storm's robust check of the exported file: ``Pmin [F "accept"]`` (uncertainty
    MINIMIZE) is ``lower``, ``Pmax [F "c1"]`` (MAXIMIZE) the constraint's worst case."""
    import stormpy
    from test_band_chain import storm_worst

    from mitld_lp.running.sensed_band_chain import write_sensed_band_chain

    r = constrained
    path = write_sensed_band_chain(r, tmp_path / "c.drn")
    assert abs(storm_worst(path) - r.lower) <= 1e-9
    chain = stormpy.build_model_from_drn[stormpy.Interval](str(path))
    env = stormpy.Environment()
    env.solver().min_max().precision = stormpy.Rational("1/1000000000000")
    got = stormpy.model_checking(
        chain, stormpy.parse_properties('Pmax=? [F "c1"]')[0], environment=env,
        uncertainty_resolution_mode=stormpy.UncertaintyResolutionMode.MAXIMIZE)
    worst = float(got.get_value(chain.initial_states[0]))
    (v,) = r.constraints
    assert worst <= v.bounds[1] + 1e-12 and abs(worst - v.bounds[1]) <= 1e-8


def test_no_controller_meeting_the_constraint_under_every_law_is_failed() -> None:
    """``P(task) >= 0.44``: met at each of the band's constant laws (the sensed optimum
    at the low end is 0.4448, by the expectimax of tests/test_sensed_band.py's last
    tests and the route alike), but the candidates' worst case over the band is below
    it: status failed, no controller, no constraint said to hold, and the answer says
    so rather than return a controller meeting it at some laws only."""
    r = synthesize(model(("0.3", "0.6"), "0.6"),
                   constraints=["P(F[0,3] (b & F[0,1] A)) >= 0.44"])
    assert str(r.status) == "failed" and r.controller is None and r.lower != r.lower
    assert not any(v.holds for v in r.constraints)
    assert "under every law of the band" in r.part.message
    low = synthesize(model(("0.3", "0.3"), "0.6"))  # the band's low end as a point law
    assert low.lower >= 0.44


def test_the_interval_chain_too_large_is_stopped_before_its_unfolding() -> None:
    """A budget that the information-state product fits but the controller's interval
    chain cannot: stopped from the product's count (a lower bound on the chain's
    states), before the chain is unfolded, naming that count; the count is at most the
    states of the chain unfolded under a budget it fits."""
    import re

    from test_composition_sensed import _model

    from mitld_lp.util.memory import ProductTooLarge

    # the middle law's controller alone (no time left for the bands' ends): the one the
    # budget stops
    full = synthesize(_model("safety", "band", 0.6, "none"), time_limit=1e-3)
    assert list(full.part.point_uppers) == ["middle law"]
    chain, product = full.part.worst.n_states, full.mdp.n_states
    assert product < chain
    budget = (product + chain) // 2
    with pytest.raises(ProductTooLarge, match="at least") as err:
        synthesize(_model("safety", "band", 0.6, "none"), max_states=budget)
    floor = int(re.search(r"at least ([\d,]+) states", str(err.value))[1].replace(",", ""))
    assert budget < floor <= chain


@needs_storm
def test_a_mixed_first_step_gives_nature_a_corner_per_action(tmp_path: Path) -> None:
    """``P(F[0,1] A) >= 0.5``: the robot must draw between going and holding at the
    first step, with the bus's band open; the chain gives nature a corner for each
    action drawn (choices named ``act/go:b=lo/hold:b=hi``), and its worst cases are the
    enumeration's (nature choosing after the draw) and Storm's."""
    from test_band_chain import storm_worst

    from mitld_lp.running.sensed_band_chain import write_sensed_band_chain

    def early(t: int, state: str, k: int | None) -> bool | None:
        if t <= 1 and "A" in GAME.propositions(state):
            return True
        return False if t >= 1 else None

    r = synthesize(model(("0.3", "0.6"), "0.6"), constraints=["P(F[0,1] A) >= 0.5"])
    (v,) = r.constraints
    assert v.holds and r.controller is not None
    path = write_sensed_band_chain(r, tmp_path / "c.drn")
    assert "go:b=lo/hold:b=hi" in path.read_text() or "hold:b=hi/go:b=lo" in path.read_text()
    task = randomised_by_nature(r.controller, ("0.3", "0.6"), "0.6", _task, min)
    assert abs(task - Fraction(r.lower)) <= Fraction(1, 10**9)
    assert abs(storm_worst(path) - r.lower) <= 1e-9
    reach = randomised_by_nature(r.controller, ("0.3", "0.6"), "0.6", early, min)
    assert reach >= Fraction(1, 2) and abs(reach - Fraction(v.bounds[0])) <= Fraction(1, 10**9)


def test_the_trade_off_curve_s_end_point_is_the_worst_case_not_the_middle_law() -> None:
    """``synthesize_constrained`` without constraints (the trade-off curve's end point):
    the band's worst case of its controller (the enumeration's), within the sensed band
    route's bracket, not the optimum at the band's middle law (0.589 here)."""
    from mitld_lp.synthesis import synthesize_constrained

    r = synthesize_constrained(model(("0.3", "0.6"), "0.6"), [])
    assert r.bands and r.controller is not None
    worst = randomised_by_nature(r.controller, ("0.3", "0.6"), "0.6", _task, min)
    assert abs(worst - Fraction(r.lower)) <= Fraction(1, 10**9)
    alone = synthesize(model(("0.3", "0.6"), "0.6"))
    assert r.lower <= alone.upper + 1e-12 and alone.lower <= r.upper + 1e-12
    middle = synthesize(model(("0.45", "0.45"), "0.6"))
    assert r.upper < middle.lower
