"""The single-choice states of a block LP eliminated before the solver
(:mod:`mitld_lp.solvers.eliminate`): the reduced LP's optimum is the whole LP's (both
solved by SciPy's HiGHS here), its answer lifted back is a feasible, optimal point of
the whole LP with its values, and the default route gives the same answers with it."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog
from test_analysis import _dense_values

import mitld_lp.solvers.eliminate as elim
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.quotient import reduce
from mitld_lp.solvers.topological import Block
from mitld_lp.testing import random_mdp


def _lp(owner: np.ndarray, n: int, moves: sp.spmatrix, b: np.ndarray, r: np.ndarray):
    """``max r'y  s.t.  (E - P') y = b, y >= 0`` by HiGHS: optimum, y, duals."""
    m = owner.size
    a = sp.csr_array((np.ones(m), (owner, np.arange(m))), shape=(n, m)) - sp.csr_array(moves).T
    res = linprog(-r, A_eq=a, b_eq=b, bounds=(0, None), method="highs")
    assert res.status == 0, res.message
    return -res.fun, res.x, -res.eqlin.marginals


def _case(seed: int):
    """A random block (the quotient of a random MDP, whole) and a random pruning that
    leaves most states one column (every state keeps at least one)."""
    mdp = random_mdp(60, seed=seed, target_fraction=0.08, sink_fraction=0.08,
                     self_loop_fraction=0.2, max_choices=3, max_successors=3)
    q = reduce(mdp, mdp.target)
    block = Block.of(q, np.arange(q.n_states))
    rng = np.random.default_rng(seed)
    keep = rng.random(block.choices.size) < 0.25
    groups = block.groups
    keep[groups[:-1] + rng.integers(0, np.diff(groups))] = True  # one per state at least
    return mdp, q, block, keep


@pytest.mark.parametrize("dense_limit", [400, 2])
@pytest.mark.parametrize("seed", range(8))
def test_reduced_lp_has_the_whole_lps_optimum_and_lifts_to_it(
        seed: int, dense_limit: int, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(elim, "DENSE_LIMIT", dense_limit)  # 2: big cycles stay in the LP
    monkeypatch.setattr(elim, "MAX_KEPT_SHARE", 1.0)
    _, _, block, keep = _case(seed)
    n, groups = block.states.size, block.groups
    owner = np.repeat(np.arange(n), np.diff(groups))
    cols = np.flatnonzero(keep)
    r = block.to_target
    want, _, v_want = _lp(owner[cols], n, block.inner[cols], np.ones(n), r[cols])
    red = elim.eliminate(block.inner, r, groups, keep)
    assert red is not None and red.n_m < n
    got, y_m, v_m = _lp(red.owner, red.n_m, red.moves, red.b_eq, red.objective)
    assert got + red.offset == pytest.approx(want, rel=1e-9, abs=1e-12)
    y, v = red.lift(y_m, v_m)
    # the values of an LP with b = 1 everywhere are unique: the optimal value function
    np.testing.assert_allclose(v, v_want, atol=1e-9)
    # the lifted occupancy is a feasible point of the whole LP, on the kept columns, and
    # attains its optimum
    assert np.all(y[~keep] == 0) and np.all(y >= 0)
    flow = np.bincount(owner, weights=y, minlength=n) - block.inner.T @ y
    np.testing.assert_allclose(flow, np.ones(n), atol=1e-8)
    assert float(r @ y) == pytest.approx(want, rel=1e-9)


def test_a_cycle_of_single_choice_states_is_eliminated() -> None:
    """Three one-choice states in a cycle (0 -> 1 -> 2 -> 0, each leaving to the target
    with 0.1 and to state 3 with 0.1) above a state 3 of two choices (the target with
    0.5, or with 0.3 and back to 0 with 0.6).  By hand: v(0..2) = x with
    x = 0.1 + 0.1 v3 + 0.8 x, so x = 0.5 + 0.5 v3; v3 = max(0.5, 0.3 + 0.6 x) =
    max(0.5, 0.6 + 0.3 v3) = 6/7."""
    inner = sp.csr_array(np.array([[0, .8, 0, .1], [0, 0, .8, .1], [.8, 0, 0, .1],
                                   [0, 0, 0, 0], [.6, 0, 0, 0]]))
    reward = np.array([.1, .1, .1, .5, .3])
    groups = np.array([0, 1, 2, 3, 5])
    red = elim.eliminate(inner, reward, groups, np.ones(5, bool))
    assert red is not None and red.n_m == 1 and list(red.s_states) == [0, 1, 2]
    got, y_m, v_m = _lp(red.owner, 1, red.moves, red.b_eq, red.objective)
    _, v = red.lift(y_m, v_m)
    v3 = 6 / 7
    np.testing.assert_allclose(v, [0.5 + 0.5 * v3] * 3 + [v3], rtol=1e-12)
    # the whole LP's objective is the sum of the values (b = 1 everywhere)
    assert got + red.offset == pytest.approx(float(np.sum(v)), rel=1e-12)
    assert y_m[1] > y_m[0]  # the second choice of state 3 is the optimal one


def _forced(monkeypatch: pytest.MonkeyPatch) -> None:
    """Eliminate in every block, however small the product and the block."""
    for name in ("MIN_ENTRIES", "MIN_PRODUCT_ENTRIES", "MIN_BLOCK_ENTRIES"):
        monkeypatch.setattr(elim, name, 0)


@pytest.mark.parametrize("seed", range(4))
def test_default_route_with_elimination_keeps_values_and_policy(
        seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    mdp = random_mdp(80, seed=seed, target_fraction=0.08, sink_fraction=0.08,
                     self_loop_fraction=0.0, max_choices=4, max_successors=3)
    want = _dense_values(mdp, mdp.target)
    it = interval_iteration(mdp, mdp.target, gap="max", progress=False)
    # the LP itself (the bounds' greedy policy, certified, would skip it)
    plain = solve_lp(mdp, mdp.target, everywhere=True, bounds=(it.lower, it.upper),
                     greedy=False)
    _forced(monkeypatch)
    reduced = solve_lp(mdp, mdp.target, everywhere=True, bounds=(it.lower, it.upper),
                       greedy=False)
    assert re.search(r"\d+ single-choice block states eliminated", reduced.message)
    assert reduced.status.value == "optimal"
    assert reduced.values is not None and plain.policy is not None
    np.testing.assert_allclose(reduced.values, want, atol=1e-8)
    # where the optimal choice is unique (the second best is worse by 1e-6), the same
    score = mdp.matrix @ want  # want is 1 on the target: P(c, target) included
    groups = np.asarray(mdp.row_groups)
    unique_best = []
    for s in range(mdp.n_states):
        part = np.sort(score[groups[s]:groups[s + 1]])[::-1]
        if part.size == 1 or part[0] - part[1] > 1e-6:
            unique_best.append(s)
    assert unique_best
    idx = np.array(unique_best)
    visited = (want[idx] > 0) & (want[idx] < 1) & ~mdp.target[idx]
    idx = idx[visited]
    np.testing.assert_array_equal(np.asarray(reduced.policy)[idx],
                                  np.asarray(plain.policy)[idx])


def test_bundled_case_answer_unchanged_within_its_bracket(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from mitld_lp import load_model, synthesize

    model = load_model(Path(__file__).resolve().parent.parent / "models" / "bus_grid.toml")
    before = synthesize(model)
    _forced(monkeypatch)
    import mitld_lp.solvers.lp_blocks as lp

    reduced = []
    monkeypatch.setattr(lp, "eliminate", lambda *a: reduced.append(elim.eliminate(*a))
                        or reduced[-1])
    monkeypatch.setattr(lp, "certified_greedy", lambda *a: None)  # every block solved
    after = synthesize(model)
    assert any(r is not None and r.n_m < r.n_states for r in reduced)
    assert after.certified and before.certified
    assert before.lower <= after.lower <= before.upper
    assert after.lower <= before.lower <= after.upper
    assert after.lower == pytest.approx(0.9244053, abs=1e-6)  # Storm's value (README)


def test_a_block_whose_cycles_would_mostly_stay_goes_to_the_sparse_lu(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Three one-choice states in a cycle, one state of two choices: with cyclic
    components limited to 2 states, all three would stay in the LP (more than
    MAX_KEPT_SHARE of them, or every one): the compiled walk refuses and one sparse LU
    eliminates them all (:mod:`mitld_lp.solvers.sparse_elimination`); with its budget
    at zero, no reduction, the caller solves the whole LP."""
    import mitld_lp.solvers.sparse_elimination as spe

    inner = sp.csr_array(np.array([[0, .8, 0, .1], [0, 0, .8, .1], [.8, 0, 0, .1],
                                   [0, 0, 0, 0], [.6, 0, 0, 0]]))
    args = (inner, np.array([.1, .1, .1, .5, .3]), np.array([0, 1, 2, 3, 5]),
            np.ones(5, bool))
    monkeypatch.setattr(elim, "DENSE_LIMIT", 2)
    for share in (0.2, 1.0):  # more than the share would stay; every state would
        monkeypatch.setattr(elim, "MAX_KEPT_SHARE", share)
        red = elim.eliminate(*args)
        assert isinstance(red, spe.SparseElimination) and list(red.s_states) == [0, 1, 2]
    monkeypatch.setattr(spe, "WORK_PER_ENTRY", 0.0)
    assert elim.eliminate(*args) is None
