"""A transient chain solved level by level over its own components
(:mod:`mitld_lp.solvers.chain_levels`), against SciPy's direct solve of the whole
chain, a hand chain in Fractions, and its two users on random MDPs (the occupancy flow
and the certificates' chain) against dense LAPACK solves."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from mitld_lp.solvers import chain_levels
from mitld_lp.solvers.certify_chain import chain, support_layers
from mitld_lp.solvers.chain_levels import ChainLevels, chain_solve
from mitld_lp.solvers.graph import graph_blocks
from mitld_lp.solvers.lp_blocks import Walked, policy_flow
from mitld_lp.solvers.quotient import reduce
from mitld_lp.solvers.rounding import rounding
from mitld_lp.solvers.topological import Block
from mitld_lp.testing import random_mdp


def _chain(n: int, seed: int) -> sp.csr_array:
    """A sub-stochastic chain of ``n`` states: rings of 1 to 6 states (a ring of one a
    self-loop) and random edges to later states, each row scaled to 0.95."""
    rng = np.random.default_rng(seed)
    sizes = rng.integers(1, 7, n)
    first = np.concatenate([[0], np.cumsum(sizes)])
    first = first[first < n]
    ring = np.repeat(first, np.diff(np.append(first, n)))  # each state's ring start
    size = np.diff(np.append(first, n))[np.searchsorted(first, ring)]
    nxt = ring + (np.arange(n) - ring + 1) % size
    later = sp.triu(sp.random_array((n, n), density=2.0 / n, rng=rng), k=1)
    q = sp.csr_array(later + sp.csr_array((rng.random(n) + 0.1, (np.arange(n), nxt)),
                                          shape=(n, n)))
    return sp.csr_array(sp.diags_array(0.95 / np.asarray(q.sum(axis=1)).ravel()) @ q)


@pytest.mark.parametrize("walk_from", [256, 10**9])  # the level walk, then one LU
def test_levels_of_a_large_chain_match_one_direct_solve(walk_from: int,
                                                        monkeypatch) -> None:
    monkeypatch.setattr(chain_levels, "WALK_MIN_STATES", walk_from)
    n = 1500
    q = _chain(n, 11)
    blk = graph_blocks(sp.csr_array(q != 0, dtype=np.float64), q.diagonal())
    # the chain has what the walk distinguishes: many levels, cycles and single states
    assert blk.n_levels > 10 and np.any(blk.size > 1) and np.any(blk.size == 1)
    rhs = np.random.default_rng(2).random((n, 2))
    a = sp.csc_array(sp.eye_array(n) - q)
    want = spla.spsolve(a, rhs)
    walk = ChainLevels(q)
    assert (walk.blocks is not None) == (walk_from < n)
    np.testing.assert_allclose(walk.solve(rhs), want, rtol=1e-11)
    # a second right-hand side on the kept factorisations, and a vector
    np.testing.assert_allclose(walk.solve(rhs[:, 1]), want[:, 1], rtol=1e-11)
    # the transposed chain (a flow): the same components, the levels reversed
    flow = spla.spsolve(sp.csc_array(sp.eye_array(n) - q.T), rhs[:, 0])
    np.testing.assert_allclose(chain_solve(sp.csr_array(q.T), rhs[:, 0]), flow,
                               rtol=1e-11)


def test_a_hand_chain_in_fractions(monkeypatch) -> None:
    """States 0 <-> 1 a cycle, 1 -> 2 -> 3 a path with self-loops, 3 to nothing; more
    than 256 states padded as single states that only lead to state 0, and the level
    walk taken from 256 states.  Exact values by hand:
    x3 = 1 / (1 - 1/2) = 2; x2 = (1 + x3/4) / (1 - 1/4) = 2;
    x0 = 1 + x1/2, x1 = 1 + x0/3 + x2/3: x1 = (1 + 1/3 + 2/3) / (1 - 1/6) = 12/5,
    x0 = 11/5; a padding state p: x_p = 1 + x0 / 2 = 21/10."""
    monkeypatch.setattr(chain_levels, "WALK_MIN_STATES", 256)
    f = Fraction
    n = 300
    entries = {(0, 1): f(1, 2), (1, 0): f(1, 3), (1, 2): f(1, 3), (2, 2): f(1, 4),
               (2, 3): f(1, 4), (3, 3): f(1, 2)}
    entries.update({(p, 0): f(1, 2) for p in range(4, n)})
    rows, cols = zip(*entries, strict=True)
    q = sp.csr_array(([float(v) for v in entries.values()], (rows, cols)), shape=(n, n))
    x = chain_solve(q, np.ones(n))
    want = [f(11, 5), f(12, 5), f(2), f(2)] + [f(21, 10)] * (n - 4)
    np.testing.assert_allclose(x, [float(v) for v in want], rtol=1e-15)


@pytest.mark.parametrize("seed", range(4))
def test_walked_flow_and_certificate_chain_match_dense_solves(seed: int,
                                                              monkeypatch) -> None:
    """Every chain walked over its components (from 2 states): a randomised policy's
    occupancy (``policy_flow``) against the dense solve of ``x = b + P_w^T x``, and the
    certificates' chain values (``certify_chain.chain``) against the dense solve of the
    policy's chain on the states it leaves transient."""
    monkeypatch.setattr(chain_levels, "WALK_MIN_STATES", 2)
    mdp = random_mdp(240, seed=seed, target_fraction=0.08, sink_fraction=0.08,
                     self_loop_fraction=0.0, max_choices=3, max_successors=3)
    q = reduce(mdp, mdp.target)
    blk = q.order
    assert blk.size.max() > 2  # a non-trivial block: the walk runs inside it
    rng = np.random.default_rng(seed)
    owner = q.choice_state()
    weights = rng.random(q.n_choices)
    weights /= np.bincount(owner, weights=weights)[owner]
    b = rng.random(q.n_states)
    y = policy_flow(q, blk, weights, b)
    mixed = np.zeros((q.n_states, q.n_states))
    np.add.at(mixed, owner, weights[:, None] * q.matrix.toarray())
    x = np.linalg.solve(np.eye(q.n_states) - mixed.T, b)
    np.testing.assert_allclose(y, weights * x[owner], rtol=1e-10, atol=1e-14)

    groups = np.asarray(mdp.row_groups)
    policy = groups[:-1] + (rng.random(mdp.n_states) * np.diff(groups)).astype(np.int64)
    policy[mdp.target] = -1
    ch = chain(mdp, mdp.target, policy, rounding(sp.csr_array(mdp.matrix)),
               support_layers(mdp))
    live = np.flatnonzero(ch.solved)
    assert live.size > 20
    rows = sp.csr_array(mdp.matrix)[policy[live]].toarray()
    want = np.linalg.solve(np.eye(live.size) - rows[:, live],
                           rows[:, np.flatnonzero(ch.sure)].sum(axis=1))
    np.testing.assert_allclose(ch.values[live], np.clip(want, 0.0, 1.0), rtol=1e-10,
                               atol=1e-15)


