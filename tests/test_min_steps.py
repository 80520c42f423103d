"""A minimum's expected steps and costs count until the *posed* task is decided.

A minimum is solved as the maximum of the task's complement, but ``then = "min-steps"``,
``E(steps)`` and ``E(cost)`` count the actions taken while the posed task is undecided:
neither accepted nor rejected, and some policy could still make it accept.  A state from
which every policy satisfies the task is still charged until the task is accepted.
Every expected value below is counted by hand on the world drawn in the test.
"""

from __future__ import annotations

import pytest

from mitld_lp import Model, synthesize, synthesize_constrained
from mitld_lp.logic.constraints import LEXICOGRAPHIC_TOL
from mitld_lp.problem import ProblemError
from mitld_lp.running.constrained_runs import run_constrained
from mitld_lp.worlds.game import ExplicitGame

TOL = 1e-6


def _sure_world() -> ExplicitGame:
    # every run reaches the goal: "fast" in one step, "slow" in three, "retry" in two on
    # average (a fair coin each step); the minimum of P(F goal) is 1
    return ExplicitGame(initial="a", transitions={
        "a": {"slow": {"c1": 1.0}, "fast": {"goal": 1.0}, "retry": {"a": 0.5, "goal": 0.5}},
        "c1": {"go": {"c2": 1.0}}, "c2": {"go": {"goal": 1.0}},
        "goal": {"wait": {"goal": 1.0}}}, labels={"goal": {"goal"}})


@pytest.mark.parametrize("objective", ["max", "min"])
def test_min_steps_counts_until_the_sure_task_is_accepted(objective: str) -> None:
    m = Model.from_game(_sure_world(), "F goal", objective=objective)
    r = synthesize_constrained(m, [], then="min-steps")
    assert r.lower == pytest.approx(1.0, abs=TOL) and r.upper == pytest.approx(1.0, abs=TOL)
    # the fastest policy among those of probability 1 (all of them): "fast", one step
    assert r.secondary == pytest.approx(1.0, abs=TOL)
    # its runs are charged that one step each
    stats = run_constrained(r, runs=200, seed=3)
    assert stats.steps.min() == 1 and stats.steps.max() == 1


def test_a_minimum_s_steps_bound_is_checked_on_the_posed_task() -> None:
    only_slow = ExplicitGame(initial="a", transitions={
        "a": {"slow": {"c1": 1.0}}, "c1": {"go": {"c2": 1.0}}, "c2": {"go": {"goal": 1.0}},
        "goal": {"wait": {"goal": 1.0}}}, labels={"goal": {"goal"}})
    m = Model.from_game(only_slow, "F goal", objective="min")
    # three steps on every run: a bound of 2.5 cannot be met, 3.5 is
    r = synthesize_constrained(m, ["E(steps) <= 2.5"])
    assert r.status == "infeasible"
    assert r.constraints[0].feasible_bound == pytest.approx(3.0, abs=TOL)
    ok = synthesize_constrained(m, ["E(steps) <= 3.5"])
    assert ok.status == "optimal" and ok.certified
    assert ok.constraints[0].value == pytest.approx(3.0, abs=TOL)
    assert ok.constraints[0].holds


def test_a_minimum_s_cost_counts_until_the_task_holds() -> None:
    world = ExplicitGame(initial="a", transitions={
        "a": {"slow": {"c1": 1.0}, "fast": {"goal": 1.0}},
        "c1": {"go": {"goal": 1.0}}, "goal": {"wait": {"goal": 1.0}}},
        labels={"goal": {"goal"}})
    m = Model.from_game(world, "F goal", objective="min")
    r = synthesize_constrained(m, [], then="min-cost", costs={"fast": 5.0})
    # both policies satisfy the task surely; slow + go cost 2, fast costs 5
    assert r.lower == pytest.approx(1.0, abs=TOL)
    assert r.secondary == pytest.approx(2.0, abs=TOL)


def test_a_decided_loss_stops_the_count_for_a_minimum() -> None:
    # "right" leads where the goal can never be reached: the task is decided (lost)
    # after that one step, so the minimum (0) takes one charged step; "left" reaches the
    # goal after a corridor of two
    world = ExplicitGame(initial="a", transitions={
        "a": {"left": {"c1": 1.0}, "right": {"trap": 1.0}},
        "c1": {"go": {"goal": 1.0}}, "trap": {"stay": {"trap": 1.0}},
        "goal": {"wait": {"goal": 1.0}}}, labels={"goal": {"goal"}})
    m = Model.from_game(world, "F goal", objective="min")
    r = synthesize_constrained(m, [], then="min-steps")
    assert r.upper == pytest.approx(0.0, abs=TOL)
    assert r.secondary == pytest.approx(1.0, abs=TOL)
    # the maximum goes left: two steps to the goal
    mx = synthesize_constrained(Model.from_game(world, "F goal"), [], then="min-steps")
    # (the lexicographic step may give up LEXICOGRAPHIC_TOL of the probability)
    assert mx.lower == pytest.approx(1.0, abs=LEXICOGRAPHIC_TOL + TOL)
    assert mx.secondary == pytest.approx(2.0, abs=2 * LEXICOGRAPHIC_TOL + TOL)


def test_a_sensed_minimum_with_steps_is_refused_by_name() -> None:
    import dataclasses
    from types import MappingProxyType

    from mitld_lp import GridWorld
    from mitld_lp.distributions.literal import from_table
    from mitld_lp.sensing import Sensor

    world = GridWorld.make(3, 2, start=(0, 0), slip=0.2, regions={"goal": [(2, 1)]})
    m = Model.from_game(world, "F goal & D[mu] b", objective="min", epsilon=0.05,
                        distributions={"mu": from_table({"geometric": 0.4}, "mu")})
    m = dataclasses.replace(m, sensors=MappingProxyType({"b": Sensor(0.6)}))
    with pytest.raises(ProblemError, match="objective min with then min-steps and a sensor"):
        synthesize(m, then="min-steps")
    with pytest.raises(ProblemError, match=r"objective min with E\(steps\) <= 4"):
        synthesize(m, constraints=["E(steps) <= 4"])
