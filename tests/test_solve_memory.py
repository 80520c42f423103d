"""The solve stage's memory-lean helpers answer what the plain constructions do: the
reversed graph built once for several backward searches (:class:`~mitld_lp.solvers.
graph.Reversed`), and the support extremes read a batch of rows at a time
(:func:`~mitld_lp.solvers.rounding.support_extreme`); each against a brute force
written differently here."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers import rounding
from mitld_lp.solvers.graph import Reversed, backward_reachable


def _closure(n: int, source: np.ndarray, succ: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """States with a path to a seed: a fixpoint over the edge list, no graph library."""
    reached = np.asarray(seeds, dtype=bool).copy()
    edges = list(zip(source.tolist(), succ.tolist(), strict=True))
    changed = True
    while changed:
        changed = False
        for s, t in edges:
            if reached[t] and not reached[s]:
                reached[s] = changed = True
    return reached


def test_reversed_answers_each_seed_set_as_a_fresh_search() -> None:
    rng = np.random.default_rng(7)
    n, m = 60, 110
    source = rng.integers(0, n, m).astype(np.int32)
    succ = rng.integers(0, n, m).astype(np.int32)
    graph = Reversed(n, source, succ)
    # many seeds first, then fewer: the earlier search's seed row must not leak
    for k in (25, 3, 0, 1, 40):
        seeds = np.zeros(n, dtype=bool)
        seeds[rng.choice(n, k, replace=False)] = True
        expected = _closure(n, source, succ, seeds)
        assert np.array_equal(graph.reaching(seeds), expected)
        assert np.array_equal(backward_reachable(n, source.astype(np.int64),
                                                 succ.astype(np.int64), seeds), expected)


def test_support_extreme_in_batches_is_the_per_row_extreme(monkeypatch) -> None:
    rng = np.random.default_rng(3)
    dense = rng.random((40, 25)) * (rng.random((40, 25)) < 0.2)
    dense[5] = 0.0  # an empty row: its extreme is the empty max/min (-inf / inf)
    matrix = sp.csr_array(dense)
    x = rng.random(25)
    rows = rng.integers(0, 40, 33)
    monkeypatch.setattr(rounding, "BATCH", 4)  # several batches, the last one short
    for largest in (True, False):
        got = rounding.support_extreme(matrix, rows, x, largest)
        for i, r in enumerate(rows.tolist()):
            support = [x[j] for j in range(25) if dense[r, j] != 0.0]
            want = (max(support) if largest else min(support)) if support else (
                -np.inf if largest else np.inf)
            assert got[i] == want
