"""The sensed route against an exhaustive expectimax over observation histories, written
here from the semantics (docs/semantics.md, "Sensors that miss events"): hidden
scenarios (event step, report step) enumerated with their probabilities, the task
judged on the trace, the optimum over every observation-based policy by enumerating
histories -- no hazards, no automaton, no information states."""

from __future__ import annotations

import itertools
import math
from typing import Any

import pytest

from mitld_lp import ExplicitGame, Model, synthesize
from mitld_lp.sensing.observe import Observation, simulate_sensed

STATION = ExplicitGame(
    initial="mid",
    transitions={
        "mid": {"go": {"st": 0.8, "ditch": 0.2}, "wait": {"mid": 1.0}},
        "st": {"wait": {"st": 0.5, "ditch": 0.5}, "back": {"mid": 0.8, "ditch": 0.2}},
        "ditch": {"stay": {"ditch": 1.0}},
    },
    labels={"st": {"A"}},
)
PMF = (0.25, 0.25, 0.25, 0.25)  # the bus comes at step 1, 2, 3 or 4
WINDOW = 2
SPEC = f"D[pmf({', '.join(map(str, PMF))})] b & F(b & F[0,{WINDOW}] A)"


def expectimax(game: ExplicitGame, pmf: tuple[float, ...], detect: float, window: int,
               goal: str, horizon: int) -> float:
    """:func:`expectimax_many` of one event."""
    return expectimax_many(game, [(pmf, detect, goal, window)], horizon)


def expectimax_many(game: ExplicitGame, events: list[tuple[Any, ...]],
                    horizon: int) -> float:
    """The best probability, over policies that see the world state and the sensors'
    reports (never the events), that for some event ``i`` with step ``k_i`` the robot
    is at ``goal_i`` at some step in ``[k_i, k_i + window_i]``, the events independent;
    by enumerating observation histories.  ``events``: ``(pmf, detect, goal, window)``
    and optionally the sensor's ``delay``.  A scenario fixes every event's step ``k`` and
    first report ``r >= k + delay`` (None: not within the horizon); its probability is
    the product over the events."""
    per_event = []
    for pmf, detect, *_, delay in [(*e, 0) if len(e) == 4 else e for e in events]:
        options = []
        for k, mu in enumerate(pmf, start=1):
            for r in range(k + delay, horizon + 1):
                options.append((k, r, mu * detect * (1 - detect) ** (r - k - delay)))
            options.append((k, None, mu * (1 - detect) ** max(0, horizon - k - delay + 1)))
        per_event.append([o for o in options if o[2] > 0])
    scenarios = [(tuple((k, r) for k, r, _ in combo), math.prod(p for _, _, p in combo))
                 for combo in itertools.product(*per_event)]

    def caught(t: int, state: str, times: tuple[tuple[int, int | None], ...]) -> bool:
        return any(k <= t <= k + e[3] and e[2] in game.propositions(state)
                   for (k, _), e in zip(times, events, strict=True))

    def open_(t: int, times: tuple[tuple[int, int | None], ...]) -> bool:
        return any(t < k + e[3] for (k, _), e in zip(times, events, strict=True))

    def best(t: int, state: str, alive: list) -> float:
        won = sum(p for times, p in alive if caught(t, state, times))
        left = [(times, p) for times, p in alive
                if not caught(t, state, times) and open_(t, times)]
        if t == horizon or not left:
            return won
        values = []
        for action in game.actions(state):
            v = 0.0
            for nxt, ps in game.successors(state, action, frozenset()):
                groups: dict[tuple[bool, ...], list] = {}
                for times, p in left:  # the observation: which events are reported now
                    seen = tuple(r == t + 1 for _, r in times)
                    groups.setdefault(seen, []).append((times, p * ps))
                v += sum(best(t + 1, nxt, group) for group in groups.values())
            values.append(v)
        return won + max(values)

    return best(0, game.initial, scenarios)


