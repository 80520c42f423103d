"""The sweeps' value order and renumbering in compiled passes
(:mod:`mitld_lp.solvers.order_kernels`, run here as Python: nothing compiled, no cache
written): the same permutation and the same renumbered block as NumPy's route, to the
bit and type for type, on random blocks (ties, empty rows, int32 and int64 indices);
both against the order written here from its definition; and the interval iteration
with them on and off gives the same bracket, which holds the optimum SciPy's LP solver
(HiGHS) finds, max and min."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog

from mitld_lp.solvers import interval_iteration, order_kernels, sweep_order
from mitld_lp.solvers.block_cut import Block
from mitld_lp.solvers.graph import Sense
from mitld_lp.testing import random_mdp


@pytest.fixture
def as_python(monkeypatch):
    """The order's kernels as plain Python (numba never called)."""
    for name in (*order_kernels.KERNELS, "reach_order"):
        monkeypatch.setattr(order_kernels, name, getattr(order_kernels, name).py_func)


def _quotient(seed: int, index: type) -> SimpleNamespace:
    """What ``Block.of`` reads of a quotient: random rows (0-3 choices a state, a few
    entries each, some rows empty, many targets probabilities zero) in ``index``'s width."""
    rng = np.random.default_rng(seed)
    n = 90
    sizes = rng.integers(0, 4, size=n)
    groups = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    m = int(groups[-1])
    dense = np.where(rng.random((m, n)) < 0.03, rng.random((m, n)), 0.0)
    dense[rng.random(m) < 0.15] = 0.0
    matrix = sp.csr_array(dense)
    matrix = sp.csr_array((matrix.data, matrix.indices.astype(index),
                           matrix.indptr.astype(index)), shape=(m, n))
    to_target = np.where(rng.random(m) < 0.05, rng.random(m), 0.0)
    return SimpleNamespace(row_groups=groups, matrix=matrix, n_states=n,
                           to_target=to_target, dense=dense)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def _plain_order(block: Block) -> list[int]:
    """The order from its definition, on the dense pattern: the states by their fewest
    moves inside the block to one with a choice reaching the target, then the others by
    their fewest moves to one with an exit, then the rest; at one distance (and among
    the rest) the larger index first."""
    n = block.states.size
    groups = block.groups
    inner = block.inner.toarray() != 0
    edge = np.zeros((n, n), dtype=bool)  # s -> t: a choice of s moves to t
    target = np.zeros(n, dtype=bool)
    leaving = np.zeros(n, dtype=bool)
    out_counts = np.diff(block.outer.indptr)
    for s in range(n):
        for c in range(groups[s], groups[s + 1]):
            edge[s] |= inner[c]
            target[s] |= block.to_target[c] > 0
            leaving[s] |= out_counts[c] > 0

    def distances(seeds: np.ndarray) -> np.ndarray:
        dist = np.where(seeds, 0, np.inf)
        for _ in range(n):  # relax every move, n times
            dist = np.minimum(dist, np.where(edge, dist[None, :] + 1, np.inf).min(axis=1))
        return dist

    order: list[int] = []
    for seeds in (target, leaving):
        if seeds.any():
            dist = distances(seeds)
            found = [s for s in range(n) if np.isfinite(dist[s]) and s not in order]
            order += sorted(found, key=lambda s: (dist[s], -s))
    return order + [s for s in range(n - 1, -1, -1) if s not in order]


