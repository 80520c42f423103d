"""End-to-end synthesis: values against Storm's reference numbers and hand calculations,
the certified bracket, the controller and Monte-Carlo simulation."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import reference_values

from mitld_lp import GridWorld, Model, Observation, RunStatus, load_model, simulate, synthesize
from mitld_lp.solvers.result import Status

MODELS = Path(__file__).resolve().parent.parent / "models"
BUS_CASE1 = MODELS / "bus_grid.toml"
BUS_CASE2 = MODELS / "bus_grid_case2.toml"
RED_LIGHT = MODELS / "red_light.toml"

# Pmax computed by Storm on an independent PRISM encoding of the same world (issue 5).
STORM_CASE1 = 0.9244053
STORM_CASE2 = 0.9138372


@pytest.mark.parametrize(("path", "expected"), [(BUS_CASE1, STORM_CASE1), (BUS_CASE2, STORM_CASE2)])
@pytest.mark.parametrize(
    ("method", "backend"), [("lp", "cvxpy"), ("lp", "direct"), ("vi", "cvxpy")]
)
def test_canonical_model_matches_storm(path, expected, method, backend):
    r = synthesize(load_model(path), method=method, backend=backend)
    assert r.status is Status.OPTIMAL
    assert r.certified, r.failed_checks
    # Geometric buses are memoryless: nothing is truncated and the bracket is a point.
    assert r.sta.epsilon_achieved == 0.0
    assert r.sta.truncation_points == {}
    assert r.lower == pytest.approx(expected, abs=1e-6)
    assert r.upper == pytest.approx(expected, abs=1e-6)
    assert r.lower_model.value == pytest.approx(expected, abs=1e-6)


def _corridor(width: int, slip: float) -> GridWorld:
    return GridWorld.make(width, 1, start=(0, 0), slip=slip, regions={"A": [(width - 1, 0)]})


def test_hand_value_deterministic_corridor():
    # A is two moves away and must be occupied at the very step the event happens; the
    # event comes at step 1, 2, 3 with 0.2, 0.3, 0.4 and never with 0.1.  The robot is
    # at A from step 2 on, so it succeeds exactly when 2 <= K <= 3: 0.3 + 0.4.
    r = synthesize(Model.from_game(_corridor(3, 0.0), "D[pmf(0.2, 0.3, 0.4)] b & F(b & F[0,0] A)"))
    assert r.certified, r.failed_checks
    assert r.lower == pytest.approx(0.7, abs=1e-7)
    assert r.upper == pytest.approx(0.7, abs=1e-7)


def test_hand_value_slippery_corridor():
    # 2x1 corridor, slip 0.1: moving E reaches A with 0.8, else both perpendicular moves
    # leave the grid and the robot stays.  P(at A at step 1) = 0.8, at step 2 = 0.8 +
    # 0.2 * 0.8 = 0.96.  The event is at step 1 or 2 with 1/2 each: 0.5*0.8 + 0.5*0.96.
    r = synthesize(Model.from_game(_corridor(2, 0.1), "D[pmf(0.5, 0.5)] b & F(b & F[0,0] A)"))
    assert r.certified, r.failed_checks
    assert r.lower == pytest.approx(0.88, abs=1e-7)
    assert r.upper == pytest.approx(0.88, abs=1e-7)


def test_truncation_bracket_contains_the_exact_value():
    # The exact value with a truncated (Poisson) event, from a model without truncation:
    # the same law written as an explicit pmf over a long support is exact.  The bracket
    # of the truncated model must contain it, and tighten as epsilon shrinks.
    from scipy.stats import poisson

    lam = 2.0
    masses = [float(poisson.pmf(k - 1, lam)) for k in range(1, 40)]
    spec_exact = f"D[pmf({', '.join(repr(m) for m in masses)})] b & F(b & F[0,1] A)"
    world = GridWorld.make(4, 1, start=(0, 0), slip=0.1, regions={"A": [(3, 0)]})
    exact = synthesize(Model.from_game(world, spec_exact))
    assert exact.sta.truncation_points == {}
    widths = []
    for eps in (0.2, 0.05, 0.01):
        spec = f"D[poisson({lam})] b & F(b & F[0,1] A)"
        r = synthesize(Model.from_game(world, spec), epsilon=eps)
        assert r.certified, r.failed_checks
        assert r.sta.truncation_points, "a Poisson law has no constant hazard: it is truncated"
        assert r.lower - 1e-7 <= exact.lower <= r.upper + 1e-7
        assert r.upper - r.lower <= r.sta.epsilon_achieved + 1e-7
        assert r.sta.epsilon_achieved <= eps
        widths.append(r.upper - r.lower)
    assert widths[0] >= widths[1] >= widths[2]


def test_controller_follows_the_policy_and_tracks_the_automaton():
    model = load_model(BUS_CASE1)
    r = synthesize(model)
    c = r.controller
    c.reset()
    first = c.act(Observation((0, 0)))
    # The first move must be optimal: taking it and then playing well reaches Storm's
    # value.  Its Q-value, from interval iteration's sound lower bounds (not from the
    # policy that chose it), must reach 0.9244053.
    mdp, it = r.mdp, r.lower_model.iteration
    (row,) = [c_ for c_ in mdp.choices(mdp.initial) if mdp.action_name(c_) == first]
    q_first = float((mdp.matrix[[row]] @ it.lower)[0])
    assert q_first == pytest.approx(STORM_CASE1, abs=1e-6)
    assert c.pending == frozenset({"b1", "b2"})
    # Bus 1 arrives while the robot is at A: the task is done at once (k = j).
    assert c.act(Observation((1, 2), frozenset({"b1"}))) is None
    assert c.status is RunStatus.ACCEPTED
    # A second run: bus 2 arrives while the robot is far from B; after 4 more steps away
    # from B (and bus 1 never coming), the B obligation has expired.
    c.reset()
    c.act(Observation((0, 0)))
    c.act(Observation((0, 1), frozenset({"b2"})))
    assert c.pending == frozenset({"b1"})
    for _ in range(4):
        assert c.act(Observation((0, 3))) is not None
    assert c.status is RunStatus.RUNNING
    assert c.act(Observation((1, 2), frozenset({"b1"}))) is None  # bus 1 saves the day
    assert c.status is RunStatus.ACCEPTED
    with pytest.raises(ValueError, match="second time"):
        c.act(Observation((0, 0), frozenset({"b1"})))


def test_simulation_confidence_interval_contains_the_certified_value():
    model = load_model(RED_LIGHT)
    r = synthesize(model)
    sim = simulate(model, r.controller, runs=8000, seed=7, max_steps=200)
    # The controller's true value lies between its value in the lower model and the
    # upper bound; the 95% interval must meet that range.
    assert sim.ci_low <= r.upper + 1e-9 and sim.ci_high >= r.lower - 1e-9
    assert sim.runs == 8000
    assert sim.beyond_model > 0  # P(K > T) > 0: some runs outlive the model
    assert 0 <= sim.successes <= sim.runs


def test_simulation_of_canonical_model():
    model = load_model(BUS_CASE2)
    r = synthesize(model)
    sim = simulate(model, r.controller, runs=3000, seed=3, max_steps=60)
    assert sim.ci_low <= STORM_CASE2 <= sim.ci_high


def test_wilson_interval_by_hand():
    from mitld_lp.util.rollouts import wilson as _wilson

    lo, hi = _wilson(50, 100)
    # Wilson score interval for 50/100 at 95%: 0.5 +- 1.96*sqrt(0.25/100 + 1.96^2/40000)
    # / (1 + 1.96^2/100), centred at 0.5.
    z = 1.959963984540054
    half = z * math.sqrt(0.25 / 100 + z * z / 40000) / (1 + z * z / 100)
    assert lo == pytest.approx(0.5 - half) and hi == pytest.approx(0.5 + half)


def test_unknown_method_is_an_error():
    with pytest.raises(ValueError, match="method"):
        synthesize(load_model(BUS_CASE1), method="magic")  # type: ignore[arg-type]


def test_solver_failure_is_a_status_not_an_exception(monkeypatch):
    # a solver that fails on every LP (an unknown solver's name is refused by the
    # problem before any work, so the failure is made here, inside the backend)
    from mitld_lp.solvers import lp_backends

    monkeypatch.setattr(lp_backends, "_run_backend",
                        lambda *args, **kw: lp_backends.Raw(Status.FAILED, "made to fail"))
    from mitld_lp.solvers import lp_blocks  # every block to the solver, none certified
    monkeypatch.setattr(lp_blocks, "certified_greedy", lambda *args: None)
    r = synthesize(load_model(BUS_CASE1))
    assert r.lower_model.lp is not None
    assert r.lower_model.lp.status is Status.FAILED
    assert not r.certified
    assert any(c.name == "LP solved" for c in r.failed_checks)
    # The interval-iteration fallback still gives a sound bracket.
    assert r.lower == pytest.approx(STORM_CASE1, abs=1e-6)


@pytest.mark.parametrize("path", [BUS_CASE1, RED_LIGHT])  # red_light: truncated
def test_policy_is_optimal_in_every_state(path):
    # Pmax of every product state by the value LP (scipy, no graph analysis, no end
    # components collapsed), against the exact value of the returned policy in that
    # state: the policy is optimal everywhere, not only where it goes from the start.
    r = synthesize(load_model(path))
    mdp = r.mdp
    for model, target in ((r.lower_model, mdp.target),
                          (r.upper_model, mdp.target | mdp.truncated)):
        live = ~(mdp.target | mdp.sink | mdp.truncated)
        rows = model.policy[live]
        starts, ends = mdp.row_groups[:-1][live], mdp.row_groups[1:][live]
        assert np.all((rows >= starts) & (rows < ends))
        pmax = reference_values(mdp, target)
        np.testing.assert_allclose(model.policy_values, pmax, atol=1e-6)
        assert model.policy_values[mdp.initial] == pytest.approx(
            r.lower if model is r.lower_model else r.upper, abs=1e-6)


def test_controller_rejects_once_both_deadlines_are_missed():
    # Both buses come at step 1 while the robot is in the far corner (3, 3), three moves
    # from A = (1, 2) and from B = (3, 0); the deadline is step 1 + 3 = 4.  At step 1
    # three perfect moves can still make it; if the robot is still at (3, 3) at step 2,
    # nothing can satisfy the task any more (no event is left), so the run is rejected
    # rather than continued.
    r = synthesize(load_model(BUS_CASE1))
    c = r.controller
    c.reset()
    c.act(Observation((3, 3)))
    assert c.act(Observation((3, 3), frozenset({"b1", "b2"}))) is not None
    assert c.status is RunStatus.RUNNING
    assert c.act(Observation((3, 3))) is None
    assert c.status is RunStatus.REJECTED


def test_the_reduced_matrix_is_released_before_the_exact_evaluations(monkeypatch):
    # The quotients (each holding a copy of most transitions) are garbage by the time the
    # policies are evaluated, where memory peaks; counted among the objects the collector
    # tracks, at the LP (where they must be alive: the count can be positive) and at
    # each evaluation.
    import gc

    from mitld_lp.solvers import certify, lp
    from mitld_lp.solvers.quotient import Quotient

    def alive() -> int:
        return sum(isinstance(o, Quotient) for o in gc.get_objects())

    seen: dict[str, list[int]] = {"lp": [], "evaluate": []}

    def counting(name, fn):
        def wrapped(*args, **kwargs):
            seen[name].append(alive())
            return fn(*args, **kwargs)
        return wrapped

    monkeypatch.setattr(lp, "solve_lp", counting("lp", lp.solve_lp))
    monkeypatch.setattr(certify, "chain", counting("evaluate", certify.chain))
    r = synthesize(load_model(RED_LIGHT))  # truncated: two models, two quotients
    assert r.sta.truncation_points and r.certified
    assert len(seen["lp"]) == 2 and min(seen["lp"]) == 2
    assert seen["evaluate"] == [0, 0]
    assert r.upper_model.prob0.dtype == bool and r.upper_model.prob0.shape == (
        r.mdp.n_states,)
    with pytest.raises(AttributeError, match="prob0"):
        r.upper_model.quotient  # noqa: B018 - the removed field says where to look


def test_the_builders_memory_is_trimmed_only_for_large_products(monkeypatch):
    import mitld_lp.routes.plain as synthesis_module

    calls = []
    monkeypatch.setattr(synthesis_module, "release_free_memory", lambda: calls.append(1))
    model = load_model(BUS_CASE1)  # 6,153 transitions
    synthesize(model)
    assert calls == []
    monkeypatch.setattr(synthesis_module, "TRIM_FROM_TRANSITIONS", 6_000)
    synthesize(model)
    assert calls == [1]