@pytest.mark.parametrize("detect", [0.0, 0.3, 0.7, 0.95])
def test_optimum_equals_expectimax_over_observation_histories(detect: float) -> None:
    model = Model.from_game(STATION, SPEC, sensors={"b": {"detect": detect}})
    r = synthesize(model)
    assert r.route == "sensed" and r.certified
    exact = expectimax(STATION, PMF, detect, WINDOW, "A", horizon=len(PMF) + WINDOW)
    assert r.lower - 1e-7 <= exact <= r.upper + 1e-7
    assert r.upper - r.lower < 1e-7  # finite support: nothing truncated


def test_the_sensor_matters_between_blind_and_perfect() -> None:
    """The example is not degenerate: the value grows strictly with ``detect``, from the
    blind optimum to the fully observed one (a route the test does not reuse)."""
    blind = expectimax(STATION, PMF, 0.0, WINDOW, "A", horizon=len(PMF) + WINDOW)
    seen = expectimax(STATION, PMF, 1.0, WINDOW, "A", horizon=len(PMF) + WINDOW)
    full = synthesize(Model.from_game(STATION, SPEC))
    assert abs(full.lower - seen) < 1e-9 and full.route == "plain"
    values = [synthesize(Model.from_game(STATION, SPEC, sensors={"b": {"detect": d}})).lower
              for d in (0.0, 0.5, 0.9)]
    assert abs(values[0] - blind) < 1e-7
    assert blind < values[1] < values[2] < seen


def test_geometric_law_is_truncated_and_bracketed() -> None:
    """A geometric bus is truncated when sensed: the bracket's width is at most the
    epsilon achieved, and it holds the expectimax over a long enough horizon (whose own
    lower and upper ends differ by the scenarios still open at the horizon)."""
    spec = "D[geometric(0.4)] b & F(b & F[0,1] A)"
    model = Model.from_game(STATION, spec, sensors={"b": {"detect": 0.6}}, epsilon=1e-3)
    r = synthesize(model)
    assert r.certified and 0 <= r.upper - r.lower <= r.sta.epsilon_achieved + 1e-9
    horizon = 9
    pmf = tuple(0.4 * 0.6 ** (k - 1) for k in range(1, horizon))  # the rest: after 8
    low = expectimax(STATION, pmf, 0.6, 1, "A", horizon=horizon)
    high = low + 0.6 ** (horizon - 1)  # every bus after step 8 counted as caught
    assert low - 1e-7 <= r.upper and r.lower <= high + 1e-7


def test_simulation_within_its_confidence_interval() -> None:
    model = Model.from_game(STATION, SPEC, sensors={"b": {"detect": 0.5}})
    r = synthesize(model)
    sim = simulate_sensed(model, r.controller, runs=4000, seed=3)
    sigma = math.sqrt(r.lower * (1 - r.lower) / sim.runs)
    assert abs(sim.estimate - r.lower) <= 4.5 * sigma  # the policy's exact value
    assert sim.beyond_model == 0


def test_controller_reads_observations_only() -> None:
    model = Model.from_game(STATION, SPEC, sensors={"b": {"detect": 0.5}})
    c = synthesize(model).controller
    c.reset()
    first = c.act(Observation("mid"))
    assert first in ("go", "wait")
    with pytest.raises(TypeError, match="reports"):
        Observation("mid", reports="b")
    c.reset()
    with pytest.raises(ValueError, match="step 0"):
        c.act(Observation("mid", reports={"b"}))


TWO = ExplicitGame(
    initial="mid",
    transitions={
        "mid": {"to_a": {"sa": 0.8, "ditch": 0.2}, "to_b": {"sb": 0.8, "ditch": 0.2},
                "wait": {"mid": 1.0}},
        "sa": {"back": {"mid": 0.8, "ditch": 0.2}},
        "sb": {"back": {"mid": 0.8, "ditch": 0.2}},
        "ditch": {"stay": {"ditch": 1.0}},
    },
    labels={"sa": {"A"}, "sb": {"B"}},
)
PMF1, PMF2 = (0.3, 0.3, 0.4), (0.4, 0.3, 0.3)
SPEC2 = ("(D[pmf(0.3, 0.3, 0.4)] b1 & F(b1 & F[0,1] A)) | "
         "(D[pmf(0.4, 0.3, 0.3)] b2 & F(b2 & F[0,1] B))")


