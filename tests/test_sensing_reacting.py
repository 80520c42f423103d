"""A camera on an event the world's moves react to (issue 43; the ``sensed-reacting``
route, :mod:`mitld_lp.sensing.reacting`): the robot reads the event from its sensor's
reports *and* from the world's moves, which differ when the event happens.

Independent routes: an exhaustive expectimax over observation histories written here in
exact arithmetic (hidden scenarios of the event's step and its first report; the world
moved by its own table under each scenario's events; the task judged on the trace -- no
automaton, no hazards, no information states, no posterior), both objectives, with and
without a delay; Storm on the exported controlled chain (exactly, ``stormpy.Rational``);
the ``sensed`` route on the same world with the reaction removed (when the reaction is
invisible); the fully observed (plain) route with a perfect sensor (when the world's move
reveals the event fully)."""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable
from fractions import Fraction
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mitld_lp import ExplicitGame, Model, ProblemError, synthesize
from mitld_lp.automata.translate import to_dta
from mitld_lp.distributions import pmf
from mitld_lp.product import ProductTooLarge
from mitld_lp.sensing.belief import belief_product
from mitld_lp.sensing.reacting import reacting_events, reacting_product

# a robot between a station (A) and a ditch (h, absorbing); the event b (a bus) makes
# the world move by REACT's rows instead of BASE's, and raises an observable flag ("!")
# with probability ``show``
BASE = {
    "mid": {"go": {"st": 0.8, "ditch": 0.2}, "wait": {"mid": 0.5, "st": 0.5}},
    "st": {"wait": {"st": 0.5, "ditch": 0.5}, "back": {"mid": 0.8, "ditch": 0.2}},
    "ditch": {"stay": {"ditch": 1.0}},
}
REACT = {
    "mid": {"go": {"st": 1.0}, "wait": {"mid": 0.2, "st": 0.8}},
    "st": {"wait": {"st": 0.9, "ditch": 0.1}, "back": {"mid": 0.5, "ditch": 0.5}},
    "ditch": {"stay": {"ditch": 1.0}},
}
PMF = ("0.3", "0.3", "0.4")  # the bus comes at step 1, 2 or 3
LAW = f"D[pmf({', '.join(PMF)})] b & "
CAUGHT = "F(b & F[0,1] A)"  # at the station the step the bus comes or the next
AVOID = "G !(b & A)"  # never at the station the step the bus comes


def world(show: float, react: dict[str, Any] = REACT) -> ExplicitGame:
    """The world: states ``loc`` and ``loc!`` (the flag raised); under ``b`` the rows
    of ``react``, the flag raised with probability ``show``."""
    transitions, overrides, labels = {}, {}, {}
    for loc, flag in itertools.product(BASE, ("", "!")):
        s = loc + flag
        labels[s] = {"st": {"A"}, "ditch": {"h"}}.get(loc, set())
        transitions[s] = {a: {n + flag: p for n, p in row.items()}
                          for a, row in BASE[loc].items()}
        for a, row in react[loc].items():
            out: dict[str, float] = {}
            for n, p in row.items():
                for f, q in (("!", show), (flag, 1.0 - show)):
                    if p * q > 0:
                        out[n + f] = out.get(n + f, 0.0) + p * q
            overrides[(s, a, frozenset({"b"}))] = out
    return ExplicitGame(initial="mid", transitions=transitions, labels=labels,
                        event_transitions=overrides)


def model(game: ExplicitGame, task: str, detect: float, delay: int = 0,
          masses: tuple[str, ...] = PMF) -> Model:
    sensors = {"b": {"detect": detect, "delay": delay}}
    if task == CAUGHT:
        return Model.from_game(game, f"D[pmf({', '.join(masses)})] b & " + task,
                               sensors=sensors)
    return Model.from_game(game, task, events={"b": pmf([float(x) for x in masses])},
                           sensors=sensors)


# ------------------------------------------------------------------ the expectimax


