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

from mitld_lp import ExplicitGame, Model, synthesize
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
            seen = observed(game, trace[-1], action, t, alive)
            values.append(sum((value((*trace, nxt), tuple(group))
                               for (nxt, _), group in seen.items()), Fraction(0)))
        return sense(values)

    return value((game.initial,), tuple(x for x in scenarios if x[1] > 0))


def observed(game: ExplicitGame, state: str, action: str, t: int, alive: Any
             ) -> dict[tuple[str, bool], list[Any]]:
    """The scenarios ``alive`` (``((k, r), mass)``) after ``action`` from ``state`` at
    step ``t``, the world moved on each one's events of step ``t + 1``, grouped by what
    the robot observes (the next state, a report)."""
    seen: dict[tuple[str, bool], list[Any]] = {}
    for (k, r), p in alive:
        events = frozenset({"b"}) if k == t + 1 else frozenset()
        for nxt, pw in game.successors(state, action, events):
            seen.setdefault((nxt, r == t + 1), []).append(((k, r), p * Fraction(str(pw))))
    return seen


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


# ------------------------------------------------------------------ constraints, then
# (the sensed-constrained route on the reacting product)

RISK = "P(F[0,3] h) <= 0.25"  # in the ditch by step 3: binds on every world below
EXTRAS = [({"constraints": [RISK]}, "risk"), ({"then": "min-steps"}, "then"),
          ({"constraints": [RISK], "then": "min-steps"}, "risk-then")]


# the task and objective of each case; a constraint's value and the steps compared on
# the first only (elsewhere the risk does not bind: optimal policies differ in it)
LIMITS = [(CAUGHT, "max", e) for e, _ in EXTRAS] + [
    (task, objective, {"constraints": [RISK]}) for task, objective in ((AVOID, "max"),
                                                                       (CAUGHT, "min"))]
LIMIT_IDS = [i for _, i in EXTRAS] + ["avoid-max-risk", "caught-min-risk"]


def same_answer(a: Any, b: Any, values: bool) -> None:
    """Two certified answers of one problem: the same bracket and (``values``) the same
    constraint values and expected steps (each an LP's optimum, so to the solvers'
    tolerance)."""
    assert a.certified and b.certified
    assert abs(a.lower - b.lower) <= 1e-8 and abs(a.upper - b.upper) <= 1e-8
    if not values:
        return
    for x, y in zip(a.constraints, b.constraints, strict=True):
        assert abs(x.certified - y.certified) <= 1e-6
    if a.secondary is not None or b.secondary is not None:
        assert abs(a.secondary - b.secondary) <= 1e-6


@pytest.mark.parametrize("task, objective, extra", LIMITS, ids=LIMIT_IDS)
def test_constraints_with_a_revealing_reaction_are_the_fully_observed_answer(
        task: str, objective: str, extra: dict[str, Any]) -> None:
    """The flag raised on every move under the bus: the camera (delayed, missing) adds
    nothing, and the constrained answer is the fully observed constrained route's
    (``detect = 1``: the ``constrained`` route on the fully observed product)."""
    shown = world(1.0)
    camera = synthesize(model(shown, task, 0.5, delay=1), objective=objective, **extra)
    seen = synthesize(model(shown, task, 1.0), objective=objective, **extra)
    assert (camera.route, seen.route) == ("sensed-constrained", "constrained")
    same_answer(camera, seen, (task, objective) == (CAUGHT, "max"))
    blind = synthesize(model(world(0.0), task, 0.5, delay=1), objective=objective, **extra)
    assert abs(blind.lower - camera.lower) > 5e-6  # without the flag: another answer


@pytest.mark.parametrize("task, objective, extra", LIMITS, ids=LIMIT_IDS)
def test_constraints_with_an_invisible_reaction_are_the_sensed_answer(
        task: str, objective: str, extra: dict[str, Any]) -> None:
    """A reaction declared but moving alike (the same rows, no flag): the reacting
    product's constrained answer is the non-reacting sensed-constrained route's."""
    same = world(0.0, BASE)
    plain = dataclasses.replace(same, event_transitions={})
    reacting = synthesize(model(same, task, 0.5), objective=objective, **extra)
    ignoring = synthesize(model(plain, task, 0.5), objective=objective, **extra)
    assert reacting.route == ignoring.route == "sensed-constrained"
    assert reacting_events(same, {"b"}) and not reacting_events(plain, {"b"})
    same_answer(reacting, ignoring, True)


@pytest.mark.parametrize("objective", ["max", "min"])
def test_the_constrained_lp_with_neither_is_the_expectimax(objective: str) -> None:
    """The constrained LP asked with no constraint and no ``then`` (a trade-off curve's
    end) on the reacting product: the expectimax over observation histories."""
    from mitld_lp.synthesis import synthesize_constrained

    game = world(0.5)
    m = dataclasses.replace(model(game, CAUGHT, 0.5, delay=1), objective=objective)
    r = synthesize_constrained(m)
    assert r.route == "sensed-constrained"
    within(r, optimum(game, CAUGHT, "0.5", 1, max if objective == "max" else min))


