"""Sensed events whose law is known only within a band (issue 43): the worst case over
the band for a controller that acts on observations, with sound bounds.

Independent routes: an enumeration in exact arithmetic of every hidden scenario (the
step the event comes, the steps its sensor reports it, the world's branches) and of
nature's choices at every step among the band's two ends, nature seeing everything (a
minimum at every node), the returned controller asked for its action after replaying
each observation history (no automaton, no information states, no chain); and Storm's
robust check of the exported interval model."""

from __future__ import annotations

import importlib.util
from fractions import Fraction
from pathlib import Path
from typing import Any

import pytest

from mitld_lp import ExplicitGame, Model, synthesize
from mitld_lp.controllers.observation import Observation
from mitld_lp.distributions import from_table
from mitld_lp.running.sensed_band_chain import write_sensed_band_chain
from mitld_lp.sensing import Sensor

MODELS = Path(__file__).resolve().parent.parent / "models"

# a robot waits in "mid"; "go" reaches the goal "sa" (A) with 3/4, from where it must
# pass "trap" before it is back: a round of 3 steps, so it cannot be at A in every window
# of two steps, and seeing the event's report tells it when to go
GAME = ExplicitGame(initial="mid", labels={"sa": {"A"}}, transitions={
    "mid": {"go": {"sa": 0.75, "mid": 0.25}, "wait": {"mid": 1.0}},
    "sa": {"back": {"trap": 1.0}}, "trap": {"back": {"mid": 1.0}}})
SPEC = "D[mu] b & F[0,3] (b & F[0,1] A)"  # b at step k <= 3, A at a step in [k, k + 1]


def model(band: Any, detect: float) -> Model:
    return Model.from_game(GAME, SPEC, distributions={"mu": from_table({"geometric": band},
                                                                         "mu")},
                           sensors={"b": Sensor(detect)})


def replay(controller: Any, seen: list[tuple[str, frozenset[str]]]) -> str | None:
    """The controller's action after the observation history ``seen`` (each step's
    world state and reports), replayed from its start."""
    controller.reset()
    action = controller.act(Observation(seen[0][0]))
    for state, reports in seen[1:]:
        action = controller.act(Observation(state, reports=reports))
    return action


def worst_over_nature(controller: Any, lo: str, hi: str, detect: str, *,
                      pick: Any = min, game: ExplicitGame = GAME,
                      alarm: str | None = None) -> Fraction:
    """The controller's value in ``game`` (default :data:`GAME`, the task :data:`SPEC`)
    with nature choosing the hazard of each step among ``lo`` and ``hi`` after seeing
    everything so far (module docs), by ``pick`` (``min``: against a robot that
    maximises; ``max``: against one that minimises), as a fraction.  ``alarm``: the
    sensor reports or not at every step, with ``detect`` from the step ``b`` comes and
    ``alarm`` before it (false alarms; tests/test_false_alarms_band.py)."""
    d = Fraction(detect)
    ends = (Fraction(lo), Fraction(hi))

    def value(t: int, state: str, k: int | None, reported: bool,
              seen: list[tuple[str, frozenset[str]]]) -> Fraction:
        if k is not None and k <= t <= k + 1 and "A" in game.propositions(state):
            return Fraction(1)
        if (k is None and t >= 3) or (k is not None and t >= k + 1):
            return Fraction(0)  # the event too late, or its window missed
        action = replay(controller, seen)
        if action is None:
            return Fraction(0)
        values = []
        for h in (ends if k is None else (None,)):
            v = Fraction(0)
            comes = [(t + 1, h), (None, 1 - h)] if k is None else [(k, Fraction(1))]
            for k2, pe in comes:
                if pe == 0:
                    continue
                if alarm is not None:  # every step's report: due from the step b comes
                    p = d if k2 is not None else Fraction(alarm)
                    told = [(True, p), (False, 1 - p)]
                else:
                    told = ([(True, d), (False, 1 - d)] if k2 is not None and not reported
                            else [(reported, Fraction(1))])
                for now, pr in told:
                    reports = (frozenset({"b"}) if now and (alarm or not reported)
                               else frozenset())
                    for nxt, pw in game.successors(state, action, frozenset()):
                        v += pe * pr * Fraction(str(pw)) * value(
                            t + 1, nxt, k2, now, [*seen, (nxt, reports)])
            values.append(v)
        return pick(values)

    return value(0, game.initial, None, False, [(game.initial, frozenset())])


@pytest.mark.parametrize("band, detect", [(("0.3", "0.6"), "0.6"), (("0.1", "0.9"), "0.5"),
                                          (("0.2", "0.7"), "0")])
def test_lower_is_the_controllers_worst_case_over_nature(band, detect) -> None:
    r = synthesize(model([float(band[0]), float(band[1])], float(detect)))
    assert r.route == "sensed" and r.bands
    worst = worst_over_nature(r.controller, *band, detect)
    assert Fraction(r.lower) <= worst <= Fraction(r.upper)
    assert abs(worst - Fraction(r.lower)) <= Fraction(1, 10**9)
    # nature does hurt: the worst case lies below the value at the band's middle law
    assert r.lower < r.part.nominal_upper
    # honest: certified only when the gap is within the precision
    # (the truncation's part of the gap reported apart, as every route's)
    assert r.certified == (r.upper - r.lower - r.width["truncation"] <= r.precision * r.lower)
    if not r.certified:
        assert "not certified" in r.part.message and "both ends" in r.part.message


