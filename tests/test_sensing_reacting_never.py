"""A camera with false alarms on an event whose law may never happen, on a world whose
moves react to it (issue 43; route ``sensed-reacting``, with constraints
``sensed-constrained``): bracketed (mitld_lp/routes/sensed_never.py) between the
controller that ignores the reports, reading the world's moves only, and a sensor
without false alarms at least as informative, each end a reacting product's solve.

Independent routes: an expectimax in fractions written here from the world's own tables
(the bus's step or never, every step's report or silence, the world moved by the
reacting rows on the step the bus comes; no automaton, no hazards, no information
states) over a horizon that decides each task: the posed optimum must lie in the
bracket, its blind (``detect = false_alarm = 0``) and informed (``d' = (d - f) / (1 -
f)`` by hand: 3/4 here) versions are the bracket's ends; the returned controller
replayed exactly over every scenario, move and report (fed to it, dropped); Storm on the
exported chain, exactly."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable
from fractions import Fraction
from functools import cache
from pathlib import Path
from typing import Any

import pytest

from mitld_lp import ExplicitGame, Model, synthesize
from mitld_lp.distributions import pmf

B = frozenset({"b"})
# the robot between a station (A) and a ditch (h); waiting at mid is pushed to the station
BASE = {
    "mid": {"go": {"st": "0.8", "ditch": "0.2"}, "wait": {"mid": "0.5", "st": "0.5"}},
    "st": {"wait": {"st": "0.5", "ditch": "0.5"}, "back": {"mid": "0.8", "ditch": "0.2"}},
    "ditch": {"stay": {"ditch": "1"}},
}
# the rows the step the bus comes: the world reacts (its moves tell a little of the bus)
REACT = {("mid", "wait"): {"mid": "0.3", "st": "0.7"},
         ("st", "back"): {"mid": "0.5", "ditch": "0.5"}}
GAME = ExplicitGame(
    initial="mid",
    transitions={s: {a: {n: float(p) for n, p in row.items()} for a, row in acts.items()}
                 for s, acts in BASE.items()},
    labels={"st": {"A"}, "ditch": {"h"}},
    event_transitions={(s, a, B): {n: float(p) for n, p in row.items()}
                       for (s, a), row in REACT.items()})
LAW = ("0.25", "0.25", "0.3")  # the bus at step 1, 2 or 3; never with probability 0.2
HORIZON = 5  # each task below is decided by step 5

CAUGHT, AVOID = "F(b & F[0,1] A)", "G !(b & A)"
OBLIGATION = CAUGHT + " & G[0,5] !h"


def holds(task: str, trace: tuple[str, ...], k: int | None) -> bool:
    """The task on the trace (indices 0..HORIZON), the bus at step ``k`` (None: never)."""
    at = [s == "st" for s in trace]
    caught = k is not None and any(at[k:k + 2])
    if task == CAUGHT:
        return caught
    if task == AVOID:
        return k is None or not at[k]
    return caught and "ditch" not in trace[:6]


def model(task: str, detect: float, false_alarm: float, law: Any = None) -> Model:
    return Model.from_game(GAME, task, events={"b": law or pmf([float(x) for x in LAW])},
                           sensors={"b": {"detect": detect, "false_alarm": false_alarm}})


def expectimax(task: str, d: str, f: str, sense: Callable[..., Any]) -> Fraction:
    """The best (``sense=min``: the worst) probability of ``task`` over the controllers
    that see the world's state and, at each step, whether the camera reported: the bus's
    step ``k`` (or never) hidden, the camera reporting with probability ``f`` before
    step ``k`` and ``d`` from it on (``f`` for ever if the bus never comes)."""
    pd, pf = Fraction(d), Fraction(f)
    masses = [Fraction(x) for x in LAW]
    prior = (*((k, m) for k, m in enumerate(masses, start=1)), (None, 1 - sum(masses)))

    @cache
    def best(trace: tuple[str, ...], alive: frozenset[tuple[int | None, Fraction]]
             ) -> Fraction:
        t = len(trace) - 1
        if t == HORIZON:
            return sum((p for k, p in alive if holds(task, trace, k)), Fraction(0))
        here = trace[-1]
        options = []
        for action, row in BASE[here].items():
            seen: dict[tuple[str, bool], dict[int | None, Fraction]] = {}
            for k, p in alive:
                moves = REACT.get((here, action), row) if k == t + 1 else row
                q = pd if k is not None and t + 1 >= k else pf
                for nxt, pm in moves.items():
                    for report, pr in ((True, q), (False, 1 - q)):
                        if pr:
                            group = seen.setdefault((nxt, report), {})
                            group[k] = group.get(k, Fraction(0)) + p * Fraction(pm) * pr
            options.append(sum((best((*trace, nxt), frozenset(g.items()))
                                for (nxt, _), g in seen.items()), Fraction(0)))
        return sense(options)

    return best((GAME.initial,), frozenset(x for x in prior if x[1]))


def replayed(r: Any, task: str, d: str, f: str) -> Fraction:
    """The returned controller's value, exactly: every scenario (the bus's step or
    never), every move of the world (its reacting rows the step the bus comes) and every
    step's report or silence, each fed to the controller (which drops them) from its
    start."""
    from mitld_lp.controllers.observation import Observation

    pd, pf = Fraction(d), Fraction(f)
    masses = [Fraction(x) for x in LAW]
    c = r.controller

    def act(history: list[tuple[str, frozenset[str]]]) -> str | None:
        c.reset()
        action = None
        for s, reports in history:
            action = c.act(Observation(s, reports=reports))
        return action

    def run(k: int | None, history: list[tuple[str, frozenset[str]]]) -> Fraction:
        trace = tuple(s for s, _ in history)
        t = len(trace) - 1
        if t == HORIZON:
            return Fraction(holds(task, trace, k))
        here = trace[-1]
        # decided (None): the verdict is kept whatever is played; the world's first action
        action = act(history) or next(iter(BASE[here]))
        row = BASE[here][action]
        moves = REACT.get((here, action), row) if k == t + 1 else row
        q = pd if k is not None and t + 1 >= k else pf
        return sum((Fraction(pm) * pr * run(k, [*history, (nxt, B if report else frozenset())])
                    for nxt, pm in moves.items()
                    for report, pr in ((True, q), (False, 1 - q)) if pr), Fraction(0))

    start = [(GAME.initial, frozenset[str]())]
    return sum((m * run(k, start) for k, m in
                (*enumerate(masses, start=1), (None, 1 - sum(masses)))), Fraction(0))


def near(x: float, exact: Fraction) -> bool:
    return abs(Fraction(x) - exact) <= Fraction(1, 10**9)


POSED, INFORMED = ("0.8", "0.2"), ("0.75", "0")  # d' = (0.8 - 0.2) / (1 - 0.2), by hand
CASES = [(CAUGHT, "max"), (CAUGHT, "min"), (AVOID, "max"), (AVOID, "min"),
         (OBLIGATION, "max")]


@pytest.mark.parametrize("task, objective", CASES)
def test_the_every_step_optimum_lies_between_the_blind_and_informed_optima(
        task: str, objective: str) -> None:
    """The bracket holds the expectimax over every step's report and the world's moves
    (fractions, no tolerance); its end on the controller's side (``lower`` for a
    maximum, ``upper`` for a minimum) is the blind expectimax (only the world's moves
    read), the other the informed sensor's, each also the separate reacting solve with
    that sensor; certified exactly where the two meet."""
    sense = max if objective == "max" else min
    exact = expectimax(task, *POSED, sense)
    blind = expectimax(task, "0", "0", sense)
    informed = expectimax(task, *INFORMED, sense)
    assert sense(blind, exact) == exact and sense(exact, informed) == informed
    r = synthesize(model(task, 0.8, 0.2), objective=objective)
    assert r.route == "sensed-reacting"
    assert Fraction(r.lower) <= exact <= Fraction(r.upper), (r.lower, float(exact), r.upper)
    ours, other = (r.lower, r.upper) if objective == "max" else (r.upper, r.lower)
    assert near(ours, blind), (ours, blind)
    alone = synthesize(model(task, 0.0, 0.0), objective=objective)
    better = synthesize(model(task, 0.75, 0.0), objective=objective)
    assert alone.route == better.route == "sensed-reacting"
    assert abs(ours - (alone.lower if objective == "max" else alone.upper)) <= 1e-9
    assert abs(other - (better.upper if objective == "max" else better.lower)) <= 1e-9
    # the informed solve's bracket holds the informed expectimax (its truncation's part
    # on the far side: the obligation's G[0,5] past the bus's last step)
    assert Fraction(better.lower) - Fraction(1, 10**9) <= informed \
        <= Fraction(better.upper) + Fraction(1, 10**9)
    check = next(c for c in r.checks if c.name == "false alarms, law that may never happen")
    assert check.passed == (blind == informed) == r.certified
    if not check.passed:
        assert "not read" in check.detail and r.width["information"] > 1e-3


@pytest.mark.parametrize("task, objective", [(CAUGHT, "max"), (OBLIGATION, "max"),
                                             (AVOID, "min")])
def test_the_returned_controller_replayed_exactly_is_its_end(task: str, objective: str
                                                             ) -> None:
    """The blind controller fed every step's report (and dropping it) over every
    scenario and world move: its exact value is the bracket's end on its side."""
    r = synthesize(model(task, 0.8, 0.2), objective=objective)
    value = replayed(r, task, *POSED)
    assert near(r.lower if objective == "max" else r.upper, value), (r.lower, r.upper,
                                                                      float(value))


