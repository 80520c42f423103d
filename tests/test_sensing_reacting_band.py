"""A camera on an event the world's moves react to, its law known only within a band
(issue 43; the ``sensed-reacting`` route with the band's solvers,
mitld_lp/routes/sensed_band.py and sensed_optimistic_solve.py, on the reacting product).

Independent routes: an enumeration written here in exact arithmetic of every hidden
scenario (the step the bus comes, the step its camera first reports it, the world's
branches, the world moved by its own table on each step's true events) and of nature's
choice of the step's hazard among the band's two ends at every node, nature seeing
everything, the returned controller asked for its action after replaying each
observation history (no automaton, no information states, no posterior, no chain);
an expectimax over observation histories at a constant law of the band (an upper bound
on the worst-case optimum: nature may play that law at every step); the fully observed
robust route where the world's move shows the bus; the ``sensed`` route's band answer on
the same tables with the reaction removed (another problem, another answer); and Storm's
robust check of the exported interval chain."""

from __future__ import annotations

import dataclasses
import importlib.util
from collections.abc import Callable
from fractions import Fraction
from functools import cache
from pathlib import Path
from typing import Any

import pytest
from test_sensing_reacting import world

from mitld_lp import ExplicitGame, Model, synthesize
from mitld_lp.controllers.observation import Observation
from mitld_lp.distributions import from_table
from mitld_lp.problem import ProblemError, Settings

CAUGHT = "F[0,3] (b & F[0,1] A)"  # the bus at k <= 3, the robot at A at step k or k + 1
AVOID = "G[0,3] !(b & A)"  # not at A the step the bus comes, if it comes by step 3
HORIZON = 4  # every run is decided by then
BAND = ("0.3", "0.6")  # the bus's hazard at every step, geometric


def model(game: ExplicitGame, task: str, detect: float, delay: int = 0,
          band: tuple[str, str] = BAND) -> Model:
    """The task with the bus ``b``'s law the geometric band, a camera on it; epsilon so
    small that the truncation point lies far past the horizon (nothing truncated)."""
    law = from_table({"geometric": [float(x) for x in band]}, "mu")
    return Model.from_game(game, "D[mu] b & " + task, distributions={"mu": law},
                           sensors={"b": {"detect": detect, "delay": delay}}, epsilon=1e-9)


def verdict(game: ExplicitGame, task: str, trace: tuple[str, ...], k: int | None
            ) -> bool | None:
    """The task on the world's trace so far (steps 0..t) with the bus at step ``k``
    (None: not by step t): True or False once decided, else None."""
    t = len(trace) - 1
    at = ["A" in game.propositions(s) for s in trace]
    if task == CAUGHT:
        if k is not None and k <= 3 and any(at[k:k + 2]):
            return True
        if (k is None and t >= 3) or (k is not None and (k > 3 or t >= k + 1)):
            return False
        return None
    if k is not None and k <= 3 and t >= k:
        return not at[k]
    if (k is None and t >= 3) or (k is not None and k > 3):
        return True
    return None


def replay(controller: Any, seen: tuple[tuple[str, frozenset[str]], ...]) -> str | None:
    """The controller's action after the observation history ``seen``."""
    controller.reset()
    action = None
    for state, reports in seen:
        action = controller.act(Observation(state, reports=reports))
    return action


