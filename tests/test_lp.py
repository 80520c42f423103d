"""The occupancy LP: hand values, certificates, backends, failures, random MDPs.

Reference values come from routes that share nothing with ``solve_lp``: hand
computation, and the classic *value* LP ``min sum v  s.t.  v(s) >= sum P(c,.) v`` for
every choice, ``v(target) = 1``, ``0 <= v <= 1`` (solved by scipy's linprog on the
untouched MDP, no graph analysis, no MEC collapse); its least solution is Pmax.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cvxpy as cp
import numpy as np
import pytest
import scipy.sparse as sp
from conftest import HAND, HAND_VALUES, build_mdp, reference_values

from mitld_lp.mdp import MDP
from mitld_lp.model import Model
from mitld_lp.solvers import (
    Layout,
    LPResult,
    Status,
    evaluate_policy,
    interval_iteration,
    occupancy_lp,
    solve_lp,
)
from mitld_lp.solvers.quotient import prob0_max
from mitld_lp.testing import random_mdp

# HAND and its hand values: tests/conftest.py.

# A self-loop next to an exit: 0 'wait' (loop) | 'try' -> 0.6 target, 0.4 sink.
LOOP = build_mdp(
    [[("wait", {0: 1.0}), ("try", {1: 0.6, 2: 0.4})], [], []], target=[1], sink=[2]
)

# Initial state inside a 3-state MEC (a ring 0 -> 1 -> 2 -> 0 by 'next') whose only
# good exit is at 2 ('jump': 0.9 target); 0 also has a bad exit 'bail' (0.2 target).
RING = build_mdp(
    [
        [("next", {1: 1.0}), ("bail", {3: 0.2, 4: 0.8})],
        [("next", {2: 1.0})],
        [("next", {0: 1.0}), ("jump", {3: 0.9, 4: 0.1})],
        [],
        [],
    ],
    target=[3],
    sink=[4],
)

BACKENDS = [("cvxpy", "CLARABEL"), ("cvxpy", "HIGHS"), ("direct", "CLARABEL")]


def check_certificates(mdp: MDP, target: np.ndarray, r: LPResult, tol: float) -> None:
    """Dual feasibility (Bellman inequalities) and complementary slackness, on ``mdp``."""
    assert r.values is not None and r.occupancy is not None
    v = r.values
    owner = mdp.choice_state()
    active = ~target[owner] & ~prob0_max(mdp, target)[owner]
    slack = v[owner] - mdp.matrix @ v  # v(s) - sum_s' P(c,s') v(s')  >= 0
    assert np.all(slack[active] >= -tol)
    assert np.all(r.occupancy >= 0)
    assert np.all(r.occupancy[~active] == 0)
    assert np.all(r.occupancy * np.maximum(slack, 0) <= tol)
    assert r.primal_objective == pytest.approx(r.dual_objective, abs=tol)


@pytest.mark.parametrize(("backend", "solver"), BACKENDS)
def test_hand_mdp_values_policy_and_certificates(backend: str, solver: str) -> None:
    r = solve_lp(HAND, HAND.target, backend=backend, solver=solver)  # type: ignore[arg-type]
    assert r.status == Status.OPTIMAL, r.message
    assert r.value == pytest.approx(0.25, abs=1e-8)
    assert r.primal_objective == pytest.approx(0.25, abs=1e-8)
    assert r.values is not None and r.policy is not None
    # States 0, 1, 4 are visited from 0; 6 is not, its value is only an upper bound.
    np.testing.assert_allclose(r.values[[0, 1, 2, 3, 4, 5]], HAND_VALUES[:6], atol=1e-8)
    assert r.values[6] >= 1 - 1e-8
    check_certificates(HAND, HAND.target, r, 1e-7)
    # 0 goes, 4 takes exit d, 1 walks to 4 with b (a would lose value); 2, 3 stop.
    assert r.policy.tolist()[:5] == [1, 3, -1, -1, 7]
    assert evaluate_policy(HAND, HAND.target, r.policy)[0] == pytest.approx(0.25, abs=1e-12)
    assert r.backend == backend and r.solver == solver and r.seconds > 0
    assert r.lp_shape == (3, 5)


def test_everywhere_gives_the_value_function_of_every_state() -> None:
    r = solve_lp(HAND, HAND.target, everywhere=True)
    assert r.status == Status.OPTIMAL and r.values is not None and r.policy is not None
    np.testing.assert_allclose(r.values, HAND_VALUES, atol=1e-8)
    np.testing.assert_allclose(evaluate_policy(HAND, HAND.target, r.policy), HAND_VALUES,
                               atol=1e-12)
    assert r.value == pytest.approx(0.25, abs=1e-8)
    assert r.primal_objective == pytest.approx(0.25 + 0.5 + 1.0, abs=1e-7)  # one per MEC


def test_self_loop_with_exit() -> None:
    r = solve_lp(LOOP, LOOP.target)
    assert r.value == pytest.approx(0.6, abs=1e-8)
    assert r.policy is not None and r.policy[0] == 1  # 'try', never 'wait'
    assert r.occupancy is not None and r.occupancy[0] == 0  # the loop is not in the LP


def test_initial_inside_mec_walks_to_the_best_exit() -> None:
    r = solve_lp(RING, RING.target, backend="direct")
    assert r.value == pytest.approx(0.9, abs=1e-8)
    assert r.policy is not None
    assert r.policy.tolist() == [0, 2, 4, -1, -1]  # next, next, jump
    exact = evaluate_policy(RING, RING.target, r.policy)
    np.testing.assert_allclose(exact[:3], 0.9, atol=1e-12)


def test_initial_state_decided_by_graph_analysis() -> None:
    at_target = build_mdp([[("a", {1: 1.0})], []], initial=1, target=[1])
    r = solve_lp(at_target, at_target.target)
    assert r.status == Status.OPTIMAL and r.value == 1.0 and r.solver == ""
    assert "target" in r.message
    assert r.values is not None and np.isnan(r.values[0])
    assert r.policy is not None and r.policy.tolist() == [0, -1]
    hopeless = build_mdp([[("a", {1: 1.0})], [], []], target=[2], sink=[1])
    r = solve_lp(hopeless, hopeless.target)
    assert r.status == Status.OPTIMAL and r.value == 0.0 and "prob-0" in r.message


def test_prob_one_through_an_end_component() -> None:
    # 0 'retry' -> 0.5 back to 0, 0.5 to 1; 1 -> target.  Pmax = 1 without a MEC exit
    # that is certain: the loop is not an end component (it leaves with 1/2).
    mdp = build_mdp([[("retry", {0: 0.5, 1: 0.5})], [("go", {2: 1.0})], []], target=[2])
    r = solve_lp(mdp, mdp.target, backend="direct")
    assert r.value == pytest.approx(1.0, abs=1e-8)
    assert r.occupancy is not None
    assert r.occupancy[0] == pytest.approx(2.0, abs=1e-6)  # expected visits of 0


def test_naive_lp_without_mec_collapse_is_unbounded() -> None:
    """On the maybe states with every choice kept, the flow polytope has a ray."""
    maybe = ~LOOP.target & ~prob0_max(LOOP, LOOP.target)  # only state 0
    owner = LOOP.choice_state()
    cols = np.flatnonzero(maybe[owner])  # 'wait' (loop) and 'try'
    dense = LOOP.matrix.toarray()
    a_naive = np.eye(LOOP.n_states)[np.ix_(maybe, owner[cols])] - dense[np.ix_(cols, maybe)].T
    ray = np.array([1.0, 0.0])  # push any amount of flow round the self-loop
    np.testing.assert_allclose(a_naive @ ray, 0.0)
    y = cp.Variable(cols.size)
    cons = [a_naive @ y == 1.0, y >= 0]
    naive = cp.Problem(cp.Maximize(cp.sum(y)), cons)  # expected time: infinite
    naive.solve(solver="HIGHS")
    assert naive.status in (cp.UNBOUNDED, cp.UNBOUNDED_INACCURATE)
    # Ours: the same objective is bounded (expected number of steps = 1).
    lp = occupancy_lp(LOOP, LOOP.target)
    z = cp.Variable(lp.objective.size)
    ours = cp.Problem(cp.Maximize(cp.sum(z)), [lp.a_eq @ z == lp.b_eq, z >= 0])
    ours.solve(solver="HIGHS")
    assert ours.status == cp.OPTIMAL and ours.value == pytest.approx(1.0)


def test_backends_agree_and_scs_too() -> None:
    mdp = random_mdp(80, seed=3, locality=5, self_loop_fraction=0.2)
    results = [solve_lp(mdp, mdp.target, backend=b, solver=s) for b, s in BACKENDS]  # type: ignore[arg-type]
    scs = solve_lp(mdp, mdp.target, solver="SCS", tol=1e-8)
    assert scs.status.has_solution
    values = [r.value for r in results]
    assert max(values) - min(values) < 1e-7
    assert scs.value == pytest.approx(values[0], abs=1e-5)


# ------------------------------------------------------------------------------------
# Failures are statuses.
# ------------------------------------------------------------------------------------


def test_unknown_solver_is_a_status_listing_installed_ones() -> None:
    r = solve_lp(HAND, HAND.target, solver="NO_SUCH_SOLVER")
    assert r.status == Status.FAILED
    assert "NO_SUCH_SOLVER" in r.message and "CLARABEL" in r.message
    assert r.values is None and np.isnan(r.value)


def test_bad_backend_and_direct_with_other_solver() -> None:
    assert solve_lp(HAND, HAND.target, backend="nope").status == Status.FAILED  # type: ignore[arg-type]
    r = solve_lp(HAND, HAND.target, backend="direct", solver="HIGHS")
    assert r.status == Status.FAILED and "CLARABEL" in r.message


def test_iteration_limit_is_a_status() -> None:
    mdp = random_mdp(60, seed=1)
    r = solve_lp(mdp, mdp.target, backend="direct", solver_options={"max_iter": 1})
    assert r.status == Status.MAX_ITERATIONS and "MaxIterations" in r.message
    r = solve_lp(mdp, mdp.target, backend="cvxpy", solver_options={"max_iter": 1})
    assert r.status == Status.MAX_ITERATIONS and r.values is None
    assert r.message.startswith("cvxpy/CLARABEL: user_limit")
    r = solve_lp(mdp, mdp.target, backend="direct", solver_options={"no_such": 1})
    assert r.status == Status.FAILED and "no_such" in r.message


# ------------------------------------------------------------------------------------
# Random MDPs: every route against the value LP.
# ------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(10))
def test_random_mdps_all_routes_agree(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(20, 201))
    mdp = random_mdp(
        n, seed=seed, target_fraction=0.03 + 0.05 * rng.random(),
        sink_fraction=0.02 + 0.1 * rng.random(), self_loop_fraction=0.3 * rng.random(),
        max_choices=int(rng.integers(1, 5)), max_successors=int(rng.integers(1, 5)),
        locality=None if seed % 3 == 0 else int(rng.integers(2, 8)),
    )
    target = mdp.target
    maybe = ~target & ~prob0_max(mdp, target)
    assert maybe.any()
    ref = reference_values(mdp, target)
    # Start where the optimum is least trivial (closest to 1/2).
    mdp = replace(mdp, initial=int(np.argmin(np.where(maybe, np.abs(ref - 0.5), np.inf))))
    vi = interval_iteration(mdp, target, gap="max", progress=False)
    assert vi.status == Status.OPTIMAL
    np.testing.assert_allclose(vi.lower, ref, atol=1e-7)
    np.testing.assert_allclose(vi.upper, ref, atol=1e-7)
    for backend, solver in BACKENDS:
        r = solve_lp(mdp, target, backend=backend, solver=solver)  # type: ignore[arg-type]
        assert r.status == Status.OPTIMAL, r.message
        assert r.value == pytest.approx(ref[mdp.initial], abs=1e-7)
        assert r.values is not None and r.policy is not None
        assert np.all(r.values >= ref - 1e-7)  # duals are upper bounds everywhere
        check_certificates(mdp, target, r, 1e-6)
        exact = evaluate_policy(mdp, target, r.policy)
        assert exact[mdp.initial] == pytest.approx(ref[mdp.initial], abs=1e-7)
    full = solve_lp(mdp, target, everywhere=True, backend="direct")
    assert full.values is not None and full.policy is not None
    np.testing.assert_allclose(full.values, ref, atol=1e-7)
    np.testing.assert_allclose(evaluate_policy(mdp, target, full.policy), ref, atol=1e-7)
    # The randomised policy is a distribution in every acting state.
    assert full.randomized is not None
    sums = np.add.reduceat(full.randomized, mdp.row_groups[:-1])
    acting = full.policy >= 0
    np.testing.assert_allclose(sums[acting], 1.0, atol=1e-9)
    assert np.all(sums[~acting] == 0)


def test_upper_model_target_includes_truncated() -> None:
    # 0 'go' -> 0.5 target, 0.25 truncated, 0.25 sink.
    mdp = build_mdp([[("go", {1: 0.5, 2: 0.25, 3: 0.25})], [], [], []],
                    target=[1], truncated=[2], sink=[3])
    lower = solve_lp(mdp, mdp.target)
    upper = solve_lp(mdp, mdp.target | mdp.truncated)
    assert lower.value == pytest.approx(0.5, abs=1e-8)
    assert upper.value == pytest.approx(0.75, abs=1e-8)


def test_the_lp_is_the_hand_written_one_and_its_arrays_are_read_only() -> None:
    # RING's ring {0, 1, 2} is one end component: collapsed to one LP row, whose two
    # exits bail (choice 1) and jump (choice 4) leave it for good.  By hand: the flow
    # y(bail) + y(jump) = 1 (start weight 1, nothing flows back), the objective
    # 0.2 y(bail) + 0.9 y(jump); the optimum sends all the flow through jump.
    lp = occupancy_lp(RING, RING.target)
    assert sp.issparse(lp.a_eq)
    np.testing.assert_array_equal(lp.a_eq.toarray(), [[1.0, 1.0]])
    np.testing.assert_array_equal(lp.b_eq, [1.0])
    np.testing.assert_array_equal(lp.objective, [0.2, 0.9])
    np.testing.assert_array_equal(lp.quotient.choice_origin, [1, 4])
    r = solve_lp(RING, RING.target)
    assert r.occupancy is not None and r.values is not None
    np.testing.assert_allclose(r.occupancy, [0, 0, 0, 0, 1, 0, 0], atol=1e-8)
    np.testing.assert_allclose(r.values, reference_values(RING, RING.target), atol=1e-8)
    arrays = {name: getattr(r, name) for name in ("values", "occupancy", "policy",
                                                   "randomized")}
    for name, array in arrays.items():
        assert isinstance(array, np.ndarray) and not array.flags.writeable, name
        with pytest.raises(ValueError):
            array[0] = 0
    np.testing.assert_allclose(r.values, reference_values(RING, RING.target), atol=1e-8)


# ------------------------------------------------------------------------------------
# Block by block (the default) against the one monolithic LP and the value LP.
# ------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(8))
def test_topological_lp_matches_monolithic_and_value_lp(seed: int) -> None:
    # Local successors: long chains of small components, many end components.
    mdp = random_mdp(120, seed=100 + seed, locality=3 + seed % 4, self_loop_fraction=0.25,
                     sink_fraction=0.08, max_choices=3)
    target = mdp.target
    ref = reference_values(mdp, target)
    maybe = ~target & ~prob0_max(mdp, target)
    mdp = replace(mdp, initial=int(np.argmin(np.where(maybe, np.abs(ref - 0.5), np.inf))))
    blocks = solve_lp(mdp, target, backend="direct")
    whole = solve_lp(mdp, target, backend="direct", layout=Layout.WHOLE)
    assert blocks.status == whole.status == Status.OPTIMAL, blocks.message
    assert blocks.values is not None and blocks.policy is not None
    # Every block is solved with b = 1: the values are exact everywhere, not only
    # where the initial state's flow goes.
    np.testing.assert_allclose(blocks.values, ref, atol=1e-7)
    assert blocks.value == pytest.approx(whole.value, abs=1e-7)
    check_certificates(mdp, target, blocks, 1e-6)
    np.testing.assert_allclose(evaluate_policy(mdp, target, blocks.policy), ref, atol=1e-7)
    # The occupancy is a feasible flow of the monolithic LP from the initial state.
    lp = occupancy_lp(mdp, target)
    y = blocks.occupancy[lp.quotient.choice_origin]
    np.testing.assert_allclose(lp.a_eq @ y, lp.b_eq, atol=1e-9)
    assert blocks.primal_objective == pytest.approx(ref[mdp.initial], abs=1e-7)


@pytest.mark.parametrize("faer", [True, False])
def test_block_lps_factorised_with_or_without_faer(monkeypatch: pytest.MonkeyPatch,
                                                   faer: bool) -> None:
    """The block LPs ask Clarabel for faer's factorisation only where the installed
    build has it; without it (QDLDL) the values are the same, the reference's."""
    from mitld_lp.solvers import lp_backends

    asked: list[dict[str, object]] = []
    real = lp_backends._solve_clarabel

    def spy(lp: object, options: dict[str, object]) -> object:
        asked.append(dict(options))
        return real(lp, options)  # type: ignore[arg-type]

    monkeypatch.setattr(lp_backends, "clarabel_has_faer", lambda: faer)
    monkeypatch.setattr(lp_backends, "_solve_clarabel", spy)
    mdp = random_mdp(120, seed=7, locality=4, self_loop_fraction=0.25, sink_fraction=0.08,
                     max_choices=3)
    r = solve_lp(mdp, mdp.target, backend="direct")
    assert r.status == Status.OPTIMAL and r.values is not None
    assert asked, "the model has non-trivial blocks, so Clarabel must have been called"
    assert all((o.get("direct_solve_method") == "faer") == faer for o in asked)
    np.testing.assert_allclose(r.values, reference_values(mdp, mdp.target), atol=1e-7)


