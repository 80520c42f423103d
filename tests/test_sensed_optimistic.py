"""Sensed events with a band read for its best law (``bands = "best"``, issue 43): the
optimum over observation-based policies of the best case over the band, bracketed.

Independent routes: an enumeration in exact arithmetic of every observation-based
policy of a tiny world (a decision for each observation history) jointly with nature's
choice of the hazard at every step among the band's two ends, nature seeing everything
(no automaton, no information states, no chain); the returned controller asked for its
action after replaying each observation history, nature maximising against it (the
enumeration of tests/test_sensed_band.py, nature on the robot's side); the fully
observed optimistic answer (the robust route); the worst-case answer; Storm on the
exported chain."""

from __future__ import annotations

import importlib.util
import json
from fractions import Fraction
from pathlib import Path
from typing import Any

import pytest
from test_sensed_band import GAME, worst_over_nature
from test_sensed_band import model as bus_model

from mitld_lp import ExplicitGame, Model, synthesize
from mitld_lp.controllers.observation import Observation
from mitld_lp.distributions import from_table
from mitld_lp.problem import ProblemError
from mitld_lp.sensing import Sensor

# a robot in "mid" goes to "sa" (A) or waits; from "sa" it must pass "trap" before it is
# back: a round of 3 steps, so it cannot be at A in every window of two steps, and the
# event's report tells it when to go (the world of tests/test_sensed_band.py, no slip)
TINY = ExplicitGame(initial="mid", labels={"sa": {"A"}}, transitions={
    "mid": {"go": {"sa": 1.0}, "wait": {"mid": 1.0}}, "sa": {"back": {"trap": 1.0}},
    "trap": {"back": {"mid": 1.0}}})
H = 3
SPECS = {"max": f"D[mu] b & F[0,{H}] (b & F[0,1] A)",  # b at k <= H, then A at k or k + 1
         "min": f"D[mu] b & F[0,{H}] (b & !A)"}  # b at k <= H while the robot is not at A

History = tuple[tuple[str, frozenset[str]], ...]


def tiny(band: tuple[str, str], detect: str, objective: str) -> Model:
    law = from_table({"geometric": [float(band[0]), float(band[1])]}, "mu")
    return Model.from_game(TINY, SPECS[objective], objective=objective,
                           distributions={"mu": law}, sensors={"b": Sensor(float(detect))})


def holds(objective: str, t: int, state: str, k: int | None) -> bool | None:
    """The task's verdict at step ``t`` in ``state`` with the event at step ``k`` (None:
    not yet), or None while undecided (the formulas of :data:`SPECS`, by hand)."""
    at_a = "A" in TINY.propositions(state)
    if objective == "max":
        if k is not None and k <= t <= k + 1 and at_a:
            return True
        return False if (k is None and t >= H) or (k is not None and t >= k + 1) else None
    if k is not None and k == t:
        return not at_a
    return False if k is not None or t >= H else None


def value(act: Any, band: tuple[str, str], detect: str, objective: str) -> Fraction:
    """The task's probability in :data:`TINY` under the robot's ``act`` (an observation
    history to an action), nature picking each step's hazard among the band's ends after
    seeing everything, to the robot's advantage (the greatest for a maximum, the least for
    a minimum)."""
    d, ends = Fraction(detect), tuple(Fraction(x) for x in band)
    pick = max if objective == "max" else min

    def go(t: int, state: str, k: int | None, reported: bool, seen: History) -> Fraction:
        verdict = holds(objective, t, state, k)
        if verdict is not None:
            return Fraction(int(verdict))
        action = act(seen)
        values = []
        for h in (ends if k is None else (None,)):
            v = Fraction(0)
            comes = [(t + 1, h), (None, 1 - h)] if k is None else [(k, Fraction(1))]
            for k2, pe in comes:
                told = ([(True, d), (False, 1 - d)] if k2 is not None and not reported
                        else [(reported, Fraction(1))])
                for now, pr in told:
                    if pe * pr == 0:
                        continue
                    reports = frozenset({"b"}) if now and not reported else frozenset()
                    for nxt, pw in TINY.successors(state, action, frozenset()):
                        v += pe * pr * Fraction(str(pw)) * go(t + 1, nxt, k2, now,
                                                              (*seen, (nxt, reports)))
            values.append(v)
        return pick(values)

    return go(0, TINY.initial, None, False, ((TINY.initial, frozenset()),))