stormpy = pytest.importorskip("stormpy")


def storm(path: Path, prop: str = 'P=? [F "accept"]') -> Fraction:
    chain = stormpy.build_model_from_drn[stormpy.Rational](str(path))
    result = stormpy.model_checking(chain, stormpy.parse_properties(prop)[0])
    return Fraction(str(result.get_value(chain.initial_states[0])))


def test_storm_on_the_chain_and_the_tree_gives_lower(tmp_path: Path) -> None:
    """``export --chain`` (the world moved on the true events, every step's report drawn
    from the posed camera, then dropped) and the decision tree of ``export --tree`` run
    as the controller: Storm's exact value is ``lower``, the blind expectimax."""
    from mitld_lp.running.chain import write_chain
    from mitld_lp.running.tree import tree_controller, tree_of

    r = synthesize(model(OBLIGATION, 0.8, 0.2))
    value = storm(write_chain(r, tmp_path / "c.drn"))
    assert near(r.lower, value) and near(float(value), expectimax(OBLIGATION, "0", "0", max))
    tree = tree_controller(r, tree_of(r))
    assert storm(write_chain(r, tmp_path / "t.drn", controller=tree)) == value


def test_rollouts_of_the_posed_model_land_on_lower() -> None:
    """Rollouts of the posed model (the world moved on the drawn bus, every step's report
    drawn from the posed camera) never meet an observation the controller cannot read,
    and their success rate lands on ``lower``."""
    from mitld_lp.sensing.observe import simulate_sensed

    m = model(OBLIGATION, 0.8, 0.2)
    r = synthesize(m)
    sim = simulate_sensed(m, r.controller, runs=3000, seed=7, max_steps=12)
    sigma = (r.lower * (1 - r.lower) / sim.runs) ** 0.5
    assert sim.beyond_model == 0 and abs(sim.estimate - r.lower) <= 4.5 * sigma