@pytest.mark.parametrize("index", [np.int32, np.int64])
@pytest.mark.parametrize("seed", range(5))
def test_compiled_order_and_renumbering_are_numpys_to_the_bit(monkeypatch, as_python,
                                                              seed: int, index: type):
    q = _quotient(seed, index)
    rng = np.random.default_rng(seed + 7)
    states = rng.permutation(q.n_states)[: int(rng.integers(q.n_states // 2, q.n_states))]
    block = Block.of(q, states)
    exits = rng.random((block.choices.size, 2))
    runs = []
    for on in (False, True):
        monkeypatch.setattr(sweep_order, "order_compiled", lambda n, on=on: on)
        order = sweep_order.value_order(block)
        renumbered, taken = sweep_order.for_sweeps([block], order[::-1], exits)
        runs.append((order, renumbered, taken, exits))
    (o0, b0, t0, e0), (o1, b1, t1, _) = runs
    assert _same(o0, o1)
    assert o1.tolist() == _plain_order(block)
    for f in ("states", "choices", "starts"):
        assert _same(getattr(b0, f), getattr(b1, f)), f
    assert b0.outer is None and b1.outer is None and b1.to_target is None
    assert b0.inner.shape == b1.inner.shape
    for g in ("indptr", "indices", "data"):
        assert _same(getattr(b0.inner, g), getattr(b1.inner, g)), g
    assert _same(t0, t1)
    # the renumbered block read from the dense rows: state i of it is order[::-1][i]
    new = o1[::-1]
    rows = [c for s in new for c in range(block.groups[s], block.groups[s + 1])]
    assert b1.states.tolist() == block.states[new].tolist()
    assert np.array_equal(b1.inner.toarray(), block.inner.toarray()[rows][:, new])
    assert np.array_equal(t1, e0[rows])


def test_ties_empty_rows_and_a_block_without_target_or_exit(as_python):
    # state 0 has no choice; 1 and 2 both move to 3 (a tie at distance 1); 3 reaches
    # the target; 4 moves only to 0 (no target, no exit: the rest)
    groups = np.array([0, 0, 1, 2, 3, 4], dtype=np.int64)
    inner = sp.csr_array((np.ones(4), np.array([3, 3, 3, 0], dtype=np.int32),
                          np.array([0, 1, 2, 3, 4], dtype=np.int32)), shape=(4, 5))
    to_target = np.array([0.0, 0.0, 0.5, 0.0])
    out_ptr = np.zeros(5, dtype=np.int32)
    order = order_kernels.value_order_of(groups, inner, to_target, out_ptr)
    assert order.dtype == np.int64 and order.tolist() == [3, 2, 1, 4, 0]


def _values(mdp, sense: Sense) -> np.ndarray:
    """The optimum by HiGHS on the dense rows: max, the least ``v >= P v``; min, the
    greatest ``v <= P v`` with ``v = 0`` where some policy keeps off the target."""
    n = mdp.n_states
    groups = np.asarray(mdp.row_groups)
    dense = mdp.matrix.toarray()
    target = np.asarray(mdp.target)
    owner = np.repeat(np.arange(n), np.diff(groups))
    if sense is Sense.MAX:
        keep = target.copy()  # the states that reach the target
        while True:
            more = keep.copy()
            more[owner[(dense[:, keep] > 0).any(axis=1)]] = True
            if np.array_equal(more, keep):
                break
            keep = more
    else:
        away = ~target  # the states with a choice staying away from the target
        while True:
            stays = ~(dense[:, ~away] > 0).any(axis=1)
            more = np.zeros(n, dtype=bool)
            more[owner[stays]] = True
            more &= away
            if np.array_equal(more, away):
                break
            away = more
        keep = ~away
    idx = np.flatnonzero(keep & ~target)
    place = np.full(n, -1)
    place[idx] = np.arange(idx.size)
    a_ub, b_ub = [], []
    sign = 1.0 if sense is Sense.MAX else -1.0
    for s in idx:
        for c in range(groups[s], groups[s + 1]):
            row = np.zeros(idx.size)
            row[place[s]] -= 1.0
            row += dense[c, idx]
            a_ub.append(sign * row)
            b_ub.append(-sign * dense[c, target].sum())
    res = linprog(sign * np.ones(idx.size), A_ub=np.array(a_ub), b_ub=np.array(b_ub),
                  bounds=(0, 1), method="highs")
    assert res.status == 0
    v = target.astype(float)
    v[idx] = res.x
    return v


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(3))
def test_iteration_with_it_same_bracket_holding_the_optimum(monkeypatch, as_python,
                                                            sense: Sense, seed: int):
    mdp = random_mdp(300, seed=seed, max_choices=3, max_successors=3,
                     target_fraction=0.03, sink_fraction=0.1, self_loop_fraction=0.05)
    calls = []
    real = order_kernels.renumber_kernel
    monkeypatch.setattr(order_kernels, "renumber_kernel",
                        lambda *a: calls.append(1) or real(*a))
    runs = []
    for on in (False, True):
        monkeypatch.setattr(sweep_order, "order_compiled", lambda n, on=on: on)
        runs.append(interval_iteration(mdp, mdp.target, sense=sense, compiled=True,
                                       gap="max"))
    assert calls  # the second run renumbered compiled
    assert runs[0].lower.tobytes() == runs[1].lower.tobytes()
    assert runs[0].upper.tobytes() == runs[1].upper.tobytes()
    v = _values(mdp, sense)
    # the LP solver's own tolerance (1e-9) on its side of the comparison
    assert np.all(runs[1].lower <= v + 1e-8) and np.all(v <= runs[1].upper + 1e-8)
    assert float(np.max(runs[1].upper - runs[1].lower)) < 1e-6