@pytest.mark.parametrize("d1, d2", [(0.6, 0.4), (0.5, 1.0), (1.0, 0.3), (0.0, 0.8), (0.0, 0.0)])
def test_two_events_equal_expectimax(d1: float, d2: float) -> None:
    """Two independent events, each with its own sensor (or none: ``detect = 1``); the
    posterior is a product over the events and a seen event sits beside hidden ones."""
    sensors = {e: {"detect": d} for e, d in (("b1", d1), ("b2", d2)) if d < 1}
    r = synthesize(Model.from_game(TWO, SPEC2, sensors=sensors))
    assert r.certified and r.route == ("sensed" if sensors else "plain")
    exact = expectimax_many(TWO, [(PMF1, d1, "A", 1), (PMF2, d2, "B", 1)], horizon=5)
    assert r.lower - 1e-7 <= exact <= r.upper + 1e-7
    assert r.upper - r.lower < 1e-7


def test_two_events_example_is_not_degenerate() -> None:
    def value(d1: float, d2: float) -> float:
        return expectimax_many(TWO, [(PMF1, d1, "A", 1), (PMF2, d2, "B", 1)], horizon=5)

    assert value(0.0, 0.0) < value(0.6, 0.4) < value(1.0, 1.0)


def test_controller_refuses_an_unknown_report() -> None:
    c = synthesize(Model.from_game(STATION, SPEC, sensors={"b": {"detect": 0.5}})).controller
    c.reset()
    c.act(Observation("mid"))
    with pytest.raises(ValueError, match="'bus' is not an event"):
        c.act(Observation("mid", reports={"bus"}))


@pytest.mark.parametrize("detect, delay", [(0.7, 1), (1.0, 1), (0.5, 2)])
def test_reporting_delay_equals_expectimax(detect: float, delay: int) -> None:
    """A sensor whose report can come only ``delay`` steps after the event."""
    sensors = {"b": {"detect": detect, "delay": delay}}
    r = synthesize(Model.from_game(STATION, SPEC, sensors=sensors))
    assert r.route == "sensed" and r.certified
    exact = expectimax_many(STATION, [(PMF, detect, "A", WINDOW, delay)],
                            horizon=len(PMF) + WINDOW)
    assert r.lower - 1e-7 <= exact <= r.upper + 1e-7
    assert r.upper - r.lower < 1e-7
    sim = simulate_sensed(Model.from_game(STATION, SPEC, sensors=sensors), r.controller,
                          runs=3000, seed=5)
    assert abs(sim.estimate - r.lower) <= 4.5 * math.sqrt(r.lower * (1 - r.lower) / 3000)


def test_delay_costs() -> None:
    """Not degenerate: a later report is worth less (expectimax alone)."""
    def value(delay: int) -> float:
        return expectimax_many(STATION, [(PMF, 0.7, "A", WINDOW, delay)],
                               horizon=len(PMF) + WINDOW)

    assert value(0) > value(1) > value(2)


def test_a_sensed_answer_is_the_one_result_with_its_sensors_part() -> None:
    """The sensed route answers with the same Result type and JSON schema as every other
    route (it had its own SensedResult), its stages timed alike, the policy table over
    information states, the sensor in the summary."""
    from mitld_lp import Result
    from mitld_lp.report import SUMMARY_KEYS

    r = synthesize(Model.from_game(STATION, SPEC, sensors={"b": {"detect": 0.5}}))
    assert type(r) is Result and r.route == "sensed" and r.certified
    assert r.mdp is r.belief.mdp and set(r.sensors) == {"b"}
    assert {"automaton", "product", "solve"} <= set(r.timings)
    summary = r.summary()
    assert tuple(summary) == SUMMARY_KEYS and summary["sensors"] == {"b": 0.5}
    rows = r.policy_table()
    assert rows and all(0.0 <= row["value"] <= 1.0 for row in rows)