def test_upper_is_the_full_information_robust_optimum_when_it_is_less() -> None:
    """A perfect sensor: the robust route's answer on the same problem; the sensed
    controller cannot beat the robot that sees the event."""
    seen = synthesize(model([0.3, 0.6], 1.0))
    assert seen.route == "robust"
    r = synthesize(model([0.3, 0.6], 0.6))
    assert r.upper <= seen.upper + 1e-12 and r.lower <= seen.lower + 1e-12


@pytest.mark.skipif(importlib.util.find_spec("stormpy") is None, reason="needs stormpy")
def test_storm_on_the_exported_interval_model_gives_lower(tmp_path: Path) -> None:
    from test_band_chain import storm_worst  # Storm's Pmin, uncertainty MINIMIZE

    r = synthesize(model([0.3, 0.6], 0.6))
    path = write_sensed_band_chain(r, tmp_path / "c.drn")
    assert "b=lo" in path.read_text() and "b=hi" in path.read_text()
    assert abs(storm_worst(path) - r.lower) <= 1e-9
    with pytest.raises(FileExistsError):
        write_sensed_band_chain(r, path)


def test_a_band_of_one_point_is_the_sensed_point_answer() -> None:
    point = synthesize(Model.from_game(GAME, SPEC, distributions={
        "mu": from_table({"geometric": 0.45}, "mu")}, sensors={"b": Sensor(0.6)}))
    r = synthesize(model([0.45, 0.45], 0.6))
    assert (r.lower, r.upper, r.certified) == (point.lower, point.upper, point.certified)
    assert worst_over_nature(r.controller, "0.45", "0.45", "0.6") >= Fraction(r.lower)


def test_the_point_chain_of_a_band_answer_is_refused() -> None:
    from mitld_lp.running.chain import chain_of

    with pytest.raises(ValueError, match="no Markov chain"):
        chain_of(synthesize(model([0.3, 0.6], 0.6)))


def test_a_certified_answer_is_the_optimum_at_the_band_s_worst_constant_law() -> None:
    """Band [0.3, 0.6], camera 0.6: the bracket closes.  Its value must then be the best
    an observation-based policy does against nature's constant low hazard (an upper
    bound on the worst-case optimum, nature being free to play it), found here by an
    expectimax over observation histories (tests/test_sensed_chain.py) with the law
    0.3, 0.7 * 0.3, 0.7^2 * 0.3 on steps 1..3 (a later bus is too late)."""
    from test_sensed_chain import histories

    r = synthesize(model([0.3, 0.6], 0.6))
    assert r.certified
    best = histories(GAME, [(("0.3", "0.21", "0.147"), "0.6", 0, "A", 1)], 4)
    assert abs(best - Fraction(r.lower)) <= Fraction(1, 10**9)
    assert worst_over_nature(r.controller, "0.3", "0.6", "0.6") >= Fraction(r.lower)


@pytest.mark.skipif(importlib.util.find_spec("stormpy") is None, reason="needs stormpy")
def test_a_safety_task_with_a_camera_and_a_band_exported_and_rechecked_by_storm(
        tmp_path: Path, capsys) -> None:
    """bus_puddle (G !puddle: a safety part, kept on the chain's closed components of
    persistent states), bus 1 a band seen by a camera: ``export --chain`` writes the
    interval model, Storm's robust check of it gives lower, inside the bracket."""
    import json

    from test_band_chain import storm_worst

    from mitld_lp.cli import main

    text = (MODELS / "bus_puddle.toml").read_text().replace(
        "mu1 = { geometric = 0.8 }", "mu1 = { geometric = [0.7, 0.9] }", 1)
    path = tmp_path / "puddle.toml"
    path.write_text(text + "\n[sensors]\nb1 = { detect = 0.5 }\n")
    out = tmp_path / "p.drn"
    code = main(["export", str(path), "--chain", str(out), "--json"])
    said = json.loads(capsys.readouterr().out)
    lower, upper, certified = said["lower"], said["upper"], said["certified"]
    assert code == (0 if certified else 3) and 0.0 < lower <= upper
    assert abs(storm_worst(out) - lower) <= 1e-9
    assert said["chain_accept"] == lower


def test_the_chain_s_budget_and_the_time_limit() -> None:
    """A budget one state short of the interval chain (larger than the information-state
    product here) stops it by name; with no time left for the bands' ends the middle
    law's answer comes back uncertified, its gap said."""
    from mitld_lp.util.memory import ProductTooLarge

    full = synthesize(model([0.3, 0.6], 0.6))
    n = full.part.worst.n_states
    assert n > full.mdp.n_states
    assert synthesize(model([0.3, 0.6], 0.6), max_states=n).lower == full.lower
    with pytest.raises(ProductTooLarge, match=f"interval chain has more than {n - 1} states"):
        synthesize(model([0.3, 0.6], 0.6), max_states=n - 1)
    r = synthesize(model([0.3, 0.6], 0.6), time_limit=1e-3)
    assert list(r.part.point_uppers) == ["middle law"] and not r.certified
    assert r.lower <= r.upper and "not certified" in r.part.message


def test_the_controller_saved_and_loaded_has_the_same_worst_case(tmp_path: Path) -> None:
    from mitld_lp.controllers.kinds import load_controller
    from mitld_lp.running.sensed_band_chain import sensed_band_chain_of, worst_case

    r = synthesize(model([0.1, 0.9], 0.5))
    loaded = load_controller(r.controller.save(tmp_path / "c.npz"))
    again = worst_case(sensed_band_chain_of(r, loaded))
    assert again.n_states == r.part.worst.n_states and again.lower == r.lower
    assert worst_over_nature(loaded, "0.1", "0.9", "0.5") >= Fraction(r.lower)