def optimum(game: ExplicitGame, task: str, detect: str, delay: int, sense: Callable[..., Any],
            masses: tuple[str, ...] = PMF) -> Fraction:
    """The best (``sense=min``: the worst) probability of ``task`` over the policies that
    see the world's state and the sensor's reports of each step, never the bus: every
    scenario ``(k, r)`` (the bus at step ``k``, first reported at step ``r``, None for
    not by the horizon) followed through the world's table moved on the events of each
    step, grouped by what the robot observes, the task judged on the trace; the mass
    ``masses`` leave is the bus never coming (``k`` None)."""
    d = Fraction(detect)
    horizon = len(masses) + 1  # every scenario is decided by then (the window is one step)
    scenarios: list[Any] = [((None, None), 1 - sum(map(Fraction, masses)))]
    for k, mu in enumerate(map(Fraction, masses), start=1):
        for r in range(k + delay, horizon + 1):
            scenarios.append(((k, r), mu * d * (1 - d) ** (r - k - delay)))
        scenarios.append(((k, None), mu * (1 - d) ** max(0, horizon - k - delay + 1)))

    def holds(trace: tuple[str, ...], k: int | None) -> bool:
        at = ["A" in game.propositions(s) for s in trace]
        if k is None:
            return task != CAUGHT
        return any(at[k:k + 2]) if task == CAUGHT else not at[k]

    @cache
    def value(trace: tuple[str, ...], alive: tuple[Any, ...]) -> Fraction:
        t = len(trace) - 1
        if t == horizon:
            return sum((p for (k, _), p in alive if holds(trace, k)), Fraction(0))
        values = []
        for action in game.actions(trace[-1]):
            seen: dict[tuple[str, bool], list[Any]] = {}
            for (k, r), p in alive:
                events = frozenset({"b"}) if k == t + 1 else frozenset()
                for nxt, pw in game.successors(trace[-1], action, events):
                    seen.setdefault((nxt, r == t + 1), []).append(
                        ((k, r), p * Fraction(str(pw))))
            values.append(sum((value((*trace, nxt), tuple(group))
                               for (nxt, _), group in seen.items()), Fraction(0)))
        return sense(values)

    return value((game.initial,), tuple(x for x in scenarios if x[1] > 0))


def within(r: Any, exact: Fraction) -> None:
    """The certified bracket holds the exact value, compared as fractions."""
    assert r.certified, [c for c in r.checks if not c.passed]
    assert Fraction(r.lower) <= exact <= Fraction(r.upper), (r.lower, float(exact), r.upper)
    assert r.upper - r.lower <= 1e-9


CASES = [(task, objective, detect, delay) for task in (CAUGHT, AVOID)
         for objective in ("max", "min") for detect, delay in (("0.5", 0), ("0.6", 1))]


@pytest.mark.parametrize("task, objective, detect, delay", CASES)
def test_the_answer_is_the_expectimax_over_observation_histories(
        task: str, objective: str, detect: str, delay: int) -> None:
    game = world(0.5)
    r = synthesize(model(game, task, float(detect), delay), objective=objective)
    assert r.route == "sensed-reacting"
    within(r, optimum(game, task, detect, delay, max if objective == "max" else min))


def reach_max(belief: Any, steps: int = 200) -> float:
    """The greatest probability of reaching the target of ``belief``'s MDP, by value
    iteration (its states past the task's horizon only loop)."""
    mdp = belief.mdp
    v = mdp.target.astype(float)
    starts = mdp.row_groups[:-1]
    for _ in range(steps):
        v = np.maximum.reduceat(mdp.matrix @ v, starts)
        v[mdp.target] = 1.0
    return float(v[mdp.initial])


@pytest.mark.parametrize("task", [CAUGHT, AVOID])
def test_a_law_that_may_never_happen(task: str) -> None:
    """The bus never comes with probability 0.4: "never" is a hypothesis of its own,
    weighed against "came, missed since" by the reports and by the world's moves; the
    bracket holds the expectimax and is no wider than the truncation's epsilon."""
    game, masses = world(0.5), ("0.3", "0.3")
    m = model(game, task, 0.5, masses=masses)
    for objective, sense in (("max", max), ("min", min)):
        r = synthesize(m, objective=objective)
        exact = optimum(game, task, "0.5", 0, sense, masses)
        assert r.route == "sensed-reacting" and r.certified
        assert Fraction(r.lower) <= exact <= Fraction(r.upper)
        assert r.upper - r.lower <= m.epsilon