def history_lp(game: ExplicitGame, detect: str, bound: float) -> float:
    """The greatest probability of ``CAUGHT`` among the randomised policies on
    observation histories keeping ``P(F[0,3] h) <= bound``: an occupancy LP (scipy) over
    the tree of observation histories to the horizon, each node holding the hidden
    scenarios (the bus's step, its report's) that agree with it -- no automaton, no
    information states, no posterior."""
    from scipy.optimize import linprog

    d = Fraction(detect)
    horizon = len(PMF) + 1
    scenarios = []
    for k, mu in enumerate(map(Fraction, PMF), start=1):
        for r in range(k, horizon + 1):
            scenarios.append(((k, r), mu * d * (1 - d) ** (r - k)))
        scenarios.append(((k, None), mu * (1 - d) ** (horizon - k + 1)))
    columns: list[tuple[int, float, float]] = []  # (node, task's mass, risk's mass)
    inflow: list[list[tuple[int, float]]] = []  # per node: (column, its share) into it

    def node(trace: tuple[str, ...], alive: list[Any], into: list[tuple[int, float]]
             ) -> None:
        me = len(inflow)
        inflow.append(into)
        mass = sum(p for _, p in alive)
        t = len(trace) - 1
        if t == horizon:
            at = ["A" in game.propositions(s) for s in trace]
            task = sum(p for (k, _), p in alive if any(at[k:k + 2]))
            risk = mass if any("h" in game.propositions(s) for s in trace[:4]) else 0
            columns.append((me, float(task / mass), float(risk / mass)))
            return
        for action in game.actions(trace[-1]):
            col = len(columns)
            columns.append((me, 0.0, 0.0))
            for (nxt, _), group in observed(game, trace[-1], action, t, alive).items():
                share = sum(p for _, p in group) / mass
                node((*trace, nxt), group, [(col, float(share))])

    node((game.initial,), [x for x in scenarios if x[1] > 0], [])
    flow = np.zeros((len(inflow), len(columns)))
    for j, (n, _, _) in enumerate(columns):
        flow[n, j] += 1.0
    for n, into in enumerate(inflow):
        for j, share in into:
            flow[n, j] -= share
    start = np.zeros(len(inflow))
    start[0] = 1.0
    task = np.array([c[1] for c in columns])
    risk = np.array([c[2] for c in columns])
    lp = linprog(-task, A_ub=risk[None, :], b_ub=[bound], A_eq=flow, b_eq=start,
                 bounds=(0, None), method="highs")
    assert lp.status == 0, lp.message
    return -lp.fun


@pytest.mark.parametrize("detect, bound", [("0.5", 0.25), ("0.5", 0.3), ("0.8", 0.25)])
def test_a_risk_constraint_is_the_lp_over_observation_histories(detect: str,
                                                                bound: float) -> None:
    game = world(0.5)
    r = synthesize(model(game, CAUGHT, float(detect)), constraints=[f"P(F[0,3] h) <= {bound}"])
    assert r.route == "sensed-constrained" and r.certified
    best = history_lp(game, detect, bound)
    assert r.lower - 1e-7 <= best <= r.upper + 1e-7
    assert r.constraints[0].certified <= bound
    unconstrained = optimum(game, CAUGHT, detect, 0, max)
    assert best < float(unconstrained) - 1e-4  # the constraint binds


def storm_value(path: Path, prop: str) -> Fraction:
    """Storm's exact value of ``prop`` at the initial state of the DTMC at ``path``."""
    m = stormpy.build_model_from_drn[stormpy.Rational](str(path))
    assert "DTMC" in str(m.model_type)
    result = stormpy.model_checking(m, stormpy.parse_properties(prop)[0])
    return Fraction(str(result.get_value(m.initial_states[0])))


@pytest.mark.parametrize("extra", [e for e, _ in EXTRAS], ids=[i for _, i in EXTRAS])
def test_storm_on_the_constrained_chain_gives_lower_and_the_constraint(
        extra: dict[str, Any], tmp_path: Path) -> None:
    """The randomised controller's chain over the true world (moved on the true events),
    reports and its memory: Storm's task value inside the bracket (at most the history
    LP's optimum), the risk at most its certified value and the bound, the expected
    steps the answer's; the controller read from its file gives the same chain, and
    ``mitld_lp.runtime`` on the file draws the live controller's actions."""
    from mitld_lp import load_controller, runtime
    from mitld_lp.controllers.observation import Observation
    from mitld_lp.running.chain import write_chain
    from mitld_lp.util.rollouts import sample_successor

    game = world(0.5)
    r = synthesize(model(game, CAUGHT, 0.5), **extra)
    assert r.route == "sensed-constrained" and r.certified
    path = write_chain(r, tmp_path / "chain.drn")
    task = storm_value(path, 'P=? [F "accept"]')
    assert Fraction(r.lower) - Fraction(1, 10**9) <= task <= Fraction(r.upper)
    assert storm_value(path, 'P=? [F "done"]') == 1
    if "constraints" in extra:
        assert task <= Fraction(history_lp(game, "0.5", 0.25)) + Fraction(1, 10**7)
        risk = storm_value(path, 'P=? [F "c1"]')
        assert risk <= Fraction(r.constraints[0].certified) <= Fraction("0.25")
    if "then" in extra:
        steps = storm_value(path, 'R{"steps"}=? [F "done"]')
        assert float(steps) == pytest.approx(r.secondary, abs=1e-6)
    saved = r.controller.save(tmp_path / "mixed.npz")
    loaded = load_controller(saved)
    assert loaded.plan.kind == "sensed-randomised"
    assert storm_value(write_chain(r, tmp_path / "file.drn", controller=loaded),
                       'P=? [F "accept"]') == task
    robot, rng = runtime.load(saved), np.random.default_rng(5)
    for run in range(60):
        r.controller.reset(seed=run)
        robot.reset(seed=run)
        k = int(rng.choice([1, 2, 3], p=[0.3, 0.3, 0.4]))
        report = k + int(rng.geometric(0.5)) - 1
        s, reports = game.initial, frozenset()
        for t in range(6):
            action = r.controller.act(Observation(s, reports=reports))
            assert robot.act(s, (), reports) == action
            if action is None:
                break
            events = frozenset({"b"}) if t + 1 == k else frozenset()
            s = sample_successor(rng, game.successors(s, action, events))
            reports = frozenset({"b"}) if t + 1 == report else frozenset()