@pytest.mark.parametrize("walk_from", [256, 10**9])  # the level walk, then one LU
def test_one_walk_solves_the_transposed_chain(walk_from: int, monkeypatch) -> None:
    """``solve_transposed`` (a flow through the chain) on the walk that solved the
    chain's values, its factorisations shared, against SciPy's direct solve of
    ``(I - Q^T) x = rhs``: two columns and a vector, before and after a value solve."""
    monkeypatch.setattr(chain_levels, "WALK_MIN_STATES", walk_from)
    n = 1500
    q = _chain(n, 5)
    rhs = np.random.default_rng(3).random((n, 2))
    want = spla.spsolve(sp.csc_array(sp.eye_array(n) - q.T), rhs)
    walk = ChainLevels(q)
    np.testing.assert_allclose(walk.solve_transposed(rhs), want, rtol=1e-11)
    walk.solve(rhs)  # the factorisations kept by a value solve serve the flow too
    np.testing.assert_allclose(walk.solve_transposed(rhs[:, 1]), want[:, 1], rtol=1e-11)
    # a wrong direction would be the values' solve: it differs here
    assert not np.allclose(walk.solve(rhs[:, 1]), want[:, 1], rtol=1e-6)


@pytest.mark.parametrize("seed", range(3))
def test_flow_on_a_kept_walk_matches_a_dense_solve(seed: int, monkeypatch) -> None:
    """``policy_flow`` given, for every non-trivial level, the walk of a deterministic
    policy's chain there (as the greedy block answer hands it on) against the dense
    solve of ``x = b + P_pi^T x``: the kept walk is that block's flow."""
    monkeypatch.setattr(chain_levels, "WALK_MIN_STATES", 2)
    mdp = random_mdp(240, seed=seed, target_fraction=0.08, sink_fraction=0.08,
                     self_loop_fraction=0.1, max_choices=3, max_successors=3)
    q = reduce(mdp, mdp.target)
    blk = q.order
    assert blk.size.max() > 2
    rng = np.random.default_rng(seed)
    groups = np.asarray(q.row_groups)
    pick = groups[:-1] + (rng.random(q.n_states) * np.diff(groups)).astype(np.int64)
    weights = np.zeros(q.n_choices)
    weights[pick] = 1.0
    walks = {}
    for level in blk.walk():
        if level.rest.size:
            block = sp.csr_array(q.matrix[pick[level.rest]][:, level.rest])
            # as the greedy block answer hands it on (lp_blocks.Walked.of)
            walks[level.index] = Walked.of(Block.of(q, level.rest), ChainLevels(block))
    assert walks
    b = rng.random(q.n_states)
    y = policy_flow(q, blk, weights, b, walks=walks)
    moves = q.matrix[pick].toarray()
    x = np.linalg.solve(np.eye(q.n_states) - moves.T, b)
    owner = q.choice_state()
    np.testing.assert_allclose(y, weights * x[owner], rtol=1e-10, atol=1e-14)


