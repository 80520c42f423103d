"""Backward reachability along a list of edges ``source -> succ`` (below
:mod:`~mitld_lp.solvers.graph`, which re-exports both names): one search
(:func:`backward_reachable`), or the edges reversed once for several searches from
different seeds (:class:`Reversed`: the certificates' chain asks twice).  Exact: only
which edges exist is read.  Many edges are walked compiled
(:mod:`~mitld_lp.solvers.compiled_graph`, chosen by :mod:`~mitld_lp.solvers.walks`):
the same sets."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.rows import gather_ranges
from mitld_lp.solvers.walks import compiled_walks
from mitld_lp.util.sparsetools import sparsetools
from mitld_lp.util.traversal import breadth_first_order

__all__ = ["Reversed", "backward_reachable", "reaching_through"]

SEED_BATCH = 1 << 16
"""States whose seeds :meth:`Reversed.reaching` indexes at a time (its memory bound)."""


def backward_reachable(
    n: int, source: np.ndarray, succ: np.ndarray, seeds: np.ndarray
) -> np.ndarray:
    """States with a path (along the edges ``source -> succ``) to a ``seeds`` state.

    One breadth-first search on the reversed graph from a virtual node ``n`` that points
    at every seed; the seeds themselves are included.  Many edges are walked compiled
    (:func:`~mitld_lp.solvers.walks.compiled_walks`): the same set.
    """
    if not np.any(seeds):
        return np.zeros(n, dtype=bool)
    walks = compiled_walks(np.asarray(succ).size)
    if walks is not None:  # the edges in int32 where they fit (one kernel signature)
        index = np.int32 if max(n, np.asarray(succ).size) < 2**31 - 1 else np.int64
        source, succ = np.asarray(source, dtype=index), np.asarray(succ, dtype=index)
        return walks.reaching_edges(n, source, succ, np.array(seeds, dtype=bool))
    return Reversed(n, source, succ).reaching(seeds)


def reaching_through(matrix: sp.csr_array, row_groups: np.ndarray, through: np.ndarray,
                     seeds: np.ndarray) -> np.ndarray:
    """The states with a path to a ``seeds`` state on the support graph of ``matrix``
    (rows: choices grouped per state by ``row_groups``; no zero stored) whose states
    before the seed are all ``through`` states: :func:`backward_reachable` along the
    entries of the ``through`` states' choices alone (the seeds included).  A minimum's
    states of value 1 (``Prob1A``) are the maybe states it leaves out, with the
    prob-0 states as seeds and the maybe states as ``through``: their quotient's own
    backward search, with no quotient made for it."""
    groups = np.asarray(row_groups)
    states = np.flatnonzero(through)
    # a state's choices are consecutive rows, so its entries one range of the matrix's
    start, stop = matrix.indptr[groups[states]], matrix.indptr[groups[states + 1]]
    succ = matrix.indices[gather_ranges(start, stop)]
    source = np.repeat(states, stop - start)  # ascending
    del start, stop
    return backward_reachable(int(groups.shape[0] - 1), source, succ,
                              np.asarray(seeds, dtype=bool))


class Reversed:
    """The edges ``source -> succ`` of a graph of ``n`` states reversed once, for
    several backward searches (:meth:`reaching`) from different seeds: 4 bytes of index
    an edge (8 past 2**31 edges and states); the weights SciPy's search is handed are
    one value repeated (a view of stride 0: the search reads only the structure), and
    the virtual node's row of seeds is written at the end of each search's view of the
    same arrays.  The edges are sorted once by ``succ``, stably, by SciPy's compiled
    CSR-to-CSC transpose (a counting sort: linear, where a stable argsort was
    ``m log m``; 0.037 -> 0.020 s on QVBS csma 4-2's certificate chain, a million
    edges): the rows are the sources where they come sorted, else one row an edge with
    its source as the value; each head's sources come in the edges' order, the
    argsort's (without the routine, that argsort).  Not through a COO matrix and its
    float copy of the weights."""

    def __init__(self, n: int, source: np.ndarray | None, succ: np.ndarray, *,
                 starts: np.ndarray | None = None) -> None:
        """``starts``: in place of ``source`` (None), the edges as a CSR over the
        states, state ``s``'s heads at ``succ[starts[s]:starts[s + 1]]``: the graph of
        ``source = repeat(arange(n), diff(starts))``, reversed alike without that
        array of every edge (QVBS csma 4-2's certificate chain: a million edges)."""
        succ = np.asarray(succ)
        m = succ.size
        index = np.int32 if n + m < np.iinfo(np.int32).max else np.int64
        self.n, self.nnz = n, m
        self.indices = np.empty(m + n, dtype=index)
        self.indptr = np.zeros(n + 2, dtype=index)
        if starts is not None and (sparsetools is None or m == 0):
            source = np.repeat(np.arange(n, dtype=index), np.diff(starts))
        if starts is None:
            source = np.asarray(source)
        if sparsetools is None or m == 0:
            self._argsorted(source, succ)
        elif starts is not None or bool(np.all(source[1:] >= source[:-1])):
            # the sources sorted (a CSR's rows, each row's entries in their order):
            # SciPy's transpose walks the rows in order into their columns' buckets
            if starts is not None:  # (read only: no copy where it has the type)
                rows = np.asarray(starts, dtype=index)
            else:
                rows = np.zeros(n + 1, dtype=index)
                np.cumsum(np.bincount(source, minlength=n), out=rows[1:])
            # the values (unread: a byte an edge) one array of zeros, read and written
            # in place (each write a zero over a zero): not a second one (1 B/t)
            zeros = np.zeros(m, dtype=np.int8)
            sparsetools.csr_tocsc(n, n, rows, succ.astype(index, copy=False), zeros,
                          self.indptr[:n + 1], self.indices[:m], zeros)
            del zeros
        else:  # one row an edge, its source the entry's value: the same sort
            sparsetools.csr_tocsc(m, n, np.arange(m + 1, dtype=index),
                          succ.astype(index, copy=False), source.astype(index, copy=False),
                          self.indptr[:n + 1], np.empty(m, dtype=index), self.indices[:m])
        self.weights = np.broadcast_to(np.float64(1.0), (m + n,))

    def _argsorted(self, source: np.ndarray, succ: np.ndarray) -> None:
        """The reversal by a stable argsort of the heads (without SciPy's routine)."""
        m, n = self.nnz, self.n
        order = np.argsort(succ, kind="stable")
        if source.dtype == self.indices.dtype:  # no copy of the sources in the order
            np.take(source, order, out=self.indices[:m], mode="clip")
        else:
            self.indices[:m] = source[order]
        del order
        np.cumsum(np.bincount(succ, minlength=n), out=self.indptr[1:n + 1])

    def reaching(self, seeds: np.ndarray) -> np.ndarray:
        """The states with a path to a ``seeds`` state (a mask), the seeds included."""
        n = self.n
        seeds = np.asarray(seeds, dtype=bool)
        stop = self.nnz + int(np.count_nonzero(seeds))
        if stop == self.nnz:
            return np.zeros(n, dtype=bool)
        # the seeds' indices written into the row in place, a batch of states at a
        # time: not an int64 index a seed beside it (QVBS csma 4-2's chain: 367,456
        # seeds, at the certificate's traced peak)
        at = self.nnz
        for a in range(0, n, SEED_BATCH):
            found = np.flatnonzero(seeds[a:a + SEED_BATCH])
            found += a
            self.indices[at:at + found.size] = found
            at += found.size
        del found
        self.indptr[n + 1] = stop
        graph = sp.csr_array((self.weights[:stop], self.indices[:stop], self.indptr),
                             shape=(n + 1, n + 1), copy=False)
        order = breadth_first_order(graph, n)
        reached = np.zeros(n + 1, dtype=bool)
        reached[np.asarray(order)] = True
        return reached[:n]
