"""The blocks' compiled cut (:mod:`mitld_lp.solvers.block_kernels` through
:meth:`mitld_lp.solvers.block_cut.Block.of`): the same block as NumPy's cut, field by
field, bit for bit and type for type, and the block a dense reading of the rows gives
(written here); and the interval iteration with it gives the same bracket to the bit,
which holds the optimum that SciPy's LP solver finds on its own."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog

pytest.importorskip("numba")

from mitld_lp.solvers import block_cut, interval_iteration  # noqa: E402
from mitld_lp.solvers.block_cut import Block  # noqa: E402
from mitld_lp.solvers.block_kernels import split_rows  # noqa: E402
from mitld_lp.solvers.graph import Sense  # noqa: E402
from mitld_lp.testing import random_mdp  # noqa: E402


def _quotient(seed: int, index: type) -> SimpleNamespace:
    """What ``Block.of`` reads of a quotient: random rows (1-4 choices a state, a few
    entries each, some rows empty) in ``index``'s width."""
    rng = np.random.default_rng(seed)
    n = 80
    sizes = rng.integers(1, 5, size=n)
    groups = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    m = int(groups[-1])
    dense = np.where(rng.random((m, n)) < 0.05, rng.random((m, n)), 0.0)
    dense[rng.random(m) < 0.1] = 0.0  # rows with no entry
    matrix = sp.csr_array(dense)
    matrix = sp.csr_array((matrix.data, matrix.indices.astype(index),
                           matrix.indptr.astype(index)), shape=(m, n))
    return SimpleNamespace(row_groups=groups, matrix=matrix, n_states=n,
                           to_target=rng.random(m) * 0.1, dense=dense)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("index", [np.int32, np.int64])
@pytest.mark.parametrize("seed", range(6))
def test_compiled_cut_is_numpy_cut_and_the_dense_rows(monkeypatch, seed: int,
                                                      index: type) -> None:
    q = _quotient(seed, index)
    rng = np.random.default_rng(seed + 50)
    states = rng.permutation(q.n_states)[: int(rng.integers(1, q.n_states))]
    if seed % 2:
        states = np.sort(states)
    monkeypatch.setattr(block_cut, "cut_compiled", lambda n: False)
    plain = Block.of(q, states)
    monkeypatch.setattr(block_cut, "cut_compiled", lambda n: True)
    cut = Block.of(q, states)
    for f in ("states", "choices", "starts", "to_target"):
        assert _same(getattr(cut, f), getattr(plain, f)), f
    for f in ("inner", "outer"):
        a, b = getattr(cut, f), getattr(plain, f)
        assert a.shape == b.shape, f
        for g in ("indptr", "indices", "data"):
            assert _same(getattr(a, g), getattr(b, g)), (f, g)
    # the block read from the dense rows: each state's choices in turn, the columns of
    # the block's states (in their order) inside, every other column outside
    choices = [c for s in states for c in range(q.row_groups[s], q.row_groups[s + 1])]
    assert cut.choices.tolist() == choices
    rows = q.dense[choices]
    assert np.array_equal(cut.inner.toarray(), rows[:, states])
    outside = rows.copy()
    outside[:, states] = 0.0
    assert np.array_equal(cut.outer.toarray(), outside)
    assert cut.starts.tolist() == np.concatenate(
        [[0], np.cumsum(np.diff(q.row_groups)[states])[:-1]]).tolist()


