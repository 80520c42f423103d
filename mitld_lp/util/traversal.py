"""Strongly connected components and breadth-first search of a sparse graph, in plain
Python for a small graph and by SciPy's ``csgraph`` for a large one.

Importing ``scipy.sparse.csgraph`` plainly imports ``scipy.sparse.linalg`` and ``scipy.linalg``
with it (the package's own import leaves both for later, :func:`csgraph`): about 0.18 s
of CPU (``python -X importtime``), a third of a whole
``mitld-lp solve`` of the bundled 371-state case.  On a graph of at most :data:`SMALL`
nodes and stored entries these routines walk the graph themselves (an iterative Tarjan, a queue),
in less time than that import; a larger graph goes to csgraph, imported then.  Nodes
count as well as entries: a walk visits every node, and the analysis makes graphs of a
whole product's states with only a few of its edges left (the rounds of the end
components).

Both read the stored structure only, as csgraph does: an explicit zero is an edge.  They
return what csgraph returns: the number of components and a label per node (numbered in
another order), the nodes in breadth-first order and each one's predecessor in the
search tree (``-9999`` for the root and the nodes not reached).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.sparse as sp

__all__ = ["SMALL", "breadth_first_order", "csgraph", "strong_components"]

SMALL = 20_000
"""Nodes plus stored entries up to which a graph is walked in plain Python (4-5 ms for
the components of a random graph of 20,000 entries, against 0.1-0.18 s to import
csgraph)."""

_UNREACHED = -9999  # csgraph's predecessor of the root and of a node not reached


def _structure(graph: Any) -> tuple[int, list[int], list[int]]:
    csr = graph if sp.issparse(graph) and graph.format == "csr" else sp.csr_array(graph)
    if csr.shape[0] != csr.shape[1]:
        raise ValueError(f"graph: expected a square matrix, got shape {csr.shape}")
    return int(csr.shape[0]), csr.indptr.tolist(), csr.indices.tolist()


def _small(graph: Any) -> bool:
    return int(graph.shape[0]) + int(graph.nnz) <= SMALL


def csgraph() -> Any:
    """``scipy.sparse.csgraph`` as the package imports it: inside the package's imports
    (:mod:`mitld_lp.own_imports`) its ``scipy.sparse.linalg`` is left for later, and so
    ``scipy.linalg``, until a name of theirs other than those served is read."""
    from scipy.sparse import csgraph

    return csgraph


_csgraph = csgraph


def strong_components(graph: Any) -> tuple[int, np.ndarray]:
    """The strongly connected components of the directed ``graph``: their number and the
    component of each node (``int32``), as ``csgraph.connected_components(...,
    connection="strong")``."""
    if not _small(graph):
        return _csgraph().connected_components(graph, directed=True, connection="strong")
    n, indptr, indices = _structure(graph)
    return _tarjan(n, indptr, indices)


def _tarjan(n: int, indptr: Sequence[int], indices: Sequence[int]) -> tuple[int, np.ndarray]:
    """Tarjan's algorithm with an explicit stack of (node, next edge to look at)."""
    order = [-1] * n  # discovery index
    low = [0] * n
    on_stack = [False] * n
    label = [-1] * n
    stack: list[int] = []
    counter = n_comp = 0
    for root in range(n):
        if order[root] >= 0:
            continue
        order[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack[root] = True
        work = [(root, indptr[root])]
        while work:
            v, pos = work[-1]
            end = indptr[v + 1]
            descended = False
            while pos < end:
                w = indices[pos]
                pos += 1
                if order[w] < 0:
                    work[-1] = (v, pos)
                    order[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack[w] = True
                    work.append((w, indptr[w]))
                    descended = True
                    break
                if on_stack[w] and order[w] < low[v]:
                    low[v] = order[w]
            if descended:
                continue
            work.pop()
            if work:
                u = work[-1][0]
                if low[v] < low[u]:
                    low[u] = low[v]
            if low[v] == order[v]:
                while True:
                    w = stack.pop()
                    on_stack[w] = False
                    label[w] = n_comp
                    if w == v:
                        break
                n_comp += 1
    return n_comp, np.asarray(label, dtype=np.int32)


def breadth_first_order(graph: Any, root: int, *, return_predecessors: bool = False,
                        ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """The nodes reached from ``root`` along the directed ``graph``, in breadth-first
    order, and with ``return_predecessors`` each node's parent in the search tree, as
    ``csgraph.breadth_first_order(..., directed=True)``."""
    if not _small(graph):
        return _csgraph().breadth_first_order(graph, root, directed=True,
                                              return_predecessors=return_predecessors)
    n, indptr, indices = _structure(graph)
    if not 0 <= root < n:
        raise ValueError(f"root: {root} is not a node of a graph of {n}")
    parent = [_UNREACHED] * n
    seen = [False] * n
    seen[root] = True
    found = [root]
    head = 0
    while head < len(found):
        v = found[head]
        head += 1
        for w in indices[indptr[v]:indptr[v + 1]]:
            if not seen[w]:
                seen[w] = True
                parent[w] = v
                found.append(w)
    order = np.asarray(found, dtype=np.int32)
    if not return_predecessors:
        return order
    return order, np.asarray(parent, dtype=np.int32)
