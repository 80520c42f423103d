"""The NumPy (Jacobi) sweeps of a block folded column by column where every state has
the same number of choices (mitld_lp.solvers.kernels.numpy_sweeps) against the sweep
written here as the module docs state it (one sparse product, the self-loop divided
out with a guard, a segmented max/min by ``reduceat``, clipped, the bounds only
tightened): the same bits, sweep by sweep; and the bounds bracket the optimum
(every policy's chain solved dense by NumPy)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.kernels import Prepared, numpy_sweeps


def _block(seed: int, n: int, width: int | None, loop_one: bool = False):
    """``n`` states, ``width`` choices each (or one to three), each choice moving to
    up to three states of the block (itself half the time) and keeping 8/64 to 56/64
    of its mass in it (a multinomial of 64ths: exact floats); rewards the mass that
    leaves times 0..1.  ``loop_one``: state 0's first choice a self-loop of 1 (it never
    leaves)."""
    rng = np.random.default_rng(seed)
    rows, cols, vals, reward, groups = [], [], [], [], [0]
    for s in range(n):
        for _ in range(width if width is not None else int(rng.integers(1, 4))):
            m = len(reward)
            succ = rng.choice(n, size=3, replace=False)
            succ[0] = s if rng.random() < 0.5 else succ[0]
            stay = int(rng.integers(8, 57))
            sixty_fourths = rng.multinomial(stay, [0.5, 0.3, 0.2])
            used = sixty_fourths > 0
            rows += [m] * int(used.sum())
            cols += succ[used].tolist()
            vals += (sixty_fourths[used] / 64.0).tolist()
            reward.append((64 - stay) / 64.0 * int(rng.integers(0, 5)) / 4.0)
        groups.append(len(reward))
    if loop_one:
        first = [i for i, r in enumerate(rows) if r != 0]
        rows, cols, vals = ([rows[i] for i in first] + [0], [cols[i] for i in first] + [0],
                            [vals[i] for i in first] + [1.0])
        reward[0] = 0.0
    inner = sp.csr_array((vals, (rows, cols)), shape=(len(reward), n))
    inner.sum_duplicates()
    return inner, np.asarray(groups, dtype=np.int64), np.asarray(reward)


def _sweep_by_hand(inner, groups, exits, local, sense):
    owner = np.repeat(np.arange(groups.size - 1), np.diff(groups))
    dense = inner.toarray()
    diag = dense[np.arange(inner.shape[0]), owner]
    off = dense.copy()
    off[np.arange(inner.shape[0]), owner] = 0.0
    leave = (1.0 - diag)[:, None]
    num = exits + sp.csr_array(off) @ local
    score = np.divide(num, leave, out=np.zeros_like(num), where=leave > 0)
    op = np.maximum if sense is Sense.MAX else np.minimum
    new = np.clip(op.reduceat(score, groups[:-1], axis=0), 0.0, 1.0)
    out = local.copy()
    out[:, 0::2] = np.maximum(local[:, 0::2], new[:, 0::2])
    out[:, 1::2] = np.minimum(local[:, 1::2], new[:, 1::2])
    return out


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize(("width", "loop_one"), [(1, False), (3, False), (4, False),
                                                 (None, False), (3, True)])
@pytest.mark.parametrize("seed", range(3))
def test_sweeps_same_bits_as_by_hand(seed, width, loop_one, sense):
    inner, groups, reward = _block(seed, 40, width, loop_one)
    prep = Prepared(inner, groups)
    counts = set(np.diff(groups).tolist())
    assert prep.fold == (counts.pop() if len(counts) == 1 else 0, not loop_one)
    assert width is None or prep.fold[0] == width
    exits = np.column_stack([reward, reward, reward, reward])  # two models
    local = np.tile([0.0, 1.0], (40, 2))
    want = local.copy()
    for _ in range(12):
        done, _over = numpy_sweeps(prep, exits, local, 1e-300, 1, sense)
        assert done == 1
        want = _sweep_by_hand(inner, groups, exits, want, sense)
        assert local.tobytes() == want.tobytes()


def _optimum(inner, groups, reward, sense):
    """Brute force over every deterministic policy, each chain solved dense by NumPy
    (LAPACK), the best per state."""
    n = groups.size - 1
    q = inner.toarray()
    values = [np.linalg.solve(np.eye(n) - q[list(pick)], reward[list(pick)])
              for pick in itertools.product(*[range(groups[s], groups[s + 1])
                                              for s in range(n)])]
    return (np.max if sense is Sense.MAX else np.min)(values, axis=0)


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(3))
def test_folded_bounds_bracket_the_optimum(seed, sense):
    inner, groups, reward = _block(seed + 10, 5, 2)
    prep = Prepared(inner, groups)
    assert prep.fold == (2, True)
    local = np.tile([0.0, 1.0], (5, 1))
    numpy_sweeps(prep, reward[:, None].repeat(2, axis=1), local, 1e-300, 300, sense)
    for (lo, hi), opt in zip(local, _optimum(inner, groups, reward, sense), strict=True):
        assert lo <= opt + 1e-12 and opt - 1e-12 <= hi  # the dense solves' rounding
        assert hi - lo < 1e-9