def test_a_state_without_choices_and_columns_outside() -> None:
    groups = np.array([0, 2, 2, 3], dtype=np.int64)  # state 1 has no choice
    m = sp.csr_array(np.array([[0.5, 0.0, 0.5], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    got = split_rows(groups, m, np.array([1, 0]), 3)
    choices, starts, ip, ii, iv, op, oi, ov = got
    assert choices.tolist() == [0, 1] and starts.tolist() == [0, 0]
    # state 0's choices (rows 0 and 1): state 0 is place 1, state 1 place 0, column 2
    # outside: row 0 keeps 0.5 at place 1 inside and 0.5 at column 2 outside, row 1
    # its 1.0 at place 0 inside
    assert ip.tolist() == [0, 1, 2] and ii.tolist() == [1, 0] and iv.tolist() == [0.5, 1.0]
    assert op.tolist() == [0, 1, 1] and oi.tolist() == [2] and ov.tolist() == [0.5]


def _pmax(mdp) -> np.ndarray:
    """Pmax(F target) by SciPy's LP solver: the least ``v`` with ``v >= P v`` on the
    states that can reach the target (the others 0, the targets 1)."""
    n = mdp.n_states
    groups = np.asarray(mdp.row_groups)
    dense = mdp.matrix.toarray()
    target = np.asarray(mdp.target)
    reach = target.copy()
    while True:  # backwards reachability of the target, by the dense rows
        owner = np.repeat(np.arange(n), np.diff(groups))
        more = reach.copy()
        more[owner[(dense[:, reach] > 0).any(axis=1)]] = True
        if np.array_equal(more, reach):
            break
        reach = more
    maybe = reach & ~target
    idx = np.flatnonzero(maybe)
    place = np.full(n, -1)
    place[idx] = np.arange(idx.size)
    a_ub, b_ub = [], []
    for s in idx:
        for c in range(groups[s], groups[s + 1]):
            row = np.zeros(idx.size)
            row[place[s]] -= 1.0
            row += dense[c, idx]
            a_ub.append(row)
            b_ub.append(-dense[c, target].sum())
    res = linprog(np.ones(idx.size), A_ub=np.array(a_ub), b_ub=np.array(b_ub),
                  bounds=(0, 1), method="highs")
    assert res.status == 0
    v = target.astype(float)
    v[idx] = res.x
    return v


@pytest.mark.parametrize("seed", range(3))
def test_iteration_with_the_cut_same_bracket_holding_the_optimum(monkeypatch,
                                                                  seed: int) -> None:
    mdp = random_mdp(300, seed=seed, max_choices=3, max_successors=3,
                     target_fraction=0.03, sink_fraction=0.1, self_loop_fraction=0.05)
    runs = []
    cuts = []
    real = block_cut._of_compiled
    monkeypatch.setattr(block_cut, "_of_compiled", lambda q, s: cuts.append(s) or real(q, s))
    for on in (False, True):
        monkeypatch.setattr(block_cut, "cut_compiled", lambda n, on=on: on)
        r = interval_iteration(mdp, mdp.target, sense=Sense.MAX, compiled=True,
                               gap="max")
        runs.append(r)
    assert cuts  # the second run cut its blocks compiled
    assert runs[0].lower.tobytes() == runs[1].lower.tobytes()
    assert runs[0].upper.tobytes() == runs[1].upper.tobytes()
    v = _pmax(mdp)
    # the LP solver's own tolerance (1e-9) on its side of the comparison
    assert np.all(runs[1].lower <= v + 1e-8) and np.all(v <= runs[1].upper + 1e-8)
    assert float(np.max(runs[1].upper - runs[1].lower)) < 1e-6


def test_warm_up_compiles_the_signature_of_read_only_row_groups(monkeypatch) -> None:
    """``warm``'s part for the cut covers a solve's call: a model's row groups are
    read-only, and read-only is part of numba's type (the first benchmark run after
    ``warm`` compiled that signature mid-solve)."""
    from mitld_lp.solvers import block_kernels
    from mitld_lp.util import kernel_loader

    real = block_kernels.split_rows_kernel
    seen: list = []

    def record(*args):
        seen.append(kernel_loader.type_key(args))
        return real(*args)

    monkeypatch.setattr(block_kernels, "split_rows_kernel", record)
    for index in (np.int32, np.int64):
        groups = np.array([0, 1, 2], dtype=np.int64)
        groups.flags.writeable = False  # as a model holds them
        m = sp.csr_array((np.array([1.0, 1.0]), np.array([1, 0], dtype=index),
                          np.array([0, 1, 2], dtype=index)), shape=(2, 2))
        split_rows(groups, m, np.array([0, 1]), 2)
    solve_keys = set(seen)
    seen.clear()
    block_kernels.warm_up()
    assert len(solve_keys) == 2 and solve_keys <= set(seen)
