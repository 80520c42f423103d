"""The sweeps' gate (``solvers/sweep_gate.py``, the iteration's ``use_compiled``): its
choice on hand-built blocks of known size and depth, and the brackets of both routes it
picks between holding a value known in closed form."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.solvers import interval_iteration, iteration, jump_cost, kernels, sweep_gate
from mitld_lp.solvers.topological import Block


def gate_block(succ: list[list[int]], leave: float = 0.01) -> Block:
    """A block of ``len(succ)`` states, one choice each, moving to ``succ[s]`` with equal
    shares of ``1 - leave`` (``leave`` to the target)."""
    n = len(succ)
    row = [s for s in range(n) for _ in succ[s]]
    col = [t for s in range(n) for t in succ[s]]
    val = [(1.0 - leave) / len(succ[s]) for s in range(n) for _ in succ[s]]
    inner = sp.csr_array((val, (row, col)), shape=(n, n))
    return Block(np.arange(n), np.arange(n), inner, sp.csr_array((n, 1)),
                 np.arange(n, dtype=np.int64), np.full(n, leave))


def gate_grid(w: int, h: int) -> list[list[int]]:
    """A ``w x h`` grid's four-neighbour moves (its depth: ``w + h - 2``)."""
    out = []
    for s in range(w * h):
        x, y = divmod(s, h)
        out.append([(x + dx) * h + y + dy for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1))
                    if 0 <= x + dx < w and 0 <= y + dy < h])
    return out


def shallow_gate_block(n: int, degree: int, seed: int) -> list[list[int]]:
    """``n`` states, each moving to ``degree`` others drawn at random: a random graph of
    that degree has a depth of a few times its logarithm."""
    rng = np.random.default_rng(seed)
    return [sorted(set(rng.integers(0, n, size=degree).tolist()) - {s}) or [(s + 1) % n]
            for s in range(n)]


def test_depth_of_hand_built_blocks() -> None:
    line = [[t for t in (s - 1, s + 1) if 0 <= t < 300] for s in range(300)]
    assert jump_cost.block_depth(gate_block(line)) == 299
    assert jump_cost.block_depth(gate_block(gate_grid(128, 64))) == 128 + 64 - 2
    assert jump_cost.block_depth(gate_block(shallow_gate_block(8192, 4, 0))) < 30


def test_same_size_different_depth_different_route() -> None:
    # bus_scaled n64 d3's first grid block has 8,192 states; a grid of them (depth 190)
    # and a random graph of the same states and about the same entries (depth < 30):
    # a size threshold sends both the same way, the gate does not
    deep, shallow = gate_block(gate_grid(128, 64)), gate_block(shallow_gate_block(8192, 4, 1))
    assert abs(deep.inner.nnz - shallow.inner.nnz) < 0.05 * deep.inner.nnz
    assert sweep_gate.prefers_compiled(deep, loaded=False)
    assert not sweep_gate.prefers_compiled(shallow, loaded=False)
    assert not sweep_gate.prefers_compiled(shallow, loaded=True)  # never jumped by NumPy
    f = sweep_gate.forecast(deep, loaded=False)
    assert f.depth == 190 and f.compiled < f.numpy


def test_numba_load_decides_a_middle_block(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sweep_gate, "_CHEAP", [False])  # numba's load: a cold cache
    # a 64 x 32 grid (depth 94) stays within what 100 Jacobi sweeps carry; a 64 x 64 one
    # (depth 126, 4,096 states as bus n64 d3's second block) does not, but its NumPy
    # work is below numba's load: compiled only where numba is loaded already
    assert not sweep_gate.prefers_compiled(gate_block(gate_grid(64, 32)), loaded=True)
    middle = gate_block(gate_grid(64, 64))
    f = sweep_gate.forecast(middle, loaded=False)
    assert f.depth == 126
    assert f.compiled - sweep_gate.NUMBA_LOAD < f.numpy < f.compiled
    assert not sweep_gate.prefers_compiled(middle, loaded=False)
    assert sweep_gate.prefers_compiled(middle, loaded=True)


def test_use_compiled_keeps_its_size_floors(monkeypatch: pytest.MonkeyPatch) -> None:
    deep = gate_block(gate_grid(128, 64))
    assert not sweep_gate.use_compiled(kernels.COMPILED_MIN_ENTRIES - 1, deep.inner.nnz, deep)
    assert not sweep_gate.use_compiled(10**7, deep.inner.nnz)  # no block: sizes alone
    # a block of at most JACOBI_SWEEPS states is decided without a search
    monkeypatch.setattr(jump_cost, "block_depth", lambda block: 1 / 0)
    small = gate_block(gate_grid(10, 10))
    assert not sweep_gate.use_compiled(10**7, small.inner.nnz, small)


