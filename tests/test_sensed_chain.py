"""The controlled chain of a controller that acts on sensor reports (issue 43, sensed
answers exportable and re-checkable): Storm reads the exported DRN exactly
(``build_model_from_drn[stormpy.Rational]``) and its ``P=? [F "accept"]`` lies inside the
certified bracket, at least ``lower``, compared as fractions with no tolerance.

Independent routes: Storm on the file; and, on a small world written here, an
enumeration of observation histories in exact arithmetic (hidden scenarios of event
steps and first reports, the world's branches, the task judged on the trace -- no
automaton, no hazards, no information states): the best value over every
observation-based policy (an expectimax) and the value of the synthesised controller
itself, run on each history.  The chain's value equals the controller's to 1e-12 (the
DRN holds the floats' shortest decimals, so its exact value differs from the
controller's by rounding alone)."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
from fractions import Fraction
from pathlib import Path
from types import MappingProxyType
from typing import Any

import pytest

from mitld_lp import ExplicitGame, Model, load_model, synthesize
from mitld_lp.cli import main
from mitld_lp.controllers.kinds import load_controller
from mitld_lp.controllers.observation import Observation
from mitld_lp.running.chain import chain_of, write_chain
from mitld_lp.running.tree import tree_of
from mitld_lp.sensing import Sensor

stormpy = pytest.importorskip("stormpy")

MODELS = Path(__file__).resolve().parent.parent / "models"

GAME = ExplicitGame(
    initial="mid",
    transitions={
        "mid": {"to_a": {"sa": 0.75, "mid": 0.25}, "to_b": {"sb": 0.75, "mid": 0.25},
                "wait": {"mid": 1.0}},
        "sa": {"back": {"mid": 0.5, "sa": 0.5}, "wait": {"sa": 1.0}},
        "sb": {"back": {"mid": 0.5, "sb": 0.5}, "wait": {"sb": 1.0}},
    },
    labels={"sa": {"A"}, "sb": {"B"}},
)
PMF1, PMF2 = ("0.5", "0.25", "0.25"), ("0.25", "0.5", "0.25")
SPEC = (f"(D[pmf({', '.join(PMF1)})] b1 & F(b1 & F[0,1] A)) | "
        f"(D[pmf({', '.join(PMF2)})] b2 & F(b2 & F[0,1] B))")


def storm_exact(path: Path) -> Fraction:
    """Storm's exact ``P=? [F "accept"]`` on the DRN at ``path``."""
    model = stormpy.build_model_from_drn[stormpy.Rational](str(path))
    assert "DTMC" in str(model.model_type)
    result = stormpy.model_checking(model, stormpy.parse_properties('P=? [F "accept"]')[0])
    return Fraction(str(result.get_value(model.initial_states[0])))


def histories(game: ExplicitGame, events: list[tuple[Any, ...]], horizon: int,
              controller: Any = None) -> Fraction:
    """The probability that for some event ``i`` (step ``k_i``) the robot is at
    ``goal_i`` at a step in ``[k_i, k_i + window_i]``, the robot seeing the world state
    and the sensors' reports only.  ``events``: ``(pmf, detect, delay, goal, window)``
    as decimal texts.  Without ``controller``: the best over every observation-based
    policy (max over actions per history); with it: the controller's own actions, asked
    of it after replaying each history's observations."""
    per_event = []
    for pmf, detect, delay, *_ in events:
        d = Fraction(detect)
        options = []
        for k, mu in enumerate(map(Fraction, pmf), start=1):
            for r in range(k + delay, horizon + 1):  # the first report at step r
                options.append((k, r, mu * d * (1 - d) ** (r - k - delay)))
            options.append((k, None, mu * (1 - d) ** max(0, horizon - k - delay + 1)))
        per_event.append([o for o in options if o[2] > 0])
    scenarios = [(tuple((k, r) for k, r, _ in combo), math.prod(p for _, _, p in combo))
                 for combo in itertools.product(*per_event)]

    def caught(t: int, state: str, times: tuple[Any, ...]) -> bool:
        return any(k <= t <= k + e[4] and e[3] in game.propositions(state)
                   for (k, _), e in zip(times, events, strict=True))

    def open_(t: int, times: tuple[Any, ...]) -> bool:
        return any(t < k + e[4] for (k, _), e in zip(times, events, strict=True))

    def act(seen: list[tuple[str, frozenset[str]]]) -> list[str]:
        if controller is None:
            return list(game.actions(seen[-1][0]))
        controller.reset()
        action = controller.act(Observation(seen[0][0]))
        for state, reports in seen[1:]:
            action = controller.act(Observation(state, reports=reports))
        return [] if action is None else [action]

    def best(t: int, seen: list[tuple[str, frozenset[str]]], alive: list[Any]) -> Fraction:
        state = seen[-1][0]
        won = sum((p for times, p in alive if caught(t, state, times)), Fraction(0))
        left = [(times, p) for times, p in alive
                if not caught(t, state, times) and open_(t, times)]
        if t == horizon or not left:
            return won
        values = [Fraction(0)]
        for action in act(seen):
            v = Fraction(0)
            for nxt, ps in game.successors(state, action, frozenset()):
                groups: dict[frozenset[str], list[Any]] = {}
                for times, p in left:  # what the robot observes: the reports of the step
                    reports = frozenset(f"b{i + 1}" for i, (_, r) in enumerate(times)
                                        if r == t + 1)
                    groups.setdefault(reports, []).append((times, p * Fraction(str(ps))))
                v += sum(best(t + 1, [*seen, (nxt, reports)], group)
                         for reports, group in groups.items())
            values.append(v)
        return won + max(values)

    return best(0, [(game.initial, frozenset())], scenarios)


