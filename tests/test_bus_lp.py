"""A block LP's single-choice states eliminated by one sparse LU
(:mod:`mitld_lp.solvers.sparse_elimination`, the fallback of
:func:`mitld_lp.solvers.eliminate.eliminate` where the compiled walk refuses): the
reduced LP's optimum is the whole LP's (both solved by SciPy's HiGHS), the eliminated
states' occupancy and values come back (flow conservation and the Bellman equations
checked on the whole block), the budget refuses before the solves, and the bundled bus
case solved this way keeps a certified bracket around Storm's exact value on its DRN."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from test_eliminate import _lp

import mitld_lp.solvers.eliminate as elim
import mitld_lp.solvers.sparse_elimination as spe
from mitld_lp.solvers.quotient import reduce
from mitld_lp.solvers.topological import Block
from mitld_lp.testing import random_mdp


def _case(seed: int, n: int = 80):
    """A random block (a random MDP's quotient, whole) with self-loops and cycles, and a
    random pruning leaving most states one column (each state at least one)."""
    mdp = random_mdp(n, seed=seed, target_fraction=0.06, sink_fraction=0.06,
                     self_loop_fraction=0.3, max_choices=3, max_successors=4)
    q = reduce(mdp, mdp.target)
    block = Block.of(q, np.arange(q.n_states))
    rng = np.random.default_rng(seed)
    keep = rng.random(block.choices.size) < 0.3
    keep[block.groups[:-1] + rng.integers(0, np.diff(block.groups))] = True
    return block, keep


@pytest.mark.parametrize("seed", range(10))
def test_sparse_reduced_lp_has_the_whole_lps_optimum_and_lifts_to_it(seed: int) -> None:
    block, keep = _case(seed)
    n, groups = block.states.size, block.groups
    owner = np.repeat(np.arange(n), np.diff(groups))
    cols = np.flatnonzero(keep)
    r = block.to_target
    want, _, v_want = _lp(owner[cols], n, block.inner[cols], np.ones(n), r[cols])
    red = spe.sparse_eliminate(block.inner, r, groups, keep)
    assert red is not None and 0 < red.n_m < n
    assert red.s_states.size + red.n_m == n
    got, y_m, v_m = _lp(red.owner, red.n_m, red.moves, red.b_eq, red.objective)
    assert got * red.scale + red.offset == pytest.approx(want, rel=1e-9, abs=1e-12)
    y, v = red.lift(y_m, v_m)
    # b = 1 on every state: the LP's duals are unique, the optimal values of the block
    np.testing.assert_allclose(v, v_want, atol=1e-9)
    # the eliminated states' Bellman equations hold on their one column
    s_cols = red.s_cols
    np.testing.assert_allclose(r[s_cols] + block.inner[s_cols] @ v, v[red.s_states],
                               atol=1e-10)
    # flow conservation on every state of the block (the eliminated ones' occupancy
    # recovered), nothing on the pruned columns, and the whole LP's optimum attained
    assert np.all(y[~keep] == 0) and np.all(y >= 0)
    flow = np.bincount(owner, weights=y, minlength=n) - block.inner.T @ y
    np.testing.assert_allclose(flow, np.ones(n), atol=1e-8)
    assert float(r @ y) == pytest.approx(want, rel=1e-9)


@pytest.mark.parametrize("seed", range(3))
def test_eliminate_falls_back_to_the_sparse_lu_and_agrees_with_the_compiled_walk(
        seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """The same block reduced by the compiled walk (every component dense) and, with
    the share of states it may keep forced below zero, by the sparse LU: the same LP
    over the same states, the same lifted values."""
    block, keep = _case(seed, 60)
    r, groups = block.to_target, block.groups
    monkeypatch.setattr(elim, "MAX_KEPT_SHARE", 1.0)
    walked = elim.eliminate(block.inner, r, groups, keep)
    monkeypatch.setattr(elim, "MAX_KEPT_SHARE", -1.0)
    lu = elim.eliminate(block.inner, r, groups, keep)
    assert isinstance(walked, elim.Elimination)
    assert isinstance(lu, spe.SparseElimination)
    np.testing.assert_array_equal(walked.m_states, lu.m_states)
    np.testing.assert_array_equal(walked.m_cols, lu.m_cols)
    np.testing.assert_allclose(walked.objective, lu.objective, atol=1e-12)
    np.testing.assert_allclose(walked.b_eq, lu.b_eq * lu.scale, rtol=1e-10)
    np.testing.assert_allclose(walked.moves.toarray(), lu.moves.toarray(), atol=1e-12)
    _, y_m, v_m = _lp(lu.owner, lu.n_m, lu.moves, lu.b_eq, lu.objective)
    np.testing.assert_allclose(walked.lift(y_m * lu.scale, v_m)[1], lu.lift(y_m, v_m)[1],
                               atol=1e-10)


def test_a_cycle_by_the_sparse_lu_has_the_hand_values() -> None:
    """Three one-choice states in a cycle (0 -> 1 -> 2 -> 0 with 0.8, each to the target
    with 0.1 and to state 3 with 0.1) above a state 3 of two choices (the target with
    0.5, or 0.3 and back to 0 with 0.6).  By hand: the cycle's states have
    x = 0.5 + 0.5 v3, and v3 = max(0.5, 0.3 + 0.6 x) = max(0.5, 0.6 + 0.3 v3) = 6/7."""
    inner = sp.csr_array(np.array([[0, .8, 0, .1], [0, 0, .8, .1], [.8, 0, 0, .1],
                                   [0, 0, 0, 0], [.6, 0, 0, 0]]))
    reward = np.array([.1, .1, .1, .5, .3])
    red = spe.sparse_eliminate(inner, reward, np.array([0, 1, 2, 3, 5]), np.ones(5, bool))
    assert red is not None and red.n_m == 1 and list(red.s_states) == [0, 1, 2]
    _, y_m, v_m = _lp(red.owner, 1, red.moves, red.b_eq, red.objective)
    y, v = red.lift(y_m, v_m)
    v3 = 6 / 7
    np.testing.assert_allclose(v, [0.5 + 0.5 * v3] * 3 + [v3], rtol=1e-12)
    # by hand, the flow: state 3 takes its second choice (0.3 + 0.6 x > 0.5) and its
    # unit start weight plus what the cycle sends it, y3 = 1 + 0.1 (x0 + x1 + x2); the
    # cycle's x0 = 1 + 0.8 x2 + 0.6 y3, x1 = 1 + 0.8 x0, x2 = 1 + 0.8 x1
    a = np.array([[1, 0, -.8, -.6], [-.8, 1, 0, 0], [0, -.8, 1, 0], [-.1, -.1, -.1, 1]])
    x = np.linalg.solve(a, np.ones(4))
    np.testing.assert_allclose(y, [x[0], x[1], x[2], 0.0, x[3]], rtol=1e-9, atol=1e-12)


def test_the_budget_refuses_before_the_solves(monkeypatch: pytest.MonkeyPatch) -> None:
    block, keep = _case(0)
    monkeypatch.setattr(spe, "WORK_PER_ENTRY", 1e-3)
    calls = []
    monkeypatch.setattr(spe, "_port_rows", lambda *a: calls.append(a))
    assert spe.sparse_eliminate(block.inner, block.to_target, block.groups, keep) is None
    assert not calls
    monkeypatch.setattr(spe, "WORK_PER_ENTRY", 6_000.0)
    monkeypatch.setattr(spe, "FILL_FACTOR", 1e-3)
    assert spe.sparse_eliminate(block.inner, block.to_target, block.groups, keep) is None
    assert not calls


def test_dense_port_rows_past_the_budget_are_refused_before_the_factor(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The ports' dense rows are known before SuperLU runs: past the budget, nothing is
    factored (a factorisation would fail the test)."""
    import scipy.sparse.linalg as spla

    block, keep = _case(0)

    def no_factor(*args, **kwargs):
        raise AssertionError("factored past the budget")

    monkeypatch.setattr(spla, "splu", no_factor)
    monkeypatch.setattr(spe, "FILL_FACTOR", 0.0)
    assert spe.sparse_eliminate(block.inner, block.to_target, block.groups, keep) is None


def test_bus_case_by_the_sparse_lu_keeps_its_bracket_around_storms_exact_value(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """The bundled bus case with every block an LP (no greedy certificate), every block
    reduced and by the sparse LU: certified, its bracket holding Storm's exact
    maximum on the exported product (rational arithmetic)."""
    stormpy = pytest.importorskip("stormpy")
    from storm_exact import exact_fraction

    import mitld_lp.solvers.lp_blocks as lp
    from mitld_lp import load_model, synthesize
    from mitld_lp.solvers import write_drn

    model = load_model(Path(__file__).resolve().parent.parent / "models" / "bus_grid.toml")
    for name in ("MIN_ENTRIES", "MIN_PRODUCT_ENTRIES", "MIN_BLOCK_ENTRIES"):
        monkeypatch.setattr(elim, name, 0)
    monkeypatch.setattr(elim, "MAX_KEPT_SHARE", -1.0)  # the sparse LU on every block
    reduced = []
    monkeypatch.setattr(lp, "eliminate", lambda *a: reduced.append(elim.eliminate(*a))
                        or reduced[-1])
    monkeypatch.setattr(lp, "certified_greedy", lambda *a: None)
    result = synthesize(model)
    assert any(isinstance(r, spe.SparseElimination) for r in reduced)
    assert result.certified
    path = tmp_path / "bus.drn"
    write_drn(result.mdp, result.mdp.target, path)
    mdp = stormpy.build_model_from_drn[stormpy.Rational](str(path))
    prop = stormpy.parse_properties('Pmax=? [F "target"]')[0]
    env = stormpy.Environment()
    env.solver().force_exact = True
    exact = exact_fraction(stormpy.model_checking(mdp, prop, environment=env).get_value(
        mdp.initial_states[0]))
    assert result.lower <= exact <= result.upper


@pytest.mark.parametrize("seed", range(2))
def test_one_right_hand_side_at_a_time_gives_the_same_lp(
        seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """The ports' rows solved a block of right-hand sides at a time or one at a time
    (``BLOCK_FLOATS`` below one state's column): the same reduced LP."""
    block, keep = _case(seed)
    args = (block.inner, block.to_target, block.groups, keep)
    whole = spe.sparse_eliminate(*args)
    monkeypatch.setattr(spe, "BLOCK_FLOATS", 1)
    single = spe.sparse_eliminate(*args)
    assert whole is not None and single is not None
    np.testing.assert_allclose(single.moves.toarray(), whole.moves.toarray(), atol=1e-14)
    np.testing.assert_allclose(single.objective, whole.objective, atol=1e-14)
