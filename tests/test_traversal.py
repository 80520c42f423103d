"""The plain-Python walks of a small graph (``mitld_lp.util.traversal``) against SciPy's
csgraph on the same graphs, and a small chain's dense LU against SuperLU's."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse import csgraph

from mitld_lp.solvers import topological
from mitld_lp.solvers.topological import transient_solve
from mitld_lp.util import traversal


def _graph(seed: int) -> sp.csr_array:
    """A random directed graph: chains with back edges, self-loops, repeated entries,
    explicit zeros (edges to csgraph too) and isolated nodes."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 300))
    m = int(rng.integers(0, 4 * n))
    src = rng.integers(0, n, m)
    dst = np.where(rng.random(m) < 0.7, np.minimum(src + rng.integers(0, 4, m), n - 1),
                   rng.integers(0, n, m))
    data = np.where(rng.random(m) < 0.1, 0.0, 1.0)
    graph = sp.csr_array((data, (src, dst)), shape=(n, n))
    graph.sum_duplicates()  # keeps the zero sums as stored entries
    return graph


def _partition(labels: np.ndarray) -> set[frozenset[int]]:
    return {frozenset(np.flatnonzero(labels == c).tolist()) for c in np.unique(labels)}


@pytest.mark.parametrize("seed", range(40))
def test_components_are_csgraphs(seed: int) -> None:
    graph = _graph(seed)
    n_ref, ref = csgraph.connected_components(graph, directed=True, connection="strong")
    n_got, got = traversal.strong_components(graph)
    assert n_got == n_ref and got.shape == ref.shape
    assert _partition(got) == _partition(ref)


@pytest.mark.parametrize("seed", range(40))
def test_breadth_first_search_is_csgraphs(seed: int) -> None:
    graph = _graph(seed)
    n = graph.shape[0]
    root = int(np.random.default_rng(seed).integers(0, n))
    ref_order, ref_pred = csgraph.breadth_first_order(graph, root, directed=True,
                                                      return_predecessors=True)
    order, pred = traversal.breadth_first_order(graph, root, return_predecessors=True)
    assert order[0] == root and set(order.tolist()) == set(ref_order.tolist())
    assert len(order) == len(set(order.tolist()))
    # the same depths (breadth first), and each parent an edge from one level up
    depth = {root: 0}
    for v in order[1:].tolist():
        p = int(pred[v])
        assert p in depth and v in graph.indices[graph.indptr[p]:graph.indptr[p + 1]]
        depth[v] = depth[p] + 1
    ref_depth = {root: 0}
    for v in ref_order[1:].tolist():
        ref_depth[v] = ref_depth[int(ref_pred[v])] + 1
    assert depth == ref_depth
    unreached = np.setdiff1d(np.arange(n), order)
    assert np.all(pred[unreached] == -9999) and pred[root] == -9999
    assert np.array_equal(traversal.breadth_first_order(graph, root), order)


def test_a_large_graph_goes_to_csgraph(monkeypatch) -> None:
    monkeypatch.setattr(traversal, "_tarjan", None)  # would fail if called
    graph = _graph(3)
    monkeypatch.setattr(traversal, "SMALL", graph.shape[0] + graph.nnz - 1)
    n_comp, labels = traversal.strong_components(graph)
    assert labels.shape == (graph.shape[0],) and n_comp == len(np.unique(labels))
    # many nodes and few edges (an end-component round of a large product) count too
    sparse_nodes = sp.csr_array(([1.0], ([0], [1])), shape=(50_000, 50_000))
    monkeypatch.setattr(traversal, "SMALL", 20_000)
    n_comp, labels = traversal.strong_components(sparse_nodes)
    assert n_comp == 50_000


def test_a_root_outside_the_graph_is_refused() -> None:
    with pytest.raises(ValueError, match="root: 5 is not a node of a graph of 3"):
        traversal.breadth_first_order(sp.csr_array((3, 3)), 5)


@pytest.mark.parametrize("k", [1, 7, 60, 256])
def test_a_small_chain_solved_dense_as_superlu_solves_it(k: int, monkeypatch) -> None:
    rng = np.random.default_rng(k)
    q = sp.random_array((k, k), density=min(1.0, 4.0 / k), rng=rng, format="csr")
    q = sp.csr_array(q.multiply(0.97 / np.maximum(q.sum(axis=1), 1.0)[:, None]))
    rhs = rng.random((k, 2))
    dense = transient_solve(q, rhs, refine=2)
    assert isinstance(topological.chain_lu(sp.csc_array(sp.eye_array(k) - q)),
                      topological.DenseLU)
    monkeypatch.setattr(topological, "DENSE_LU_STATES", 0)
    sparse = transient_solve(q, rhs, refine=2)
    np.testing.assert_allclose(np.asarray(dense, dtype=np.float64),
                               np.asarray(sparse, dtype=np.float64), rtol=0, atol=1e-15)
    # and the equation itself, x = rhs + Q x, in extended precision
    residual = rhs.astype(np.longdouble) + q.astype(np.longdouble) @ dense - dense
    assert float(np.max(np.abs(residual))) < 1e-17