def _gamblers_mdp(n: int) -> tuple[MDP, np.ndarray]:
    """A walk on ``0..n`` (0 a sink, ``n`` the target); each inner state steps up with
    probability 0.6 or, by a second choice, 0.4.  Pmax from ``i``: the gambler's ruin's
    ``(1 - r^i) / (1 - r^n)``, ``r = 0.4 / 0.6``."""
    rows, cols, vals, groups = [], [], [], [0]
    choice = 0
    for s in range(n + 1):
        if s in (0, n):
            rows.append(choice), cols.append(s), vals.append(1.0)
            choice += 1
        else:
            for up in (0.6, 0.4):
                rows += [choice, choice]
                cols += [s + 1, s - 1]
                vals += [up, 1.0 - up]
                choice += 1
        groups.append(choice)
    matrix = sp.csr_array((vals, (rows, cols)), shape=(choice, n + 1))
    target = np.zeros(n + 1, dtype=bool)
    target[n] = True
    sink = np.zeros(n + 1, dtype=bool)
    sink[0] = True
    actions = np.zeros(choice, dtype=np.int32)
    actions[[0, choice - 1]] = ABSORB
    actions[1:-1] = np.tile([0, 1], n - 1)
    mdp = MDP(matrix=matrix, row_groups=np.asarray(groups, dtype=np.int64),
              choice_actions=actions, action_names=("safe", "bold"), initial=n // 2,
              target=target, sink=sink, truncated=np.zeros(n + 1, dtype=bool),
              states=tuple(range(n + 1)))
    r = 0.4 / 0.6
    i = np.arange(n + 1)
    return mdp, (1.0 - r**i) / (1.0 - r**n)


@pytest.mark.parametrize("load", [0.0, 1e12])
def test_both_routes_hold_the_closed_form(monkeypatch: pytest.MonkeyPatch,
                                          load: float) -> None:
    # a block of 119 states and depth 118 (past what 100 Jacobi sweeps carry): with
    # numba's load counted as nothing the gate sends it to the compiled sweeps, with it
    # counted as 1e12 entries to NumPy's sweeps and the policy jump
    n = 120
    mdp, exact = _gamblers_mdp(n)
    monkeypatch.setattr(kernels, "COMPILED_MIN_ENTRIES", 0)
    monkeypatch.setattr(sweep_gate, "NUMBA_LOAD", load)
    monkeypatch.setattr(sweep_gate, "_CHEAP", [False])  # NUMBA_LOAD counted
    monkeypatch.setattr(kernels, "_KERNEL", None)  # not loaded yet: its load is counted
    called = {"compiled": 0, "numpy": 0}

    def spy(func, key):
        def counted(*args, **kwargs):
            called[key] += 1
            return func(*args, **kwargs)
        return counted

    for name, key in (("compiled_sweeps", "compiled"), ("numpy_sweeps", "numpy")):
        monkeypatch.setattr(iteration, name, spy(getattr(iteration, name), key))
    r = interval_iteration(mdp, mdp.target, gap="max", tol=1e-10, precision=None,
                           progress=False)
    assert (called["compiled"] > 0) == (load == 0.0)
    assert (called["numpy"] > 0) == (load > 0.0)
    inner = slice(1, n)
    assert np.all(r.lower[inner] <= exact[inner] + 1e-13)
    assert np.all(exact[inner] <= r.upper[inner] + 1e-13)
    assert np.max(r.upper - r.lower) < 1e-10


@pytest.mark.parametrize("seed", range(3))
def test_value_order_distances_read_by_levels_as_by_pointer_jumping(seed: int) -> None:
    # the two ways of reading the search's distances, and the radix sort against
    # lexsort, give one order on random blocks (and a chain deeper than the levels read)
    from mitld_lp.solvers import sweep_order

    rng = np.random.default_rng(seed)
    n = 3000
    succ = [sorted(set(rng.integers(max(0, s - 20), min(n, s + 20), size=3).tolist()))
            for s in range(n)]
    block = gate_block(succ, leave=0.0)
    block = Block(block.states, block.choices, block.inner, block.outer, block.starts,
                  np.where(rng.random(n) < 0.002, 0.1, 0.0))
    fast = sweep_order.value_order(block)
    levels, by_distance = sweep_order._levels, sweep_order._by_distance
    try:
        sweep_order._levels = lambda *a: None
        sweep_order._by_distance = lambda f, d, m: f[np.lexsort((-f, d))]
        slow = sweep_order.value_order(block)
    finally:
        sweep_order._levels, sweep_order._by_distance = levels, by_distance
    assert np.array_equal(fast, slow)
    chain = np.arange(sweep_order.LEVEL_STEPS + 10, dtype=np.int64)
    parent = np.concatenate([[chain.size], chain[:-1], [-9999]])
    assert sweep_order._levels(chain, parent, chain.size) is None
    np.testing.assert_array_equal(sweep_order._jumped(chain, parent, chain.size), chain + 1)