def test_compiled_single_state_runs_match_the_numpy_walk(monkeypatch) -> None:
    """The walk with its single states' runs of levels compiled
    (:mod:`mitld_lp.solvers.level_kernels`) against SciPy's direct solves of the chain
    and of its transpose, and its values against the NumPy walk's to the last bit (the
    same sums in the same order)."""
    pytest.importorskip("numba")
    from mitld_lp.solvers import topological

    monkeypatch.setattr(chain_levels, "WALK_MIN_STATES", 256)
    n = 1500
    q = _chain(n, 7)
    rhs = np.random.default_rng(4).random((n, 2))
    want = spla.spsolve(sp.csc_array(sp.eye_array(n) - q), rhs)
    flow = spla.spsolve(sp.csc_array(sp.eye_array(n) - q.T), rhs)
    compiled = topological.level_kernels(1, 1, compiled=True)
    calls = []

    class Counted:  # the compiled kernels, each call counted
        def __getattr__(self, name):
            calls.append(name)
            return getattr(compiled, name)

    monkeypatch.setattr(chain_levels, "level_kernels", lambda *a: None)
    plain = ChainLevels(q)
    monkeypatch.setattr(chain_levels, "level_kernels", lambda *a: Counted())
    fast = ChainLevels(q)
    for walk in (plain, fast):
        np.testing.assert_allclose(walk.solve(rhs), want, rtol=1e-11)
        np.testing.assert_allclose(walk.solve(rhs[:, 0]), want[:, 0], rtol=1e-11)
        np.testing.assert_allclose(walk.solve_transposed(rhs), flow, rtol=1e-11)
        np.testing.assert_allclose(walk.solve_transposed(rhs[:, 1]), flow[:, 1], rtol=1e-11)
    assert {"chain_solve", "chain_flow"} <= set(calls)
    assert np.array_equal(fast.solve(rhs), plain.solve(rhs))


def test_certificate_chain_walks_four_byte_indices(monkeypatch) -> None:
    """The certificates' chain (``certify_chain.chain``) reaches its level walks with
    4-byte indices where they fit, as the greedy block's chains do: the compiled
    level kernels then load one variant per process, not one per index type (each a
    compilation on a fresh cache).  Its values against the dense solve of the chain."""

    monkeypatch.setattr(chain_levels, "WALK_MIN_STATES", 2)
    seen = []

    class Recorded(ChainLevels):
        def __init__(self, chain):  # the chain as the walk receives it
            seen.append((chain.indices.dtype, chain.indptr.dtype))
            super().__init__(chain)

    monkeypatch.setattr(chain_levels, "ChainLevels", Recorded)  # walk_of makes it
    mdp = random_mdp(240, seed=1, target_fraction=0.08, sink_fraction=0.08,
                     self_loop_fraction=0.0, max_choices=3, max_successors=3)
    m = sp.csr_array(mdp.matrix)
    rng = np.random.default_rng(1)
    groups = np.asarray(mdp.row_groups)
    policy = groups[:-1] + (rng.random(mdp.n_states) * np.diff(groups)).astype(np.int64)
    policy[mdp.target] = -1
    ch = chain(mdp, mdp.target, policy, rounding(m), support_layers(mdp))
    assert seen and all(d == (np.dtype(np.int32),) * 2 for d in seen)
    live = np.flatnonzero(ch.solved)
    rows = m[policy[live]].toarray()
    want = np.linalg.solve(np.eye(live.size) - rows[:, live],
                           rows[:, np.flatnonzero(ch.sure)].sum(axis=1))
    np.testing.assert_allclose(ch.values[live], np.clip(want, 0.0, 1.0), rtol=1e-10,
                               atol=1e-15)