def test_the_saved_controller_runs_as_the_live_one(tmp_path: Path) -> None:
    """The controller file, loaded by :mod:`mitld_lp.runtime` and run by ``mitld-lp
    run``, plays the live controller's actions on observations with reports."""
    from mitld_lp.controllers.observation import Observation
    from mitld_lp.runtime import load

    r = synthesize(model(CAUGHT, 0.8, 0.2))
    saved = r.controller.save(tmp_path / "c.npz")
    robot = load(saved)
    lines = [{"state": "mid", "reports": []}, {"state": "mid", "reports": ["b"]},
             {"state": "st", "reports": []}, {"state": "st", "reports": ["b"]}]
    r.controller.reset()
    robot.reset()
    played = []
    for line in lines:
        action = r.controller.act(Observation(line["state"], reports=frozenset(line["reports"])))
        assert robot.act(line["state"], reports=frozenset(line["reports"])) == action
        played.append(action)
    cli = subprocess.run([sys.executable, "-m", "mitld_lp", "run", str(saved)], text=True,
                         input="\n".join(map(json.dumps, lines)) + "\n", capture_output=True,
                         timeout=120, check=False)
    assert cli.returncode == 0, cli.stderr
    assert [json.loads(out)["action"] for out in cli.stdout.splitlines()] == played


# ------------------------------------------------------------------ constraints, then


def test_a_binding_constraint_met_by_the_blind_controller(tmp_path: Path) -> None:
    """``P(F[0,3] h) <= 0.3`` binds the blind controller (its task value below the blind
    expectimax without it): the randomised blind controller's chain, in Storm, has the
    task value ``lower`` and the risk within the bound; ``upper`` is the informed
    constrained solve's, done separately, and at least the chain's value."""
    from mitld_lp.running.chain import write_chain

    bound = ["P(F[0,3] h) <= 0.3"]
    r = synthesize(model(CAUGHT, 0.8, 0.2), constraints=bound)
    assert r.route == "sensed-constrained" and r.status.has_solution
    assert not r.certified and all(c.holds for c in r.constraints)  # reports worth reading
    path = write_chain(r, tmp_path / "c.drn")
    task = storm(path)
    assert abs(task - Fraction(r.lower)) <= Fraction(1, 10**6)
    assert task < expectimax(CAUGHT, "0", "0", max) - Fraction(1, 10**3)
    assert storm(path, 'P=? [F "c1"]') <= Fraction("0.3") + Fraction(1, 10**9)
    informed = synthesize(model(CAUGHT, 0.75, 0.0), constraints=bound)
    assert abs(r.upper - informed.upper) <= 1e-9 and task <= Fraction(r.upper)


