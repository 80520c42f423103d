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
from storm_exact import exact_fraction
from test_sensed_band import GAME, worst_over_nature
from test_sensed_band import model as bus_model

from mitld_lp import ExplicitGame, Model, synthesize
from mitld_lp.controllers.observation import Observation
from mitld_lp.distributions import from_table
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


def value(act: Any, band: tuple[str, str], detect: str, objective: str,
          verdict: Any = holds) -> Fraction:
    """The task's probability in :data:`TINY` under the robot's ``act`` (an observation
    history to an action), nature picking each step's hazard among the band's ends after
    seeing everything, to the robot's advantage (the greatest for a maximum, the least for
    a minimum); ``verdict``: the formula's (default the task's, :func:`holds`)."""
    d, ends = Fraction(detect), tuple(Fraction(x) for x in band)
    pick = max if objective == "max" else min

    def go(t: int, state: str, k: int | None, reported: bool, seen: History) -> Fraction:
        said = verdict(objective, t, state, k)
        if said is not None:
            return Fraction(int(said))
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
    return pick(value(follow(plan), band, detect, objective) for plan in plans())


def follow(plan: dict[History, str]) -> Any:
    """The plan as an observation history's action ("back" where it has no decision)."""
    return lambda seen: plan.get(seen, "back")


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


def visits_a(objective: str, t: int, state: str, k: int | None) -> bool | None:
    """``F[0,H] A`` (the constraints' formula below): the robot at A by step ``H``."""
    if "A" in TINY.propositions(state):
        return True
    return False if t >= H else None


def at_law(act: Any, h: str, detect: str, objective: str, verdict: Any) -> Fraction:
    """The probability of ``verdict`` (a task's, :func:`holds` or :func:`visits_a`) under
    the robot's ``act`` with the band at the constant law of hazard ``h``."""
    return value(act, (h, h), detect, objective, verdict)


def storm_of(path: Path) -> Any:
    """Storm's exact ``P=? [F "label"]`` on the plain chain at ``path``, by label."""
    import stormpy

    chain = stormpy.build_model_from_drn[stormpy.Rational](str(path))

    def storm(label: str) -> Fraction:
        got = stormpy.model_checking(chain, stormpy.parse_properties(f'P=? [F "{label}"]')[0])
        return exact_fraction(got.get_value(chain.initial_states[0]))
    return storm


CONSTRAINED = {"max": ("P(F[0,3] A) <= 0.5", "<="), "min": ("P(F[0,3] A) >= 0.5", ">=")}


@pytest.mark.parametrize("objective", ["max", "min"])
def test_constraints_are_met_at_the_law_nature_chose(tmp_path: Path, objective) -> None:
    """With a constraint the answer is a pair (an observation-based controller, a law of
    the band) meeting it at that law: at least as good as every deterministic
    observation-based policy meeting it at one of the band's constant laws tried (the
    middle and the ends, by enumeration in fractions); at most the fully observed
    optimistic constrained bound; Storm on the controller's chain at its law finds the
    task inside the bracket and the constraint met."""
    band, detect = ("0.2", "0.7"), "0.5"
    text, sense = CONSTRAINED[objective]
    r = synthesize(tiny(band, detect, objective), bands="best", constraints=[text])
    assert r.route == "sensed-constrained" and r.summary()["bands_reading"] == "best"
    assert r.status == "optimal" and all(v.holds for v in r.constraints)
    best = None
    for h in ("0.2", "0.45", "0.7"):
        for plan in plans():
            act = follow(plan)
            c = at_law(act, h, detect, objective, visits_a)
            if not (c <= Fraction(1, 2) if sense == "<=" else c >= Fraction(1, 2)):
                continue
            v = at_law(act, h, detect, objective, holds)
            best = v if best is None else (max(best, v) if objective == "max" else
                                           min(best, v))
    assert best is not None
    if objective == "max":  # the randomised optimum at a law tried does at least as well
        assert Fraction(r.lower) >= best - Fraction(1, 10**6) and best <= Fraction(r.upper)
    else:
        assert Fraction(r.upper) <= best + Fraction(1, 10**6) and best >= Fraction(r.lower)
    pytest.importorskip("stormpy")
    from mitld_lp.running.chain import write_chain

    storm = storm_of(write_chain(r, tmp_path / "c.drn"))
    # a minimum's chain is its complement's: "accept" marks the runs that fail the task
    task = storm("accept") if objective == "max" else 1 - storm("accept")
    assert Fraction(r.lower) - Fraction(1, 10**9) <= task <= Fraction(r.upper) + Fraction(
        1, 10**9)
    c1 = storm("c1")
    assert c1 <= Fraction(1, 2) if sense == "<=" else c1 >= Fraction(1, 2)