def test_the_world_s_reaction_changes_the_optimum() -> None:
    """The example is not degenerate: the information-state product that reads the
    world's moves without the sensed event (the fast builder's) answers another problem,
    as do a blind robot and one that sees the bus; the reacting product's own value, by
    value iteration here, is the expectimax's."""
    game = world(0.5)
    exact = optimum(game, CAUGHT, "0.5", 0, max)
    m = model(game, CAUGHT, 0.5)
    args = (game, to_dta(m.spec), m.distributions, dict(m.sensors), m.epsilon)
    ignoring = belief_product(*args, max_states=10**5)
    assert abs(Fraction(reach_max(ignoring)) - exact) > Fraction(1, 100)
    assert abs(Fraction(reach_max(reacting_product(*args, max_states=10**5))) - exact) \
        < Fraction(1, 10**9)
    assert optimum(game, CAUGHT, "0", 0, max) < exact < optimum(game, CAUGHT, "1", 0, max)


# ------------------------------------------------------------------ the two limits


@pytest.mark.parametrize("objective", ["max", "min"])
def test_an_invisible_reaction_is_the_sensed_route_s_answer(objective: str) -> None:
    """A world that declares the reaction but moves alike under both (its rows the same,
    no flag) is the world that ignores the event: the reacting route's answer is the
    ``sensed`` route's on the same tables without the reaction, and both the
    expectimax's."""
    sense = max if objective == "max" else min
    same = world(0.0, BASE)
    plain = dataclasses.replace(same, event_transitions={})
    assert reacting_events(same, {"b"}) == {"b"} and not reacting_events(plain, {"b"})
    reacting = synthesize(model(same, CAUGHT, 0.5), objective=objective)
    ignoring = synthesize(model(plain, CAUGHT, 0.5), objective=objective)
    assert (reacting.route, ignoring.route) == ("sensed-reacting", "sensed")
    exact = optimum(plain, CAUGHT, "0.5", 0, sense)
    within(reacting, exact)
    within(ignoring, exact)
    assert abs(reacting.lower - ignoring.lower) <= 1e-9


@pytest.mark.parametrize("objective", ["max", "min"])
def test_a_reaction_that_reveals_the_event_is_a_perfect_sensor(objective: str) -> None:
    """A world whose every move under the bus raises the flag tells the robot the step
    the bus comes: the camera that misses adds nothing, and the answer is the fully
    observed one (the ``plain`` route, ``detect = 1``)."""
    sense = max if objective == "max" else min
    shown = world(1.0)
    camera = synthesize(model(shown, CAUGHT, 0.5, delay=1), objective=objective)
    seen = synthesize(model(shown, CAUGHT, 1.0), objective=objective)
    assert (camera.route, seen.route) == ("sensed-reacting", "plain")
    exact = optimum(shown, CAUGHT, "1", 0, sense)
    within(camera, exact)
    within(seen, exact)
    if objective == "max":  # the flag is what tells: without it the camera does worse
        assert optimum(world(0.0), CAUGHT, "0.5", 1, max) < exact


# ------------------------------------------------------------------ downstream


stormpy = pytest.importorskip("stormpy")


def storm_exact(path: Path) -> Fraction:
    """Storm's exact ``P=? [F "accept"]`` on the DRN at ``path``."""
    m = stormpy.build_model_from_drn[stormpy.Rational](str(path))
    result = stormpy.model_checking(m, stormpy.parse_properties('P=? [F "accept"]')[0])
    return Fraction(str(result.get_value(m.initial_states[0])))