def plans() -> list[dict[History, str]]:
    """Every observation-based policy of :data:`TINY` up to step ``H``: a decision at each
    observation history ending in ``mid`` that the policy's earlier decisions reach, with
    each way the report can come (once, at most), one plan per way of deciding."""
    def next_choices(seen: History, action: str) -> list[History]:
        out, todo = [], [(seen, action)]
        while todo:
            here, act = todo.pop()
            reported = any(r for _, r in here)
            for nxt, _ in TINY.successors(here[-1][0], act, frozenset()):
                for now in ((False, True) if not reported else (False,)):
                    step = (*here, (nxt, frozenset({"b"}) if now else frozenset()))
                    if len(step) > H + 1:
                        continue
                    if nxt == "mid":
                        out.append(step)
                    else:
                        todo.append((step, "back"))
        return out

    def grow(frontier: list[History]) -> list[dict[History, str]]:
        if not frontier:
            return [{}]
        seen, rest = frontier[0], frontier[1:]
        return [{seen: a, **p} for a in ("go", "wait")
                for p in grow(rest + next_choices(seen, a))]

    return grow([((TINY.initial, frozenset()),)])


def brute_optimum(band: tuple[str, str], detect: str, objective: str) -> Fraction:
    """The best over every observation-based policy (:func:`plans`) of its value with
    nature on the robot's side."""
    pick = max if objective == "max" else min
    return pick(value(lambda seen, p=plan: p.get(seen, "back"), band, detect, objective)
                for plan in plans())


def of_controller(controller: Any) -> Any:
    """The controller as an observation history's action (replayed from its start)."""
    def act(seen: History) -> str:
        controller.reset()
        action = controller.act(Observation(seen[0][0]))
        for state, reports in seen[1:]:
            action = controller.act(Observation(state, reports=reports))
        return action
    return act


CASES = [(("0.2", "0.7"), "0.5"), (("0.1", "0.9"), "0.3"), (("0.4", "0.6"), "0")]


@pytest.mark.parametrize("objective", ["max", "min"])
@pytest.mark.parametrize("band, detect", CASES)
def test_the_bracket_holds_the_brute_force_optimum(band, detect, objective) -> None:
    r = synthesize(tiny(band, detect, objective), bands="best")
    assert r.route == "sensed" and r.part.reading == "best" and r.bands
    brute = brute_optimum(band, detect, objective)
    assert Fraction(r.lower) <= brute <= Fraction(r.upper)
    # the returned controller reaches the controller's end of the bracket with nature's
    # help: lower for a maximum, upper for a minimum (up to the iteration's stop)
    own = value(of_controller(r.controller), band, detect, objective)
    near = Fraction(r.lower if objective == "max" else r.upper)
    assert abs(own - near) <= Fraction(1, 10**9)
    assert (own >= near) if objective == "max" else (own <= near)
    # honest: certified only when the gap, less the truncation's, is within the precision
    rest = r.upper - r.lower - r.width["truncation"]
    assert r.certified == (rest <= r.precision * (r.lower if objective == "max" else
                                                  1 - r.upper))