def controller_value(controller: Any, game: ExplicitGame, task: str, detect: str, delay: int,
                     nature: Callable[..., Fraction], band: tuple[str, str] = BAND
                     ) -> Fraction:
    """The controller's probability of ``task`` with nature choosing the bus's hazard of
    every step among the band's ends after seeing everything (``nature``: ``min`` its
    worst case, ``max`` its best), as a fraction (module docs).  A controller that
    stops is judged on the trace so far (an undecided task counts as failed)."""
    d, ends = Fraction(detect), tuple(Fraction(x) for x in band)

    @cache
    def value(trace: tuple[str, ...], k: int | None, reported: bool,
              seen: tuple[tuple[str, frozenset[str]], ...]) -> Fraction:
        t = len(trace) - 1
        said = verdict(game, task, trace, k)
        if said is not None or t == HORIZON:
            return Fraction(int(bool(said)))
        action = replay(controller, seen)
        if action is None:
            return Fraction(0)
        choices = []
        for h in (ends if k is None else (None,)):
            comes = [(t + 1, h), (None, 1 - h)] if k is None else [(k, Fraction(1))]
            v = Fraction(0)
            for k2, pe in comes:
                due = k2 is not None and not reported and t + 1 >= k2 + delay
                for now, pr in ([(True, d), (False, 1 - d)] if due else [(False, 1)]):
                    events = frozenset({"b"}) if k2 == t + 1 else frozenset()
                    reports = frozenset({"b"}) if now else frozenset()
                    for nxt, pw in game.successors(trace[-1], action, events):
                        v += pe * pr * Fraction(str(pw)) * value(
                            (*trace, nxt), k2, reported or now, (*seen, (nxt, reports)))
            choices.append(v)
        return nature(choices)

    return value((game.initial,), None, False, ((game.initial, frozenset()),))


def point_optimum(game: ExplicitGame, task: str, detect: str, delay: int, hazard: str,
                  robot: Callable[..., Fraction] = max) -> Fraction:
    """The best (``robot=min``: the least) probability of ``task`` over the policies on
    observation histories with the bus's hazard ``hazard`` at every step: the hidden
    scenarios that agree with each history, grouped by the next observation (the world's
    state, a report), the world moved on each one's events."""
    d, h = Fraction(detect), Fraction(hazard)

    @cache
    def value(trace: tuple[str, ...], alive: tuple[tuple[tuple[Any, bool], Fraction], ...]
              ) -> Fraction:
        t = len(trace) - 1
        if t == HORIZON or all(verdict(game, task, trace, k) is not None
                               for (k, _), _ in alive):
            return sum((p for (k, _), p in alive if verdict(game, task, trace, k)),
                       Fraction(0))
        options = []
        for action in game.actions(trace[-1]):
            seen: dict[tuple[str, bool], list[Any]] = {}
            for (k, reported), p in alive:
                for k2, pe in ([(t + 1, h), (None, 1 - h)] if k is None else [(k, 1)]):
                    due = k2 is not None and not reported and t + 1 >= k2 + delay
                    for now, pr in ([(True, d), (False, 1 - d)] if due else [(False, 1)]):
                        events = frozenset({"b"}) if k2 == t + 1 else frozenset()
                        for nxt, pw in game.successors(trace[-1], action, events):
                            m = p * pe * pr * Fraction(str(pw))
                            if m:
                                seen.setdefault((nxt, now), []).append(
                                    ((k2, reported or now), m))
            options.append(sum((value((*trace, nxt), _merged(group))
                                for (nxt, _), group in seen.items()), Fraction(0)))
        return robot(options)

    return value((game.initial,), (((None, False), Fraction(1)),))


def _merged(group: list[Any]) -> tuple[Any, ...]:
    out: dict[Any, Fraction] = {}
    for s, m in group:
        out[s] = out.get(s, Fraction(0)) + m
    return tuple(sorted(out.items(), key=repr))


GAME = world(0.5)
CASES = [(task, objective, detect, delay) for task in (CAUGHT, AVOID)
         for objective in ("max", "min") for detect, delay in (("0.5", 0), ("0.6", 1))]


def _claimed(r: Any) -> Fraction:
    """The end of ``r``'s bracket that is its controller's own value over the band: the
    robot's worst (best) case, ``lower`` for a maximum, ``upper`` for a minimum."""
    return Fraction(r.upper if r.complemented else r.lower)


