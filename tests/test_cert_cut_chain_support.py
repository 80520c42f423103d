"""A walked chain's components are those of its nonzero pattern, whether the chain is
searched as it is (canonical, no zero stored) or through ``chain != 0`` (a stored zero):
checked against SciPy's strongly connected components of the pattern made apart, and
the walk's solve against SciPy's direct sparse solve of ``(I - Q) x = b``."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import spsolve

from mitld_lp.solvers.chain_levels import WALK_MIN_STATES, ChainLevels


def _chain(seed: int, zeros: bool) -> sp.csr_array:
    """A transient chain of ``WALK_MIN_STATES + 500`` states: each state moves to two
    states below it, some pairs also to each other (cycles); with ``zeros``, stored
    zeros from some states' successors back to them (no move: a cycle only in the
    stored pattern)."""
    rng = np.random.default_rng(seed)
    n = WALK_MIN_STATES + 500
    src = np.repeat(np.arange(2, n), 2)
    dst = (rng.random(src.size) * src).astype(np.int64)  # below each source
    back = rng.choice(np.arange(0, n - 1), size=200, replace=False)
    rows = [src, back, back + 1]
    cols = [dst, back + 1, back]
    vals = [np.full(src.size, 0.3), np.full(2 * back.size, 0.2)]
    if zeros:
        picked = rng.choice(src.size, size=200, replace=False)
        rows.append(dst[picked])
        cols.append(src[picked])
        vals.append(np.zeros(picked.size))
    c = sp.csr_array((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                     shape=(n, n))
    c.sum_duplicates()  # canonical, the stored zeros kept
    return c


def _same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    pairs = np.unique(np.column_stack([a, b]), axis=0)
    return (np.unique(pairs[:, 0]).size == pairs.shape[0]
            and np.unique(pairs[:, 1]).size == pairs.shape[0])


@pytest.mark.parametrize("zeros", [False, True])
@pytest.mark.parametrize("seed", [0])
def test_walked_components_are_the_nonzero_patterns(seed: int, zeros: bool) -> None:
    c = _chain(seed, zeros)
    assert (np.count_nonzero(c.data) < c.nnz) == zeros
    walk = ChainLevels(c)
    pattern = sp.csr_array(c, copy=True)
    pattern.eliminate_zeros()  # the moves alone
    _, truth = connected_components(pattern, directed=True, connection="strong")
    assert walk.blocks is not None
    assert _same_partition(np.asarray(walk.blocks.component), truth)
    assert int(walk.blocks.size.max()) >= 2  # cyclic components walked
    b = np.random.default_rng(seed).random(c.shape[0]) * 0.1
    x = walk.solve(b)
    exact = spsolve(sp.csc_array(sp.eye_array(c.shape[0]) - c), b)
    assert np.allclose(x, exact, rtol=1e-12, atol=1e-15)