@pytest.mark.parametrize("bound, status", [("0.59", "failed"), ("0.7", "infeasible")])
def test_a_constraint_no_blind_controller_meets(bound: str, status: str) -> None:
    """Catching the bus with probability at least ``bound``, the task keeping off the
    ditch: no controller reading only the world's moves reaches 0.59 (the blind
    expectimax, 0.5735, is below it), one reading the reports may (the informed
    expectimax is above it): ``failed``, no controller, the informed bound said; 0.7 is
    above the informed expectimax too: infeasible, proved."""
    blind, informed = expectimax(CAUGHT, "0", "0", max), expectimax(CAUGHT, *INFORMED, max)
    assert (blind < Fraction(bound) <= informed) == (status == "failed")
    assert blind < Fraction(bound)
    r = synthesize(model("G[0,5] !h", 0.8, 0.2),
                   constraints=[f"P({CAUGHT}) >= {bound}"])
    assert r.route == "sensed-constrained" and r.status.value == status
    assert r.controller is None and r.lower != r.lower  # NaN: no controller's value
    check = next(c for c in r.checks if c.name == "false alarms, law that may never happen")
    assert check.passed == (status == "infeasible")


def test_then_and_the_tradeoff_curve() -> None:
    """``then min-steps``: the first objective's bracket is the unconstrained one (the
    blind and informed expectimaxes), the steps the blind controller's; the trade-off
    curve's points each hold their bound and, where the risk bound is slack, give the
    unconstrained bracket's controller end."""
    from mitld_lp.tradeoff import pareto

    m = model(CAUGHT, 0.8, 0.2)
    r = synthesize(m, then="min-steps")
    assert r.route == "sensed-constrained"
    assert abs(Fraction(r.lower) - expectimax(CAUGHT, "0", "0", max)) <= Fraction(1, 10**6)
    assert abs(Fraction(r.upper) - expectimax(CAUGHT, *INFORMED, max)) <= Fraction(1, 10**6)
    assert 0 < r.secondary < 10
    points = pareto(m, "P(F[0,3] h)", points=3)
    assert all(p.status.has_solution and p.achieved <= p.bound + 1e-7 for p in points)
    assert abs(Fraction(points[-1].lower) - expectimax(CAUGHT, "0", "0", max)) \
        <= Fraction(1, 10**6)


# ------------------------------------------------------------------ a band


@pytest.mark.parametrize("bands, extra", [("worst", {}), ("best", {}),
                                          ("worst", {"constraints": ["P(F[0,3] h) <= 0.4"]})])
def test_a_band_is_bracketed_by_its_blind_and_informed_solves(
        bands: str, extra: dict[str, Any]) -> None:
    """A band of laws that may never happen (its worst or best law; the worst with a
    constraint): the band's problem with the camera blind (``lower``) and with the
    informed camera (``upper``), each the separate reacting band solve; the check names
    the gap."""
    from mitld_lp.distributions.band import band_of_laws

    band = band_of_laws("mu", pmf([0.25, 0.25, 0.3]), [pmf([0.2, 0.3, 0.3]),
                                                      pmf([0.3, 0.2, 0.3])])
    r = synthesize(model(CAUGHT, 0.8, 0.2, band), bands=bands, **extra)
    blind = synthesize(model(CAUGHT, 0.0, 0.0, band), bands=bands, **extra)
    informed = synthesize(model(CAUGHT, 0.75, 0.0, band), bands=bands, **extra)
    route = "sensed-constrained" if extra else "sensed-reacting"
    assert r.route == blind.route == informed.route == route and r.bands
    assert abs(r.lower - blind.lower) <= 1e-9 and abs(r.upper - informed.upper) <= 1e-9
    assert all(c.holds for c in r.constraints)  # under every law of the band
    check = next(c for c in r.checks if c.name == "false alarms, law that may never happen")
    assert not check.passed and not r.certified


def test_storm_on_the_band_s_interval_chain_gives_lower(tmp_path: Path) -> None:
    """The blind controller's interval chain under the band (the world moved on the
    true events, every step's report drawn from the posed camera and dropped): Storm's
    robust check, nature minimising, gives ``lower``."""
    from test_band_chain import storm_worst

    from mitld_lp.distributions.band import band_of_laws
    from mitld_lp.running.sensed_band_chain import write_sensed_band_chain

    band = band_of_laws("mu", pmf([0.25, 0.25, 0.3]), [pmf([0.2, 0.3, 0.3]),
                                                      pmf([0.3, 0.2, 0.3])])
    r = synthesize(model(CAUGHT, 0.8, 0.2, band))
    path = write_sensed_band_chain(r, tmp_path / "c.drn")
    assert abs(storm_worst(path) - r.lower) <= 1e-9