@pytest.mark.parametrize("task, objective, detect, delay", CASES)
def test_the_worst_case_is_the_controller_s_against_nature(
        task: str, objective: str, detect: str, delay: int) -> None:
    """``lower`` (a minimum: ``upper``) is the returned controller's worst case, nature
    choosing each step's hazard among the band's ends after seeing everything; the
    bracket is sound: the worst-case optimum is at most the point optimum at either end
    (a minimum: at least)."""
    r = synthesize(model(GAME, task, float(detect), delay), objective=objective)
    assert r.route == "sensed-reacting" and r.bands
    worst = controller_value(r.controller, GAME, task, detect, delay,
                             min if objective == "max" else max)
    said = _claimed(r)
    assert abs(worst - said) <= Fraction(1, 10**9), (float(worst), float(said))
    assert Fraction(r.lower) <= worst <= Fraction(r.upper)
    robot = max if objective == "max" else min
    for end in BAND:
        point = point_optimum(GAME, task, detect, delay, end, robot)
        assert (Fraction(r.lower) <= point + Fraction(1, 10**9) if objective == "max"
                else point <= Fraction(r.upper) + Fraction(1, 10**9))
    # certified only where the gap, less the truncation's part, is within the precision
    assert not r.certified or (r.upper - r.lower - r.width["truncation"]
                               <= r.precision * r.lower + 1e-12)


@pytest.mark.parametrize("task, objective, detect, delay", CASES)
def test_the_best_law_is_the_controller_s_with_nature_helping(
        task: str, objective: str, detect: str, delay: int) -> None:
    """``bands = "best"``: ``lower`` (a minimum: ``upper``) is the returned controller's
    best case, nature choosing each step's hazard to help it; ``upper`` is at least the
    point optimum at either end (a minimum: ``lower`` at most), nature being free to
    play that end at every step."""
    r = synthesize(model(GAME, task, float(detect), delay), objective=objective,
                   bands="best")
    assert r.route == "sensed-reacting" and r.bands
    assert r.summary()["bands_reading"] == "best"
    best = controller_value(r.controller, GAME, task, detect, delay,
                            max if objective == "max" else min)
    assert abs(best - _claimed(r)) <= Fraction(1, 10**9)
    robot = max if objective == "max" else min
    for end in BAND:
        point = point_optimum(GAME, task, detect, delay, end, robot)
        assert (point <= Fraction(r.upper) + Fraction(1, 10**9) if objective == "max"
                else Fraction(r.lower) <= point + Fraction(1, 10**9))


def test_the_answer_reads_the_world_s_reaction() -> None:
    """Not degenerate: nature hurts (the worst case below the best), and the same tables
    without the reaction (the ``sensed`` route's band answer) pose another problem with
    another answer."""
    m = model(GAME, CAUGHT, 0.5)
    worst, best = synthesize(m), synthesize(m, bands="best")
    assert worst.lower < best.lower - 1e-3
    # the returned controller is optimal: its worst case reaches the point optimum over
    # observation histories at the band's low end, which no controller's worst case
    # passes (nature may play that end at every step)
    reached = controller_value(worst.controller, GAME, CAUGHT, "0.5", 0, min)
    assert abs(reached - point_optimum(GAME, CAUGHT, "0.5", 0, BAND[0])) <= Fraction(1, 10**9)
    plain = dataclasses.replace(GAME, event_transitions={})
    ignoring = synthesize(model(plain, CAUGHT, 0.5))
    assert ignoring.route == "sensed"
    assert abs(ignoring.lower - worst.lower) > 1e-3
    # each answer is its own controller's worst case in its own world
    assert abs(controller_value(ignoring.controller, plain, CAUGHT, "0.5", 0, min)
               - Fraction(ignoring.lower)) <= Fraction(1, 10**9)


@pytest.mark.parametrize("objective", ["max", "min"])
@pytest.mark.parametrize("bands", ["worst", "best"])
def test_a_reaction_that_shows_the_event_is_the_fully_observed_robust_answer(
        objective: str, bands: str) -> None:
    """Every move under the bus raises the flag: the robot knows the step the bus came,
    the delayed camera that misses adds nothing, and the answer is the fully observed
    robust one (the ``robust`` route, a perfect sensor), to the precision."""
    shown = world(1.0)
    camera = synthesize(model(shown, CAUGHT, 0.5, delay=1), objective=objective, bands=bands)
    seen = synthesize(model(shown, CAUGHT, 1.0), objective=objective, bands=bands)
    assert (camera.route, seen.route) == ("sensed-reacting", "robust")
    assert camera.certified and seen.certified
    assert abs(camera.lower - seen.lower) <= 1e-7 and abs(camera.upper - seen.upper) <= 1e-7
    # the flag is what tells: without it the delayed camera does worse (maximum, worst law)
    if (objective, bands) == ("max", "worst"):
        blind = synthesize(model(world(0.0), CAUGHT, 0.5, delay=1))
        assert blind.upper < camera.lower - 1e-3


