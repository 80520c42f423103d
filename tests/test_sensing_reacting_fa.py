"""A camera with false alarms on an event the world's moves react to (issue 43; the
``sensed-reacting`` route, :mod:`mitld_lp.sensing.reacting`): the robot reads the event
from every step's report or silence *and* from the world's moves, which differ the step
it happens.

Independent routes: an expectimax over observation histories written here in exact
arithmetic (hidden scenarios are the bus's step only; at every step the world moves by
its own table on the scenario's events and the sensor reports with probability
``false_alarm`` before the bus's step plus the delay and ``detect`` from then on -- no
automaton, no hazards, no information states); at ``false_alarm = 0`` the first-report
expectimax of tests/test_sensing_reacting.py; the fully observed (plain) route where the
world's move shows the bus; Storm on the exported controlled chain (exactly); Bayes'
rule on drawn runs for the running controller's posterior."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from collections.abc import Callable
from fractions import Fraction
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_sensing_reacting import AVOID, CAUGHT, LAW, PMF, optimum, storm_exact, world

from mitld_lp import ExplicitGame, Model, synthesize
from mitld_lp.automata.translate import to_dta
from mitld_lp.distributions.literal import from_table
from mitld_lp.product import ProductTooLarge
from mitld_lp.sensing.reacting import reacting_product

GAME = world(0.5)


def alarmed(game: ExplicitGame, task: str, detect: float, false_alarm: float,
            delay: int = 0, law: str = LAW) -> Model:
    return Model.from_game(game, law + task, sensors={
        "b": {"detect": detect, "false_alarm": false_alarm, "delay": delay}})


def expectimax(game: ExplicitGame, task: str, detect: str, false_alarm: str, delay: int,
               sense: Callable[..., Any], masses: tuple[str, ...] = PMF) -> Fraction:
    """The best (``sense=min``: the worst) probability of ``task`` over the policies that
    see the world's state and whether the sensor reported at each step, the bus at step
    ``k`` with probability ``masses[k - 1]`` (:func:`every_report`)."""
    def holds(trace: tuple[str, ...], k: int) -> bool:
        at = ["A" in game.propositions(s) for s in trace]
        return any(at[k:k + 2]) if task == CAUGHT else not at[k]

    return every_report(game, holds, tuple(enumerate(map(Fraction, masses), start=1)),
                        Fraction(detect), Fraction(false_alarm), delay, sense,
                        len(masses) + 1)


def every_report(game: ExplicitGame, holds: Callable[[tuple[str, ...], int], bool],
                 scenarios: tuple[tuple[int, Fraction], ...], d: Fraction, f: Fraction,
                 delay: int, sense: Callable[..., Any], horizon: int) -> Fraction:
    """The expectimax (module docs): the scenarios (the bus's step ``k``, its mass)
    followed step by step to ``horizon``, each observation (next state, report or
    silence) weighing a scenario by the world's move under its events and the report's
    probability (``f`` before step ``k + delay``, ``d`` from it on), the task judged
    on the trace (``holds``) at the horizon."""
    @cache
    def value(trace: tuple[str, ...], alive: frozenset[tuple[int, Fraction]]) -> Fraction:
        t = len(trace) - 1
        if t == horizon:
            return sum((p for k, p in alive if holds(trace, k)), Fraction(0))
        values = []
        for action in game.actions(trace[-1]):
            seen: dict[tuple[str, bool], dict[int, Fraction]] = {}
            for k, p in alive:
                events = frozenset({"b"}) if k == t + 1 else frozenset()
                q = d if t + 1 >= k + delay else f
                for nxt, pw in game.successors(trace[-1], action, events):
                    for report, pr in ((True, q), (False, 1 - q)):
                        if pr > 0:
                            group = seen.setdefault((nxt, report), {})
                            group[k] = group.get(k, Fraction(0)) + p * Fraction(str(pw)) * pr
            values.append(sum((value((*trace, nxt), frozenset(group.items()))
                               for (nxt, _), group in seen.items()), Fraction(0)))
        return sense(values)

    return value((game.initial,), frozenset(x for x in scenarios if x[1] > 0))


def within(r: Any, exact: Fraction) -> None:
    """The certified bracket holds the exact value (as fractions) and is tight."""
    assert r.certified, [c for c in r.checks if not c.passed]
    assert Fraction(r.lower) <= exact <= Fraction(r.upper), (r.lower, float(exact), r.upper)
    assert r.upper - r.lower <= 1e-9


CASES = [(task, objective, detect, fa, delay) for task in (CAUGHT, AVOID)
         for objective in ("max", "min")
         for detect, fa, delay in (("0.5", "0.1", 0), ("0.7", "0.3", 1))]


@pytest.mark.parametrize("task, objective, detect, fa, delay", CASES)
def test_the_answer_is_the_expectimax_over_every_step_s_report(
        task: str, objective: str, detect: str, fa: str, delay: int) -> None:
    game = world(0.5)
    r = synthesize(alarmed(game, task, float(detect), float(fa), delay), objective=objective)
    assert r.route == "sensed-reacting"
    within(r, expectimax(game, task, detect, fa, delay, max if objective == "max" else min))


def test_false_alarms_change_the_optimum_and_vanish_in_the_limit() -> None:
    """At ``false_alarm = 0`` the expectimax over every step's report is the first-report
    one (tests/test_sensing_reacting.py's, written otherwise); false alarms lower the
    best; as they vanish the route's answer goes to the answer without them."""
    game = world(0.5)
    for delay in (0, 1):
        assert expectimax(game, CAUGHT, "0.5", "0", delay, max) == \
            optimum(game, CAUGHT, "0.5", delay, max)
    none = synthesize(alarmed(game, CAUGHT, 0.5, 0.0))
    some = synthesize(alarmed(game, CAUGHT, 0.5, 0.2))
    tiny = synthesize(alarmed(game, CAUGHT, 0.5, 1e-9))
    assert some.route == tiny.route == none.route == "sensed-reacting"
    assert some.upper < none.lower - 1e-3
    within(tiny, expectimax(game, CAUGHT, "0.5", "1e-9", 0, max))
    assert abs(tiny.lower - none.lower) <= 1e-8


@pytest.mark.parametrize("fa", [0.1, 0.4])
def test_a_reaction_that_shows_the_event_is_the_fully_observed_answer(fa: float) -> None:
    """The flag raised on every move under the bus tells the robot the step it comes:
    whatever the false alarms, the answer is the fully observed one (the ``plain`` route
    with ``detect = 1``), for both objectives."""
    shown = world(1.0)
    for objective, sense in (("max", max), ("min", min)):
        camera = synthesize(alarmed(shown, CAUGHT, 0.5, fa, 1), objective=objective)
        seen = synthesize(Model.from_game(shown, LAW + CAUGHT, sensors={"b": {"detect": 1}}),
                          objective=objective)
        assert (camera.route, seen.route) == ("sensed-reacting", "plain")
        exact = optimum(shown, CAUGHT, "1", 0, sense)
        within(camera, exact)
        within(seen, exact)


stormpy = pytest.importorskip("stormpy")


@pytest.mark.parametrize("delay", [0, 1])
def test_storm_on_the_exported_chain_gives_lower(delay: int, tmp_path: Path) -> None:
    """The controlled chain over the true world (moved on the true events), every step's
    report drawn and the controller's memory: Storm's exact value is ``lower`` and the
    expectimax (the controller is optimal, nothing truncated)."""
    from mitld_lp.running.chain import write_chain

    game = world(0.5)
    r = synthesize(alarmed(game, CAUGHT, 0.6, 0.2, delay))
    value = storm_exact(write_chain(r, tmp_path / "chain.drn"))
    assert Fraction(r.lower) <= value <= Fraction(r.upper)
    assert abs(value - Fraction(r.lower)) <= Fraction(1, 10**9)
    assert abs(value - expectimax(game, CAUGHT, "0.6", "0.2", delay, max)) <= Fraction(1, 10**9)


def posterior(game: ExplicitGame, trace: list[str], actions: list[str],
              reports: list[bool], detect: Fraction, fa: Fraction) -> dict[int, Fraction]:
    """Bayes' rule on the world's moves and every step's report so far: the prior of the
    bus's step ``k`` times, per step, the world's move under ``k``'s events and the
    report's probability; the steps after the last one merged as not yet (0)."""
    t = len(reports)
    out: dict[int, Fraction] = {}
    for k, mass in enumerate(map(Fraction, PMF), start=1):
        p = mass
        for s in range(1, t + 1):
            events = frozenset({"b"}) if k == s else frozenset()
            move = dict(game.successors(trace[s - 1], actions[s - 1], events))
            p *= Fraction(str(move.get(trace[s], 0.0)))
            q = detect if s >= k else fa
            p *= q if reports[s - 1] else 1 - q
        key = k if k <= t else 0
        out[key] = out.get(key, Fraction(0)) + p
    return out


def test_the_running_controller_reads_every_report(tmp_path: Path) -> None:
    """On drawn runs (the bus's step, the world's moves on the true events, every step's
    report drawn): the controller's information state holds Bayes' posterior on the
    moves and reports so far (the undecided hypotheses, renormalised); the saved
    controller run by :mod:`mitld_lp.runtime` and by ``mitld-lp run`` plays its actions;
    rollouts drawing every report land on ``lower``."""
    from mitld_lp.controllers.observation import Observation
    from mitld_lp.runtime import load
    from mitld_lp.sensing.observe import simulate_sensed
    from mitld_lp.util.rollouts import sample_successor

    detect, fa = Fraction(7, 10), Fraction(1, 5)
    game = world(0.5)
    model = alarmed(game, CAUGHT, float(detect), float(fa))
    r = synthesize(model)
    mdp = r.mdp
    saved = r.controller.save(tmp_path / "c.npz")
    robot = load(saved)
    rng = np.random.default_rng(11)
    checked, first = 0, None
    for _ in range(30):
        k = int(rng.choice([1, 2, 3], p=[float(x) for x in PMF]))
        r.controller.reset()
        robot.reset()
        s, trace, actions, history, reports, lines = game.initial, [game.initial], [], [], \
            frozenset(), []
        for t in range(6):
            action = r.controller.act(Observation(s, reports=reports))
            lines.append({"state": s, "reports": sorted(reports)})
            assert robot.act(s, reports=reports) == action
            memory = r.controller.memory
            if action is None or not isinstance(memory, int):
                break
            state = mdp.states[memory]
            exact = posterior(game, trace, actions, history, detect, fa)
            kept = {times[0]: w for (times, _), w in zip(state.hypotheses, state.weights,
                                                         strict=True)}
            total = sum(exact[x] for x in kept)
            for x, w in kept.items():
                assert abs(w - float(exact[x] / total)) <= 1e-9, (history, kept, exact)
            checked += 1
            seen = bool(rng.random() < float(detect if t + 1 >= k else fa))
            events = frozenset({"b"}) if t + 1 == k else frozenset()
            s = sample_successor(rng, game.successors(s, action, events))
            trace.append(s)
            actions.append(action)
            history.append(seen)
            reports = frozenset({"b"}) if seen else frozenset()
        first = first or lines
    assert checked > 40
    # the command line on the first run's observations: the live controller's actions
    r.controller.reset()
    played = [r.controller.act(Observation(line["state"], reports=frozenset(line["reports"])))
              for line in first]
    cli = subprocess.run([sys.executable, "-m", "mitld_lp", "run", str(saved)], text=True,
                         input="\n".join(map(json.dumps, first)) + "\n", capture_output=True,
                         timeout=120, check=False)
    assert cli.returncode == 0, cli.stderr
    assert [json.loads(out)["action"] for out in cli.stdout.splitlines()] == played
    sim = simulate_sensed(model, r.controller, runs=4000, seed=3, max_steps=10)
    sigma = (r.lower * (1 - r.lower) / sim.runs) ** 0.5
    assert abs(sim.estimate - r.lower) <= 4.5 * sigma and sim.beyond_model == 0


def test_the_budget_stops_the_build_before_it_passes() -> None:
    m = alarmed(GAME, CAUGHT, 0.5, 0.1)
    with pytest.raises(ProductTooLarge, match="more than 12 states"):
        reacting_product(m.game, to_dta(m.spec), m.distributions, dict(m.sensors), m.epsilon,
                         max_states=12)
    with pytest.raises(ProductTooLarge):
        synthesize(m, max_states=12)


def test_the_estimate_stops_a_build_that_will_not_fit_early() -> None:
    """The bus over five steps, a camera with false alarms: the report patterns keep
    many posteriors apart.  Under a budget below the product's true size (the build
    without it, counted here) the estimate stops the build at a level's end, less than
    half of the budget stored; under one half again the true size (the estimate errs
    high here, by some 1.3), nothing stops it."""
    m = alarmed(GAME, AVOID, 0.6, 0.3, law="D[pmf(0.2, 0.2, 0.2, 0.2, 0.2)] b & ")
    args = (m.game, to_dta(m.spec), m.distributions, dict(m.sensors), m.epsilon)
    size = len(reacting_product(*args, max_states=10**6).mdp.states)
    budget = size * 3 // 4
    with pytest.raises(ProductTooLarge, match=r"will not fit.*stopped after (\d+) states") as e:
        reacting_product(*args, max_states=budget)
    stored = int(re.search(r"stopped after ([\d,]+) states", str(e.value))[1].replace(",", ""))
    assert stored < budget / 2
    assert len(reacting_product(*args, max_states=size + size // 2).mdp.states) == size


# ------------------------------------------------------------------ a band


@pytest.mark.parametrize("bands", ["worst", "best"])
def test_a_band_is_solved_within_its_point_laws(bands: str) -> None:
    """A geometric band on the bus (its laws surely happen): the band's route reads it
    as with any camera, each candidate this product's answer at the band's middle law or
    an end.  Its worst case is at most the expectimax at either end law (nature may play
    that law at every step); its best case at least (the end law's optimum is a
    candidate, and nature may help it by playing that law)."""
    from test_sensing_reacting_band import BAND, HORIZON, verdict
    from test_sensing_reacting_band import CAUGHT as BOUNDED

    law = from_table({"geometric": [float(x) for x in BAND]}, "mu")
    m = Model.from_game(GAME, "D[mu] b & " + BOUNDED, distributions={"mu": law},
                        sensors={"b": {"detect": 0.5, "false_alarm": 0.2}}, epsilon=1e-9)
    r = synthesize(m, bands=bands)
    assert r.route == "sensed-reacting" and r.bands and r.lower <= r.upper

    def holds(trace: tuple[str, ...], k: int) -> bool:
        return bool(verdict(GAME, BOUNDED, trace, None if k > HORIZON else k))

    for end in map(Fraction, BAND):  # the bus at 1..HORIZON, or later (k = HORIZON + 1)
        scenarios = tuple((k, end * (1 - end) ** (k - 1)) for k in range(1, HORIZON + 1)) \
            + ((HORIZON + 1, (1 - end) ** HORIZON),)
        point = every_report(GAME, holds, scenarios, Fraction("0.5"), Fraction("0.2"), 0,
                             max, HORIZON)
        if bands == "worst":
            assert Fraction(r.lower) <= point + Fraction(1, 10**9)
        else:  # a candidate is the end law's optimum: its best case is at least that
            assert point <= Fraction(r.lower) + Fraction(1, 10**9)


def test_a_steady_growth_is_not_carried_past_the_clock_with_false_alarms() -> None:
    """The estimate the reacting build with false alarms uses (``past = 0``): levels of
    80 growing by 2 up to the clock's step 6 add 160 + 320 to the 151 found (by hand),
    where the frontier builder's carries them two levels further (+ 640 + 1280)."""
    from mitld_lp.sensing.growth import projected

    assert projected([1, 10, 20, 40, 80], 6, past=0) == (151 + 160 + 320, 2.0, 6)
    assert projected([1, 10, 20, 40, 80], 6) == (151 + 2400, 2.0, 8)


# ------------------------------------------------------------------ constraints, then


@pytest.mark.parametrize("extra", [{"constraints": ["P(F[0,3] h) <= 0.25"]},
                                   {"then": "min-steps"}], ids=["risk", "then"])
def test_constraints_with_a_revealing_reaction_are_the_fully_observed_answer(
        extra: dict[str, Any]) -> None:
    """The flag raised on every move under the bus: the false alarms tell nothing more,
    and the constrained answer (route ``sensed-constrained`` on this product) is the
    fully observed constrained route's (``detect = 1``), its constraint value and
    expected steps too."""
    shown = world(1.0)
    camera = synthesize(alarmed(shown, CAUGHT, 0.5, 0.3, 1), **extra)
    seen = synthesize(Model.from_game(shown, LAW + CAUGHT, sensors={"b": {"detect": 1}}),
                      **extra)
    assert (camera.route, seen.route) == ("sensed-constrained", "constrained")
    assert camera.certified and seen.certified
    assert abs(camera.lower - seen.lower) <= 1e-8 and abs(camera.upper - seen.upper) <= 1e-8
    for x, y in zip(camera.constraints, seen.constraints, strict=True):
        assert abs(x.certified - y.certified) <= 1e-6
    if "then" in extra:
        assert abs(camera.secondary - seen.secondary) <= 1e-6


def test_storm_on_the_constrained_chain_meets_the_bound(tmp_path: Path) -> None:
    """The randomised controller's chain (the world moved on the true events, every
    step's report drawn): Storm's task value inside the bracket, below the answer
    without the constraint (which binds), the risk at most its certified value and the
    bound."""
    from mitld_lp.running.chain import write_chain

    m = alarmed(GAME, CAUGHT, 0.5, 0.1)
    r = synthesize(m, constraints=["P(F[0,3] h) <= 0.25"])
    assert r.route == "sensed-constrained" and r.certified
    path = write_chain(r, tmp_path / "chain.drn")
    chain = stormpy.build_model_from_drn[stormpy.Rational](str(path))

    def value(prop: str) -> Fraction:
        result = stormpy.model_checking(chain, stormpy.parse_properties(prop)[0])
        return Fraction(str(result.get_value(chain.initial_states[0])))

    task = value('P=? [F "accept"]')
    assert Fraction(r.lower) - Fraction(1, 10**9) <= task <= Fraction(r.upper)
    assert task < expectimax(GAME, CAUGHT, "0.5", "0.1", 0, max) - Fraction(1, 10**4)
    assert value('P=? [F "c1"]') <= Fraction(r.constraints[0].certified) <= Fraction("0.25")
