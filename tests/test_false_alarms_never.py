"""Sensors with false alarms on an event law that may never happen (``never > 0``):
bracketed (mitld_lp/routes/sensed_never.py) between the controller that ignores the
reports and a sensor without false alarms at least as informative.  The exact optimum
over every controller that reads every step's report (tests/test_sensing_tasks.py's
``expectimax_every_step``, in fractions, over a horizon that decides each task) must lie
in the bracket, for either objective; the bracket is certified only where its ends meet;
as ``never -> 0`` it holds the answer for the law that surely happens; a constraint that
cannot bind gives the same bracket on route sensed-constrained."""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import pytest
from test_sensing_tasks import PUSHED, STATION, avoided, both, caught, expectimax_every_step

from mitld_lp import Model, synthesize
from mitld_lp.distributions import pmf

LAW = (0.25, 0.25, 0.3)  # the bus at step 1, 2 or 3, never with probability 0.2
MASSES = tuple(Fraction(str(x)) for x in LAW)
HORIZON = 5  # each task below is decided by step 5 (the bus by step 3, windows of 1)

TASKS: dict[str, tuple[Any, str, Any]] = {
    "co-safe": (PUSHED, "F(b & F[0,1] A)", caught(PUSHED, "A", 1)),
    "safety": (PUSHED, "G !(b & A)", avoided(PUSHED, ["A"])),
    # the co-safe task's complement: its minimum reads the reports (1 - its maximum)
    "not caught": (PUSHED, "G !(b & F[0,1] A)",
                   lambda trace, times: not caught(PUSHED, "A", 1)(trace, times)),
    "obligation": (STATION, "F(b & F[0,1] A) & G[0,5] !h",
                   both(caught(STATION, "A", 1), lambda trace, _: "ditch" not in trace)),
}


def _model(task: str, detect: float, false_alarm: float, law: tuple[float, ...] = LAW,
           delay: int = 0) -> Model:
    world, spec, _ = TASKS[task]
    return Model.from_game(world, spec, events={"b": pmf(list(law))},
                           sensors={"b": {"detect": detect, "false_alarm": false_alarm,
                                          "delay": delay}})


def _exact(task: str, detect: Fraction, false_alarm: Fraction, objective: str,
           delay: int = 0) -> Fraction:
    """The optimum over controllers that read every step's report (the expectimax in
    fractions over a horizon that decides the task)."""
    world, _, judge = TASKS[task]
    return expectimax_every_step(world, MASSES, detect, judge, HORIZON,
                                 false_alarm=false_alarm, delay=delay,
                                 sense=max if objective == "max" else min)


@pytest.mark.parametrize("task, detect, false_alarm, delay", [
    ("co-safe", "0.8", "0.2", 0), ("co-safe", "0.3", "0.6", 0), ("safety", "0.3", "0.6", 0),
    ("not caught", "0.8", "0.2", 0),
    ("safety", "0.7", "0.1", 1), ("obligation", "0.7", "0.1", 1)])
def test_exact_optimum_in_the_bracket(task: str, detect: str, false_alarm: str,
                                      delay: int) -> None:
    """Both objectives: the bracket holds the every-step expectimax (fractions, no
    tolerance), with a sensor better than its false alarms and one worse than them
    (``detect < false_alarm``: a report then speaks against the bus), with a delay."""
    model = _model(task, float(detect), float(false_alarm), delay=delay)
    for objective in ("max", "min"):
        exact = _exact(task, Fraction(detect), Fraction(false_alarm), objective, delay)
        r = synthesize(model, objective=objective)
        assert r.route == "sensed"
        assert Fraction(r.lower) <= exact <= Fraction(r.upper), (r.lower, float(exact),
                                                                 r.upper)
        check = next(c for c in r.checks if c.name.startswith("false alarms, law"))
        # certified exactly where the two ends meet (the solves' own widths: 1e-9 here)
        assert check.passed == (r.upper - r.lower <= 1e-7)
        assert r.certified == check.passed