@pytest.mark.skipif(importlib.util.find_spec("stormpy") is None, reason="needs stormpy")
@pytest.mark.parametrize("task, objective", [(CAUGHT, "max"), (AVOID, "max"),
                                             (CAUGHT, "min")])
def test_storm_on_the_exported_interval_chain_gives_lower(task: str, objective: str,
                                                          tmp_path: Path) -> None:
    """The controller's interval chain over the truth (the world moved on the true
    events) and its memory, nature's corners as choices: Storm's robust check (nature
    minimising) gives ``lower`` (a minimum's file is its complement's: 1 - ``upper``)."""
    from test_band_chain import storm_worst  # Storm's Pmin, uncertainty MINIMIZE

    from mitld_lp.running.sensed_band_chain import write_sensed_band_chain

    r = synthesize(model(GAME, task, 0.6, 1), objective=objective)
    path = write_sensed_band_chain(r, tmp_path / "c.drn")
    assert "b=lo" in path.read_text()
    bound = 1 - r.upper if objective == "min" else r.lower
    assert abs(storm_worst(path) - bound) <= 1e-9


@pytest.mark.skipif(importlib.util.find_spec("stormpy") is None, reason="needs stormpy")
def test_storm_on_the_best_law_s_chain_gives_lower(tmp_path: Path) -> None:
    """``bands = "best"``: the exported chain at nature's chosen corners; Storm's exact
    ``P=? [F "accept"]`` of it is ``lower`` (the claim, to the solver's last digits)."""
    from test_sensed_optimistic import storm_of

    from mitld_lp.running.chain import write_chain

    r = synthesize(model(GAME, CAUGHT, 0.6, 1), bands="best")
    storm = storm_of(write_chain(r, tmp_path / "c.drn"))("accept")
    assert Fraction(r.lower) <= storm <= Fraction(r.lower) + Fraction(1, 10**9)


def plan_value(plan: Any, game: ExplicitGame, judge: Callable[..., bool | None],
               detect: str, delay: int, nature: Callable[..., Fraction],
               band: tuple[str, str] = BAND) -> Fraction:
    """The probability that ``judge(trace, k)`` says True (None: not decided yet) under
    a randomised observation-based ``plan`` (its mixed decision after each observation
    history, its memory moved by its own ``follow``), nature picking each step's hazard
    among the band's ends after seeing everything, the robot's draw included, in exact
    arithmetic; a run the controller stays in or stops with undecided counts as not
    satisfied."""
    d, ends = Fraction(detect), tuple(Fraction(x) for x in band)

    @cache
    def value(trace: tuple[str, ...], k: int | None, reported: bool, memory: Any
              ) -> Fraction:
        t, w = len(trace) - 1, trace[-1]
        said = judge(trace, k)
        if said is not None or t == HORIZON:
            return Fraction(int(bool(said)))
        decision = plan.decision(w, memory)
        if decision.lost or not decision.actions:
            return Fraction(0)
        weights = [Fraction(1)] if decision.weights is None else [
            Fraction(float(x)) for x in decision.weights]
        out, go = Fraction(0), 1 - Fraction(decision.stay)
        for action, x in zip(decision.actions, weights, strict=True):
            options = []
            for h in (ends if k is None else (None,)):
                v = Fraction(0)
                for k2, pe in ([(t + 1, h), (None, 1 - h)] if k is None else [(k, 1)]):
                    due = k2 is not None and not reported and t + 1 >= k2 + delay
                    for now, pr in ([(True, d), (False, 1 - d)] if due else [(False, 1)]):
                        events = frozenset({"b"}) if k2 == t + 1 else frozenset()
                        reports = frozenset({"b"}) if now else frozenset()
                        for nxt, pw in game.successors(w, action, events):
                            after, _ = plan.follow(memory, nxt, reports, action)
                            v += pe * pr * Fraction(str(pw)) * value(
                                (*trace, nxt), k2, reported or now, after)
                options.append(v)
            if x:
                out += go * x / sum(weights) * nature(options)
        return out

    return value((game.initial,), None, False, plan.start(game.initial))