@pytest.mark.parametrize("delay", [0, 1])
def test_storm_on_the_exported_chain_gives_the_optimum(delay: int, tmp_path: Path) -> None:
    """The controlled chain over the true world, events and reports and the controller's
    memory (built from the dynamics, the world moved on the true events) is the
    controller's value: Storm gives the expectimax (the controller is optimal, nothing
    truncated), inside the bracket; the controller loaded from its file, the decision
    tree run as a controller and ``mitld_lp.runtime`` act alike."""
    from mitld_lp.controllers.kinds import load_controller
    from mitld_lp.running.chain import chain_drn, chain_of, write_chain
    from mitld_lp.running.tree import tree_controller, tree_of

    game = world(0.5)
    r = synthesize(model(game, CAUGHT, 0.6, delay))
    exact = optimum(game, CAUGHT, "0.6", delay, max)
    value = storm_exact(write_chain(r, tmp_path / "own.drn"))
    assert Fraction(r.lower) <= value <= Fraction(r.upper)
    assert abs(value - exact) <= Fraction(1, 10**9)
    saved = r.controller.save(tmp_path / "c.npz")
    loaded = load_controller(saved)
    assert storm_exact(write_chain(r, tmp_path / "file.drn", controller=loaded)) == value
    tree = chain_of(r, tree_controller(r, tree_of(r)))
    from mitld_lp.files import drn

    drn.write(chain_drn(tree), tmp_path / "tree.drn")
    assert storm_exact(tmp_path / "tree.drn") == value
    _runtime_acts_alike(game, r.controller, saved)


def _runtime_acts_alike(game: ExplicitGame, controller: Any, saved: Path) -> None:
    """``mitld_lp.runtime`` (what ``mitld-lp run`` serves) on the saved file gives the
    synthesised controller's action on every observation history of a few runs."""
    from mitld_lp.controllers.observation import Observation
    from mitld_lp.runtime import load
    from mitld_lp.util.rollouts import sample_successor

    robot = load(saved)
    rng = np.random.default_rng(3)
    for _ in range(40):
        k = int(rng.choice([1, 2, 3], p=[0.3, 0.3, 0.4]))
        report = k + int(rng.geometric(0.6)) - 1
        controller.reset()
        robot.reset()
        s, reports = game.initial, frozenset()
        for t in range(6):
            action = controller.act(Observation(s, reports=reports))
            assert robot.act(s, reports=reports) == action
            if action is None:
                break
            events = frozenset({"b"}) if t + 1 == k else frozenset()
            s = sample_successor(rng, game.successors(s, action, events))
            reports = frozenset({"b"}) if t + 1 == report else frozenset()


# ------------------------------------------------------------------ budgets, refusals


def test_the_budget_stops_the_build_before_it_passes() -> None:
    m = model(world(0.5), CAUGHT, 0.5)
    with pytest.raises(ProductTooLarge, match="more than 12 states"):
        reacting_product(m.game, to_dta(m.spec), m.distributions, dict(m.sensors), m.epsilon,
                         max_states=12)
    with pytest.raises(ProductTooLarge):
        synthesize(m, max_states=12)


def test_a_band_or_a_constraint_with_a_reacting_world_is_refused_by_name() -> None:
    from mitld_lp.distributions import from_table

    game = world(0.5)
    band = Model.from_game(game, "D[mu] b & " + CAUGHT, sensors={"b": {"detect": 0.5}},
                           distributions={"mu": from_table({"geometric": [0.3, 0.6]}, "mu")})
    with pytest.raises(ProblemError, match=r"react to \(b, event_names\) with a law known "
                                           r"only within a band"):
        synthesize(band)
    with pytest.raises(ProblemError, match="react to the sensed event 'b'"):
        synthesize(band, bands="best")
    for extra in ({"constraints": ["P(F h) <= 0.5"]}, {"then": "min-steps"}):
        with pytest.raises(ProblemError, match="react to the sensed event 'b'"):
            synthesize(model(game, CAUGHT, 0.5), **extra)


def test_a_prism_door_that_shows_its_opening_is_a_perfect_sensor() -> None:
    """models/corridor.toml: the PRISM world's event action ``opened`` sets the door's
    variable, which the robot observes: a camera on ``opened`` that misses adds nothing,
    and the answer is the fully observed one (the ``plain`` route on the same file)."""
    pytest.importorskip("stormpy")
    from types import MappingProxyType

    from mitld_lp import load_model
    from mitld_lp.sensing import Sensor

    base = load_model(Path(__file__).resolve().parents[1] / "models" / "corridor.toml")
    camera = dataclasses.replace(base, sensors=MappingProxyType({"opened": Sensor(0.5)}))
    seen, r = synthesize(base), synthesize(camera)
    assert (r.route, seen.route) == ("sensed-reacting", "plain") and r.certified
    assert abs(r.lower - seen.lower) <= 1e-9 and abs(r.upper - seen.upper) <= 1e-9