@pytest.mark.parametrize("task, objective", [("co-safe", "max"), ("not caught", "min")])
def test_gap_where_the_reports_matter(task: str, objective: str) -> None:
    """The co-safe maximum and its complement's minimum: the reports are worth reading
    (the every-step expectimax beats the blind one's, both in fractions), so the bracket
    is not certified, its end on the controller's side (``lower`` for a maximum,
    ``upper`` for a minimum) is the blind controller's value, and its check names the
    cause."""
    exact = _exact(task, Fraction(8, 10), Fraction(2, 10), objective)
    blind = _exact(task, Fraction(0), Fraction(0), objective)
    assert blind != exact and (max if objective == "max" else min)(blind, exact) == exact
    r = synthesize(_model(task, 0.8, 0.2), objective=objective)
    assert not r.certified
    ours = r.lower if objective == "max" else r.upper
    assert abs(Fraction(ours) - blind) <= Fraction(1, 10**9)  # the blind controller
    check = next(c for c in r.checks if c.name.startswith("false alarms, law"))
    assert not check.passed and "not read" in check.detail
    assert r.width["information"] > 1e-3


def test_bracket_holds_the_sure_answer_as_never_vanishes() -> None:
    """As ``never -> 0`` (here 1e-9 missing mass) the bracket holds the answer of the law
    that surely happens (the information-state product with every report counted),
    which differs from it by at most the missing mass."""
    sure_law = (0.25, 0.25, 0.5)
    for task in ("co-safe", "obligation"):
        sure = synthesize(_model(task, 0.8, 0.2, law=sure_law))
        assert sure.certified
        tiny = synthesize(_model(task, 0.8, 0.2, law=(0.25, 0.25, 0.5 - 1e-9)))
        assert tiny.lower - 1e-8 <= sure.lower and sure.upper <= tiny.upper + 1e-8


@pytest.mark.parametrize("task", ["co-safe", "safety", "obligation"])
def test_a_slack_constraint_gives_the_same_bracket(task: str) -> None:
    """With constraints the bracket is built on route sensed-constrained (its own checks:
    tests/test_false_alarms_never_constrained.py): a bound no policy can break (``P(F
    h) <= 1``) gives the unconstrained bracket's controller end (the blind controller's
    value) and the every-step expectimax inside (the informed end's truncation differs
    between the two routes' products); a co-safe and an obligation task's reports are
    worth reading, the safety task's are not (the ends meet within the truncation)."""
    model = _model(task, 0.8, 0.2)
    plain = synthesize(model)
    r = synthesize(model, constraints=["P(F h) <= 1"])
    assert plain.route == "sensed" and r.route == "sensed-constrained"
    assert abs(r.lower - plain.lower) <= 1e-7
    exact = _exact(task, Fraction(8, 10), Fraction(2, 10), "max")
    assert Fraction(r.lower) <= exact <= Fraction(r.upper)
    # certified on both routes or neither: whether reading the reports could pay
    assert r.certified == plain.certified == (task == "safety")


def test_exported_chain_and_rollouts_give_the_controllers_value(tmp_path: Any) -> None:
    """The controller returned ignores the reports it is given: ``export --chain``'s
    chain, built from the posed sensor (every step's report drawn from the true event
    time, then dropped), gives in Storm (exact arithmetic) the bracket's lower end, and
    rollouts of the posed model never meet an observation the controller cannot read."""
    stormpy = pytest.importorskip("stormpy")
    from mitld_lp.running.chain import write_chain
    from mitld_lp.sensing.observe import simulate_sensed

    model = _model("obligation", 0.8, 0.2)
    r = synthesize(model)
    path = write_chain(r, tmp_path / "c.drn")
    chain = stormpy.build_model_from_drn[stormpy.Rational](str(path))
    value = Fraction(str(stormpy.model_checking(
        chain, stormpy.parse_properties('P=? [F "accept"]')[0]).get_value(
            chain.initial_states[0])))
    assert abs(value - Fraction(r.lower)) <= Fraction(1, 10**9)
    sim = simulate_sensed(model, r.controller, runs=2000, seed=5, max_steps=12)
    assert sim.beyond_model == 0
    sigma = (r.lower * (1 - r.lower) / sim.runs) ** 0.5
    assert abs(sim.estimate - r.lower) <= 4.5 * sigma