RISK = "P(F[0,3] h) <= 0.35"  # in the ditch by step 3


def in_ditch(trace: tuple[str, ...], k: int | None) -> bool | None:
    if any(s.startswith("ditch") for s in trace[:4]):
        return True
    return False if len(trace) > 4 else None


@pytest.fixture(scope="module")
def constrained() -> Any:
    return synthesize(model(GAME, CAUGHT, 0.5), constraints=[RISK])


def test_a_constraint_under_the_band_holds_under_every_law(constrained: Any) -> None:
    """Constraints with the band's worst law (the band constrained route on the
    reacting product): the returned randomised controller's risk with nature making the
    ditch as likely as it can is within its bound (and is the constraint's certified
    value), its task's worst case is ``lower``, by the enumeration; no better than the
    robot that sees the bus under the same band and constraint."""
    r = constrained
    assert r.route == "sensed-constrained" and r.bands and r.controller is not None
    (v,) = r.constraints
    assert v.holds
    risk = plan_value(r.controller.plan, GAME, in_ditch, "0.5", 0, max)
    assert risk <= Fraction("0.35") and abs(risk - Fraction(v.bounds[1])) <= Fraction(1, 10**8)
    task = plan_value(r.controller.plan, GAME,
                      lambda trace, k: verdict(GAME, CAUGHT, trace, k), "0.5", 0, min)
    assert abs(task - Fraction(r.lower)) <= Fraction(1, 10**9) and r.lower <= r.upper
    seen = synthesize(model(GAME, CAUGHT, 1.0), constraints=[RISK])
    assert seen.bands and not seen.part.observation_based and r.lower <= seen.upper + 1e-9
    # the constraint binds: without it the worst case is higher
    assert r.upper < synthesize(model(GAME, CAUGHT, 0.5)).lower - 1e-3


@pytest.mark.skipif(importlib.util.find_spec("stormpy") is None, reason="needs stormpy")
def test_storm_on_the_constrained_interval_chain(constrained: Any, tmp_path: Path) -> None:
    """Storm's robust check of the exported file: ``Pmin [F "accept"]`` (uncertainty
    MINIMIZE) is ``lower``, ``Pmax [F "c1"]`` (MAXIMIZE) the constraint's worst case,
    within its bound."""
    from test_band_chain import storm_robust, storm_worst

    from mitld_lp.running.sensed_band_chain import write_sensed_band_chain

    r = constrained
    path = write_sensed_band_chain(r, tmp_path / "c.drn")
    assert abs(storm_worst(path) - r.lower) <= 1e-9
    worst = storm_robust(path, 'Pmax=? [F "c1"]', maximise=True)
    assert worst <= 0.35 and abs(worst - r.constraints[0].bounds[1]) <= 1e-8


def test_then_under_the_band_keeps_the_worst_case() -> None:
    """``then = "min-steps"`` under the band: the task's worst case is the returned
    controller's by the enumeration, and a second objective only after the first (the
    worst case without ``then``, to the LP's tolerance)."""
    r = synthesize(model(GAME, CAUGHT, 0.5), then="min-steps")
    assert r.route == "sensed-constrained" and r.bands and r.controller is not None
    task = plan_value(r.controller.plan, GAME,
                      lambda trace, k: verdict(GAME, CAUGHT, trace, k), "0.5", 0, min)
    assert abs(task - Fraction(r.lower)) <= Fraction(1, 10**9)
    assert r.upper >= synthesize(model(GAME, CAUGHT, 0.5)).lower - 1e-6
    assert 0 < r.secondary < float("inf")


