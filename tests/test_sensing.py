"""The sensed route against an exhaustive expectimax over observation histories, written
here from the semantics (docs/semantics.md, "Sensors that miss events"): hidden
scenarios (event step, report step) enumerated with their probabilities, the task
judged on the trace, the optimum over every observation-based policy by enumerating
histories -- no hazards, no automaton, no information states."""

from __future__ import annotations

import math

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
    """The best probability, over policies that see the world state and the sensor's
    report (never the event), that the robot is at ``goal`` at some step in
    ``[k, k + window]``, ``k`` the event's step: by enumerating observation histories.
    A scenario is ``(k, r, p)``: event at ``k``, first report at ``r`` (None: not within
    the horizon), probability ``p``."""
    scenarios = []
    for k, mu in enumerate(pmf, start=1):
        for r in range(k, horizon + 1):
            scenarios.append((k, r, mu * detect * (1 - detect) ** (r - k)))
        scenarios.append((k, None, mu * (1 - detect) ** (horizon - k + 1)))
    scenarios = [s for s in scenarios if s[2] > 0]

    def best(t: int, state: str, alive: list[tuple[int, int | None, float]]) -> float:
        won = sum(p for k, _, p in alive if k <= t <= k + window and goal in
                  game.propositions(state))
        left = [(k, r, p) for k, r, p in alive
                if not (k <= t <= k + window and goal in game.propositions(state))
                and t < k + window]
        if t == horizon or not left:
            return won
        values = []
        for action in game.actions(state):
            v = 0.0
            for nxt, ps in game.successors(state, action, frozenset()):
                for seen in (True, False):  # the observation: a report at step t + 1?
                    group = [(k, r, p * ps) for k, r, p in left if (r == t + 1) == seen]
                    if group:
                        v += best(t + 1, nxt, group)
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