def test_topological_lp_of_hand_mdp_needs_one_block() -> None:
    # MEC{0} <-> MEC{1,4} is the one non-trivial component; 6 is a single state with a
    # self-loop: v(6) = 0.5 / (1 - 0.5) = 1 exactly, no LP.
    r = solve_lp(HAND, HAND.target)
    assert r.status == Status.OPTIMAL and r.message.startswith("clarabel: 1 block LP")
    assert r.values is not None
    assert r.values[6] == 1.0
    np.testing.assert_allclose(r.values, HAND_VALUES, atol=1e-8)


def test_acyclic_model_needs_no_solver() -> None:
    mdp = build_mdp([[("go", {1: 0.5, 2: 0.5}), ("wait", {0: 0.9, 2: 0.1})],
                     [("go", {3: 0.6, 2: 0.4})], [], []], target=[3], sink=[2])
    r = solve_lp(mdp, mdp.target)
    assert r.status == Status.OPTIMAL and r.iterations == 0 and r.solver == ""
    assert r.value == pytest.approx(0.3, abs=1e-15)  # 'go' twice: 0.5 * 0.6


def test_time_limit_is_a_status() -> None:
    mdp = random_mdp(200, seed=4, locality=None)
    for layout in Layout:
        r = solve_lp(mdp, mdp.target, time_limit=0.0, layout=layout)
        assert r.status == Status.TIME_LIMIT and r.values is None


