"""The interval iteration's memory cuts on a compiled block, against routes written here.

- ``level_first.FirstBounds``: the bounds taken before a block's sweeps, held a byte an
  entry where every one is +0.0 or 1.0 bitwise: read back to the same bits as NumPy's
  own row gather, packed exactly when the bits allow it (never -0.0).
- ``sweep_order.for_sweeps``: the block the sweeps read, without target probabilities
  and with int32 choices: every other field that of ``Block.of`` on the states in the
  new order, its choices the same numbers, its exits ``to_target + outer @ bounds``
  recomputed here from the quotient's dense rows.
- The iteration with the early jump forced on every compiled block (which reads the
  packed bounds), both senses: each state's bracket holds its optimum found by brute
  force (every memoryless deterministic policy's chain solved dense by
  ``numpy.linalg.solve``), and its bits equal those of the iteration holding the
  first bounds as a plain float64 copy.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import MDP
from mitld_lp.solvers import iteration, jump_cost, kernels, level_first
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.level_first import FirstBounds
from mitld_lp.solvers.quotient import quotient_for
from mitld_lp.solvers.sweep_order import for_sweeps, value_order
from mitld_lp.solvers.topological import Block
from mitld_lp.testing import random_mdp

needs_numba = pytest.mark.skipif(kernels.compiled_kernel() is None,
                                 reason="numba is not installed")


# ----------------------------------------------------------------------- FirstBounds
@pytest.mark.parametrize("kind", ["start", "with_minus_zero", "general", "ones_only"])
@pytest.mark.parametrize("seed", range(3))
def test_first_bounds_reads_back_the_same_bits(kind: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    n, cols = 200, 4
    bounds = np.zeros((n, cols))
    bounds[:, 1::2] = rng.random((n, cols // 2)) < 0.7  # an upper bound of 0.0 or 1.0
    states = rng.permutation(n)[: n // 2]
    if kind == "with_minus_zero":
        bounds[states[rng.integers(states.size)], 0] = -0.0
    elif kind == "general":
        bounds[states[rng.integers(states.size)], 1] = 0.75
    elif kind == "ones_only":
        bounds[:] = 1.0
    want = np.array([[bounds[s, c] for c in range(cols)] for s in states])
    got = FirstBounds(bounds, states)
    bits_ok = all(v.view(np.uint64) in (0, 0x3FF0000000000000) for v in want.ravel())
    assert got.packed == bits_ok
    assert got.packed == (kind in ("start", "ones_only"))
    assert got.nbytes == want.size * (1 if bits_ok else 8)
    bounds[:] = 0.5  # held apart from the bounds it was taken from
    values = got.values()
    assert values.dtype == np.float64 and values.shape == want.shape
    assert np.array_equal(values.view(np.uint64), want.view(np.uint64))


# ------------------------------------------------------------------------ for_sweeps
@pytest.mark.parametrize("seed", range(4))
def test_for_sweeps_block_is_block_of_in_the_new_order(seed: int) -> None:
    mdp = random_mdp(400, seed=seed, locality=12, sink_fraction=0.05,
                     self_loop_fraction=0.1)
    q = quotient_for(mdp, mdp.target, None, Sense.MAX)
    states = np.arange(q.n_states)
    block = Block.of(q, states)
    order = value_order(block)[::-1]
    rng = np.random.default_rng(seed)
    bounds = np.sort(rng.random((q.n_states, 2)), axis=1)
    # the exits as the iteration makes them (per column), for the block as it was
    exits = np.column_stack([block.to_target + block.outer @ bounds[:, 0],
                             block.to_target + block.outer @ bounds[:, 1]])
    want = Block.of(q, block.states[order])
    got, got_exits = for_sweeps([block], order, exits)
    del block
    assert got.outer is None and got.to_target is None
    assert got.choices.dtype == np.int32
    assert np.array_equal(got.choices, want.choices)
    assert np.array_equal(got.states, want.states)
    assert np.array_equal(got.starts, want.starts)
    assert (got.inner != want.inner).nnz == 0
    # independent exits: the quotient's dense rows, the block's columns dropped
    dense = q.matrix.toarray()
    outside = np.ones(q.n_states, dtype=bool)
    outside[want.states] = False
    for c in range(2):
        ref = q.to_target[want.choices] + dense[want.choices][:, outside] @ bounds[outside, c]
        assert np.allclose(got_exits[:, c], ref, rtol=1e-12, atol=1e-15)


# ------------------------------------------------------------- the iteration, end to end
def _dyadic_mdp(seed: int, n: int) -> tuple[MDP, list[list[dict[int, float]]]]:
    """``n`` states of one or two choices, each moving among them with 62/64 of its
    mass, 1/64 to the goal (``n``) and 1/64 to the goal or the fail state (``n + 1``);
    both absorbing.  Dyadic, so the floats are the probabilities exactly."""
    rng = np.random.default_rng(seed)
    choices: list[list[dict[int, float]]] = []
    for _ in range(n):
        options = []
        for _c in range(int(rng.integers(1, 3))):
            succ = rng.choice(n, size=int(rng.integers(1, 4)), replace=False)
            parts = rng.multinomial(62, [1 / succ.size] * succ.size)
            option = {int(t): k / 64 for t, k in zip(succ, parts, strict=True) if k}
            last = n if rng.random() < 0.5 else n + 1
            option[n] = option.get(n, 0.0) + 1 / 64
            option[last] = option.get(last, 0.0) + 1 / 64
            options.append(option)
        choices.append(options)
    rows: list[int] = []
    cols: list[int] = []
    vals: list[float] = []
    groups = [0]
    r = 0  # each option its own row, in order; the goal and fail state absorbing
    for options in choices + [[{n: 1.0}], [{n + 1: 1.0}]]:
        for option in options:
            for t, p in option.items():
                rows.append(r), cols.append(t), vals.append(p)
            r += 1
        groups.append(r)
    m = n + 2
    target = np.zeros(m, dtype=bool)
    sink = np.zeros(m, dtype=bool)
    target[n], sink[n + 1] = True, True
    mdp = MDP(matrix=sp.csr_array((vals, (rows, cols)), shape=(r, m)),
              row_groups=np.array(groups, dtype=np.int64),
              choice_actions=np.zeros(r, dtype=np.int32), action_names=("a",),
              initial=0, target=target, sink=sink,
              truncated=np.zeros(m, dtype=bool), states=tuple(range(m)))
    return mdp, choices


def _brute_force(choices: list[list[dict[int, float]]], sense: Sense) -> np.ndarray:
    """Every state's optimum: each memoryless deterministic policy's chain solved dense
    (every state reaches the goal or the fail state with 1/32 a step: I - P invertible)."""
    n = len(choices)
    best = None
    for policy in itertools.product(*(range(len(c)) for c in choices)):
        a = np.eye(n)
        b = np.zeros(n)
        for s in range(n):
            for t, p in choices[s][policy[s]].items():
                if t < n:
                    a[s, t] -= p
                elif t == n:
                    b[s] += p
        v = np.linalg.solve(a, b)
        best = v if best is None else (np.maximum(best, v) if sense is Sense.MAX
                                       else np.minimum(best, v))
    return best


class _PlainFirst:
    """The first bounds as a float64 copy (the iteration before packing)."""

    def __init__(self, bounds: np.ndarray, states: np.ndarray) -> None:
        self._held = bounds[states]

    def values(self) -> np.ndarray:
        return self._held


def _force_early(monkeypatch: pytest.MonkeyPatch) -> list[bool]:
    """Every compiled block looked at early and the jump taken; the packing of every
    first bounds the iteration takes recorded."""
    monkeypatch.setattr(iteration, "_EARLY", (16, 16, 0))
    monkeypatch.setattr(iteration, "_COMPILED_SWEEPS_BEFORE_POLICY", 4096)
    monkeypatch.setattr(kernels, "OPTIMISTIC", False)
    monkeypatch.setattr(jump_cost, "worth", lambda c, saved: True)
    packed: list[bool] = []

    class Recorded(level_first.FirstBounds):
        __slots__ = ()

        def values(self) -> np.ndarray:
            packed.append(self.packed)
            return super().values()

    monkeypatch.setattr(iteration, "FirstBounds", Recorded)
    return packed


@needs_numba
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(4))
def test_iteration_with_packed_first_bounds_brackets_the_optimum(
        monkeypatch: pytest.MonkeyPatch, seed: int, sense: Sense) -> None:
    mdp, choices = _dyadic_mdp(seed, 7)
    packed = _force_early(monkeypatch)
    res = iteration.interval_iteration(mdp, mdp.target, sense=sense, compiled=True,
                                       gap="max", precision=None, progress=False)
    assert packed and all(packed)  # the early jump read the packed bounds
    exact = _brute_force(choices, sense)
    lower, upper = np.asarray(res.lower)[:7], np.asarray(res.upper)[:7]
    slack = 4 * np.spacing(np.maximum(np.abs(exact), 1e-300))
    assert np.all(lower <= exact + slack) and np.all(exact <= upper + slack)
    assert float(np.max(upper - lower)) < 1e-9
    monkeypatch.setattr(iteration, "FirstBounds", _PlainFirst)
    plain = iteration.interval_iteration(mdp, mdp.target, sense=sense, compiled=True,
                                         gap="max", precision=None, progress=False)
    assert np.array_equal(np.asarray(res.lower).view(np.uint64),
                          np.asarray(plain.lower).view(np.uint64))
    assert np.array_equal(np.asarray(res.upper).view(np.uint64),
                          np.asarray(plain.upper).view(np.uint64))