def test_the_trade_off_curve_s_end_point_under_the_band() -> None:
    """The constrained LP asked with no constraint (a trade-off curve's end point) under
    the band's worst law: its randomised controller's worst case, by the enumeration, is
    its ``lower``, and, both certified, the band's worst-case answer without the LP."""
    from mitld_lp.synthesis import synthesize_constrained

    m = model(GAME, CAUGHT, 0.5)
    r = synthesize_constrained(m)
    assert r.route == "sensed-constrained" and r.bands and r.controller is not None
    task = plan_value(r.controller.plan, GAME,
                      lambda trace, k: verdict(GAME, CAUGHT, trace, k), "0.5", 0, min)
    assert abs(task - Fraction(r.lower)) <= Fraction(1, 10**9)
    alone = synthesize(m)
    assert r.certified and alone.certified and abs(r.lower - alone.lower) <= 1e-6


HAZARD = {"middle law": "0.45", "low ends": "0.3", "high ends": "0.6"}  # the band's laws


@pytest.mark.parametrize("objective, extra", [
    ("max", {"constraints": [RISK]}), ("min", {"constraints": [RISK]}),
    ("max", {"then": "min-steps"})], ids=["max-risk", "min-risk", "max-then"])
def test_the_best_law_with_constraints_is_a_pair_met_at_its_law(
        objective: str, extra: dict[str, Any], tmp_path: Path) -> None:
    """``bands = "best"`` with constraints or ``then`` (the optimistic constrained route
    on the reacting product): a pair of a randomised controller and a constant law of
    the band, the task's value and each constraint's at that law by the enumeration with
    nature held to it (its two ends the same hazard): the controller's own end
    (``lower``, a minimum's ``upper``) and the risk within its bound; the unconstrained
    point optimum at that law no worse; Storm's exact check of the exported chain at
    that law the enumeration's value (a minimum's: its complement), its risk the
    enumeration's."""
    pytest.importorskip("stormpy")
    from test_sensed_optimistic import storm_of

    from mitld_lp.running.chain import write_chain

    r = synthesize(model(GAME, CAUGHT, 0.5), objective=objective, bands="best", **extra)
    assert r.route == "sensed-constrained" and r.bands and r.controller is not None
    h = HAZARD[r.part.chosen_at]
    plan, at = r.controller.plan, (h, h)
    task = plan_value(plan, GAME, lambda trace, k: verdict(GAME, CAUGHT, trace, k), "0.5",
                      0, min, band=at)
    own = Fraction(r.upper if objective == "min" else r.lower)
    assert abs(task - own) <= Fraction(1, 10**7), (float(task), float(own))
    point = point_optimum(GAME, CAUGHT, "0.5", 0, h, max if objective == "max" else min)
    assert (own <= point + Fraction(1, 10**9) if objective == "max"
            else point <= own + Fraction(1, 10**9))
    storm = storm_of(write_chain(r, tmp_path / "c.drn"))
    # a minimum's chain is its complement's: "accept" marks the runs that fail the task
    assert abs(storm("accept") - (1 - task if objective == "min" else task)) \
        <= Fraction(1, 10**9)
    if "constraints" in extra:
        risk = plan_value(plan, GAME, in_ditch, "0.5", 0, max, band=at)
        (v,) = r.constraints
        assert v.holds and risk <= Fraction("0.35") + Fraction(1, 10**9)
        assert abs(storm("c1") - risk) <= Fraction(1, 10**9)
    else:
        assert 0 < r.secondary < float("inf")


def test_a_route_list_without_the_reacting_route_refuses_by_name() -> None:
    """The ``sensed`` route's band solvers on the product that ignores the reaction
    would answer another problem: asked without the ``sensed-reacting`` route, the
    band is refused, naming the route that solves it."""
    from mitld_lp.problem import pose_on
    from mitld_lp.routes.sensed import SensedRoute
    from mitld_lp.routes.sensed_optimistic import SensedOptimisticRoute

    m = model(GAME, CAUGHT, 0.5)
    for routes, bands in (([SensedRoute()], "worst"), ([SensedOptimisticRoute()], "best")):
        with pytest.raises(ProblemError, match="react to the sensed event 'b'.*solved by "
                                               "route sensed-reacting .with a band too"):
            pose_on(routes, m, settings=Settings(bands=bands))