# ------------------------------------------------------------------------------------
# Issue 12: an inaccurate Clarabel solve is retried, then replaced (not reported).
# ------------------------------------------------------------------------------------


def _inaccurate_case() -> Model:
    """Issue 12's 71-state product on which Clarabel returned 'inaccurate'."""
    from mitld_lp import GridWorld
    from mitld_lp.distributions import pmf

    world = GridWorld.make(2, 3, start=(1, 1), slip=0.2, regions={"A": [(0, 1)]})
    spec = "(D[exponential(0.7)] e2) & ((D[mu1] e1) & (F[3,5] (!A)))"
    return Model.from_game(world, spec, distributions={"mu1": pmf([0, 0.75, 0, 0, 0.25])})


def test_inaccurate_clarabel_solve_is_retried() -> None:
    from mitld_lp import synthesize

    model = _inaccurate_case()
    mdp = synthesize(model, method="vi").mdp
    highs = solve_lp(mdp, mdp.target, solver="HIGHS", layout=Layout.WHOLE)
    assert highs.status == Status.OPTIMAL and highs.value == pytest.approx(1.0, abs=1e-9)
    for backend in ("cvxpy", "direct"):
        r = solve_lp(mdp, mdp.target, backend=backend, layout=Layout.WHOLE)  # type: ignore[arg-type]
        assert r.status == Status.OPTIMAL, r.message
        assert "retried" in r.message
        assert r.value == pytest.approx(1.0, abs=1e-8)
    result = synthesize(model)
    assert result.certified and result.lower == pytest.approx(1.0, abs=1e-9)