@pytest.mark.parametrize("objective", ["max", "min"])
def test_between_the_worst_case_and_the_fully_observed_best_case(objective) -> None:
    """The worst-case answer's controller end is below (for a minimum above) the best
    case's; the fully observed optimistic answer (a perfect sensor: the robust route)
    bounds it."""
    band, detect = ("0.2", "0.7"), "0.5"
    m = tiny(band, detect, objective)
    best, worst = synthesize(m, bands="best"), synthesize(m)
    seen = synthesize(tiny(band, "1", objective), bands="best")
    assert seen.route == "robust" and worst.route == "sensed"
    if objective == "max":
        assert worst.lower <= best.lower and best.upper <= seen.upper + 1e-12
    else:
        assert worst.upper >= best.upper and best.lower >= seen.lower - 1e-12


def test_the_controllers_best_case_on_the_bus_world() -> None:
    """tests/test_sensed_band.py's world and its enumeration of nature's choices, nature
    maximising against the returned controller: it is ``lower``."""
    for band, detect in ((("0.3", "0.6"), "0.6"), (("0.1", "0.9"), "0.5")):
        r = synthesize(bus_model([float(band[0]), float(band[1])], float(detect)),
                       bands="best")
        best = worst_over_nature(r.controller, *band, detect, pick=max, game=GAME)
        assert Fraction(r.lower) <= best <= Fraction(r.lower) + Fraction(1, 10**9)


@pytest.mark.skipif(importlib.util.find_spec("stormpy") is None, reason="needs stormpy")
@pytest.mark.parametrize("objective", ["max", "min"])
def test_storm_on_the_exported_chain_gives_the_claim(tmp_path: Path, objective) -> None:
    from test_robust_optimistic import storm_exact

    from mitld_lp.files import drn
    from mitld_lp.running.chain import chain_drn, chain_of
    from mitld_lp.running.optimistic_chain import optimistic_claim

    r = synthesize(tiny(("0.2", "0.7"), "0.5", objective), bands="best")
    path = drn.write(chain_drn(chain_of(r)), tmp_path / "c.drn")
    value_ = storm_exact(path)  # a plain chain, read in exact arithmetic
    claim, _ = optimistic_claim(r)
    assert Fraction(claim) <= value_ <= Fraction(claim) + Fraction(1, 10**9)


@pytest.mark.skipif(importlib.util.find_spec("stormpy") is None, reason="needs stormpy")
def test_the_command_line_solves_and_exports(tmp_path: Path, capsys) -> None:
    from test_robust_optimistic import storm_exact

    from mitld_lp.cli import main

    path = tmp_path / "wait.toml"
    path.write_text('name = "wait_for_b"\nspec = "D[mu] b & F[0,2] (b & F[0,1] A)"\n'
                    "grid = { size = [2, 2], start = [0, 0] }\nregions = { A = [[1, 1]] }\n"
                    "distributions = { mu = { geometric = [0.3, 0.6] } }\n"
                    "[sensors]\nb = { detect = 0.5 }\n")
    code = main(["solve", str(path), "--bands", "best"])
    out = capsys.readouterr().out
    assert code in (0, 3) and "optimum in:" in out and "Pmaxmax" in out
    assert ("certified:    yes" in out) == (code == 0)
    code = main(["solve", str(path), "--bands", "best", "--json"])
    said = json.loads(capsys.readouterr().out)
    assert said["bands_reading"] == "best" and said["band_best"]["chain_states"] > 0
    worst = main(["solve", str(path), "--json"])
    assert worst in (0, 3)
    assert json.loads(capsys.readouterr().out)["lower"] <= said["lower"]
    out_chain = tmp_path / "c.drn"
    assert main(["export", str(path), "--bands", "best", "--chain", str(out_chain),
                 "--json"]) == code
    exported = json.loads(capsys.readouterr().out)
    assert exported["chain_accept"] == said["lower"]
    assert Fraction(said["lower"]) <= storm_exact(out_chain) <= Fraction(said["upper"])


def test_constraints_with_a_sensor_and_the_best_law_are_refused_by_name() -> None:
    with pytest.raises(ProblemError, match="bands 'best' with constraints and sensors"):
        synthesize(tiny(("0.2", "0.7"), "0.5", "max"), bands="best",
                   constraints=["P(F[0,2] A) <= 0.9"])