@pytest.mark.parametrize("s1, s2", [((0.5, 0), (0.75, 1)), ((0.0, 0), (0.5, 0))])
def test_the_chain_is_the_controllers_value_over_observation_histories(s1, s2,
                                                                        tmp_path) -> None:
    sensors = {"b1": {"detect": s1[0], "delay": s1[1]}, "b2": {"detect": s2[0],
                                                            "delay": s2[1]}}
    r = synthesize(Model.from_game(GAME, SPEC, sensors=sensors))
    assert r.route == "sensed" and r.certified
    events = [(PMF1, str(s1[0]), s1[1], "A", 1), (PMF2, str(s2[0]), s2[1], "B", 1)]
    horizon = 3 + 1 + max(s1[1], s2[1])
    best = histories(GAME, events, horizon)
    own = histories(GAME, events, horizon, controller=load_controller(
        r.controller.save(tmp_path / "c.npz")))
    assert Fraction(r.lower) <= best <= Fraction(r.upper)
    assert abs(own - best) <= 1e-9  # the controller is optimal (nothing is truncated)
    chain = storm_exact(write_chain(r, tmp_path / "c.drn"))
    assert abs(chain - own) <= Fraction(1, 10**12)
    assert Fraction(r.lower) <= chain <= Fraction(r.upper)


def test_the_example_is_not_degenerate() -> None:
    """The sensors change the optimum (blind < these sensors < perfect), so a chain that
    let the controller see the events, or see nothing, would give another value."""
    def value(d1: str, d2: str) -> Fraction:
        return histories(GAME, [(PMF1, d1, 0, "A", 1), (PMF2, d2, 0, "B", 1)], 4)

    assert value("0", "0") < value("0.5", "0.75") < value("1", "1")


def bus_camera(sensor: Sensor) -> Any:
    m = load_model(MODELS / "bus_grid.toml")
    return dataclasses.replace(m, sensors=MappingProxyType({"b1": sensor}))


@pytest.mark.parametrize("sensor", [Sensor(0.5), Sensor(0.7, delay=1)], ids=str)
def test_storm_on_the_bus_cases_chain_is_inside_the_bracket(sensor, tmp_path) -> None:
    """The bus case with a camera that misses bus 1 (a geometric law, truncated: the
    truncated runs lose in the chain, as ``lower`` counts them); the chain of the
    controller loaded from its file is the same chain."""
    r = synthesize(bus_camera(sensor))
    assert r.route == "sensed" and r.certified and r.lower < r.upper
    value = storm_exact(write_chain(r, tmp_path / "live.drn"))
    assert Fraction(r.lower) <= value <= Fraction(r.upper)
    loaded = load_controller(r.controller.save(tmp_path / "c.npz"))
    again = chain_of(r, loaded)
    assert again.n_states == chain_of(r).n_states
    assert storm_exact(write_chain(r, tmp_path / "file.drn", controller=loaded)) == value
    assert not any("beyond" in x for x in again.labels)


def test_the_chains_states_say_the_truth_and_the_memory(tmp_path) -> None:
    r = synthesize(bus_camera(Sensor(0.5)))
    text = write_chain(r, tmp_path / "b.drn").read_text()
    assert "@type: DTMC" in text and "state 0 init" in text
    assert "//[x=0 & y=0 & q=" in text and "& pending={b1,b2} & clock=0 & unreported={} & " \
        "memory=" in text
    assert "unreported={b1:0}" in text  # a bus come and not yet reported


def test_a_controller_of_other_sensors_is_refused() -> None:
    r, other = (synthesize(Model.from_game(GAME, SPEC, sensors={b: {"detect": 0.5}}))
                for b in ("b1", "b2"))
    with pytest.raises(ValueError, match="not a controller of this model's sensors"):
        chain_of(r, other.controller)


def test_export_chain_and_tree_from_the_command_line(tmp_path, capsys) -> None:
    model = tmp_path / "camera.toml"
    model.write_text((MODELS / "bus_grid.toml").read_text()
                     + "\n[sensors]\nb1 = { detect = 0.5 }\n")
    out = tmp_path / "camera.drn"
    assert main(["export", str(model), "--chain", str(out)]) == 0
    line = capsys.readouterr().out
    assert 'P=? [F "accept"] >= lower' in line
    lower = synthesize(load_model(model)).lower
    assert storm_exact(out) >= Fraction(lower)
    tree = tmp_path / "camera.json"  # a finite-memory controller (tests/test_sensed_tree.py)
    assert main(["export", str(model), "--tree", str(tree), "-q"]) == 0
    assert "memory" in json.loads(tree.read_text())
    assert tree_of(synthesize(load_model(model))).memory is not None