def test_unfixable_lp_is_replaced_by_the_iteration_policy(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # every solve comes back "optimal_inaccurate" and no retry helps: the route must
    # fall back to the iteration's policy and still certify.  (Issue 12's product,
    # where Clarabel said so by itself, is now decided by the graph: its initial state
    # has value 1 and no LP is left to fail; the bundled grid's value is not 0 or 1.)
    import mitld_lp.solvers.lp_backends as lp_module
    from mitld_lp import load_model, synthesize

    real = lp_module._run_backend

    def inaccurate(*args, **kwargs):
        raw = real(*args, **kwargs)
        return lp_module.Raw(Status.INACCURATE, f"{raw.message} (made inaccurate)",
                             raw.y, raw.v, raw.iterations)

    monkeypatch.setattr(lp_module, "_run_backend", inaccurate)
    monkeypatch.setattr(lp_module, "_retries", lambda settings: iter(()))
    model = load_model(Path(__file__).resolve().parent.parent / "models" / "bus_grid.toml")
    result = synthesize(model, decompose=False)
    assert result.lower_model.lp is not None
    assert result.lower_model.lp.status == Status.INACCURATE
    assert result.certified and result.status == Status.OPTIMAL
    assert result.lower <= 0.9244053 + 1e-7 and 0.9244053 - 1e-7 <= result.upper  # Storm
    names = [c.name for c in result.lower_model.checks]
    assert "LP replaced by the iteration policy" in names


def test_synthesize_time_limit_is_a_status_not_a_hang() -> None:
    from mitld_lp import load_model, synthesize

    model = load_model(Path(__file__).resolve().parent.parent / "models" / "bus_grid.toml")
    result = synthesize(model, time_limit=1e-9)
    assert result.status == Status.TIME_LIMIT and not result.certified
    assert result.lower_model.iteration.status == Status.TIME_LIMIT
    assert result.lower_model.lp is not None
    assert result.lower_model.lp.status == Status.TIME_LIMIT
    # The bracket so far is still a bracket of the true optimum (Storm: 0.9244053).
    assert result.lower_model.bracket[0] <= 0.9244053 <= result.lower_model.bracket[1]
