"""The maximal end components of a sub-MDP (below :mod:`~mitld_lp.solvers.graph`,
which re-exports the public names): de Alfaro's rounds vectorised in NumPy, or run
compiled on a large MDP (:mod:`~mitld_lp.solvers.compiled_graph`, chosen by
:mod:`~mitld_lp.solvers.walks`), the same components numbered alike.  Exact: only which
transitions have positive probability is read."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.mdp import MDP, as_state_mask
from mitld_lp.solvers.result import read_only
from mitld_lp.solvers.rows import gather_ranges
from mitld_lp.solvers.walks import compiled_walks
from mitld_lp.util.arrays import index_dtype
from mitld_lp.util.traversal import strong_components

__all__ = ["EndComponents", "compiled_end_components", "maximal_end_components"]


@dataclass(frozen=True, slots=True, eq=False)
class EndComponents:
    """The maximal end components (MECs) of a sub-MDP.

    Attributes:
        mec_of: ``(n_states,)`` int64, the MEC of each state, ``-1`` if in none.
        internal: ``(n_choices,)`` bool, the choices that belong to a MEC: their state is
            in the MEC and their whole support lies in the same MEC.
        n_mecs: the number of MECs (ids ``0 .. n_mecs - 1``).
    """

    mec_of: np.ndarray
    internal: np.ndarray
    n_mecs: int

    @classmethod
    def none(cls, n_states: int, n_choices: int) -> EndComponents:
        """The record of no end component among ``n_states`` states and ``n_choices``
        choices: ``mec_of`` -1 (in :func:`~mitld_lp.util.arrays.index_dtype` of the
        states' count) and ``internal`` False everywhere, as read-only views of stride 0
        of one value (``np.broadcast_to``): nothing a state or a choice is allocated
        (a minimum's quotient holds this record from the analysis to the LP: its
        ``mec_of`` was 2.2 bytes a transition of QVBS csma 4-2's LP stage peak).  Every
        reader indexes, slices or compares them; none writes them."""
        return cls(np.broadcast_to(index_dtype(n_states)(-1), (int(n_states),)),
                   np.broadcast_to(np.False_, (int(n_choices),)), 0)

    def states_of(self, mec: int) -> np.ndarray:
        """The states of MEC ``mec``."""
        return np.flatnonzero(self.mec_of == mec)

    def choices_of(self, mec: int, mdp: MDP) -> np.ndarray:
        """The internal choices of MEC ``mec`` (those that stay in it with probability 1)."""
        return np.flatnonzero(self.internal & (self.mec_of[mdp.choice_state()] == mec))


def maximal_end_components(mdp: MDP, states_mask: np.ndarray) -> EndComponents:
    """The MECs of the sub-MDP induced by ``states_mask``.

    An end component is a set ``C`` of states with, for each, a non-empty set of choices
    whose support lies in ``C``, such that the graph of those choices is strongly
    connected.  Algorithm (de Alfaro 1997; Baier & Katoen, Alg. 47): keep the choices
    whose support lies in the current state set, drop the states left with no choice,
    split into strongly connected components (SCCs) and drop every choice that can leave
    its SCC; repeat until nothing changes.  What is left, grouped by SCC, are the MECs.
    Each round is vectorised (one :func:`~mitld_lp.util.traversal.strong_components`);
    on a large MDP the rounds run compiled
    (:func:`~mitld_lp.solvers.walks.compiled_walks`): the same end components, numbered
    alike.
    """
    states_mask = as_state_mask(mdp, states_mask, "states_mask")
    n = mdp.n_states
    walks = compiled_walks(mdp.matrix.nnz)
    if walks is not None and walks.fits(n, mdp.matrix.nnz):  # int32 graphs (fits)
        return compiled_end_components(walks, mdp, np.flatnonzero(states_mask))
    cstate = mdp.choice_state()
    choice, source, succ = _edge_ends(mdp)
    alive = states_mask.copy()
    allowed = alive[cstate]
    while True:
        allowed &= alive[cstate]
        allowed[choice[~alive[succ]]] = False
        still = alive & (np.bincount(cstate[allowed], minlength=n) > 0)
        keep = allowed[choice]
        graph = _support(n, source[keep], succ[keep])
        _, scc = strong_components(graph)
        cross = keep & (scc[source] != scc[succ])
        if not cross.any() and np.array_equal(still, alive):
            break
        allowed[choice[cross]] = False
        alive = still
    return _numbered(alive, allowed, scc)


def compiled_end_components(walks: Any, mdp: MDP, cand: np.ndarray) -> EndComponents:
    """:func:`maximal_end_components` of the states ``cand`` (sorted ids) by the
    compiled rounds (``walks``: the module of compiled walks), numbered as the NumPy
    rounds number them: by their least state (the last round's components are closed,
    so every search meets them in that order)."""
    m = sp.csr_array(mdp.matrix)
    row_groups = np.asarray(mdp.row_groups)
    alive, allowed, label = walks.end_components_among(
        m.indptr, m.indices, m.data > 0, row_groups, np.asarray(cand, dtype=np.int64))
    mec_of = np.full(mdp.n_states, -1, dtype=np.int64)
    internal = np.zeros(mdp.n_choices, dtype=bool)
    inside = label[alive]
    n_mecs = 0
    if inside.size:
        ids, first, which = np.unique(inside, return_index=True, return_inverse=True)
        n_mecs = int(ids.size)
        rank = np.empty(ids.size, dtype=np.int64)
        rank[np.argsort(first)] = np.arange(ids.size)
        mec_of[cand[alive]] = rank[which]
        internal[gather_ranges(row_groups[cand], row_groups[cand + 1])] = allowed
    return EndComponents(read_only(mec_of), read_only(internal), n_mecs)


def _numbered(alive: np.ndarray, allowed: np.ndarray, scc: np.ndarray) -> EndComponents:
    """The end components of the states ``alive`` (with their choices ``allowed``),
    numbered in the order of their last round's component labels ``scc``."""
    mec_of = np.full(alive.shape[0], -1, dtype=np.int64)
    if alive.any():
        _, ids = np.unique(scc[alive], return_inverse=True)
        mec_of[alive] = ids
    n_mecs = int(mec_of.max()) + 1 if alive.any() else 0
    return EndComponents(read_only(mec_of), read_only(allowed), n_mecs)


def _edge_ends(mdp: MDP) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The choice, state and successor of each positive entry (those of
    :func:`~mitld_lp.solvers.graph.edges`, without the probabilities), in the
    matrix's index type (4 bytes an entry where it fits, not 8), the choices' rows in
    their order."""
    m = sp.csr_array(mdp.matrix)
    index = m.indices.dtype
    choice = np.repeat(np.arange(m.shape[0], dtype=index), np.diff(m.indptr))
    succ = m.indices
    positive = m.data > 0
    if not positive.all():
        choice, succ = choice[positive], succ[positive]
    source = np.repeat(np.arange(mdp.n_states, dtype=index), np.diff(mdp.row_groups))[choice]
    return choice, source, succ


def _support(n: int, source: np.ndarray, succ: np.ndarray) -> sp.csr_matrix:
    """The graph ``source -> succ`` (``source`` sorted) as the CSR matrix that SciPy's
    ``csr_matrix((ones, (source, succ)))`` builds (each row's columns sorted, repeats
    merged: the searches see the same order), from a byte an edge instead of the COO's
    copies and a float; its weights one value repeated (the searches read only the
    structure)."""
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(source, minlength=n), out=indptr[1:])
    index = np.int32 if max(n, succ.size) < np.iinfo(np.int32).max else np.int64
    graph = sp.csr_matrix((np.ones(succ.size, dtype=bool), succ.astype(index),
                           indptr.astype(index)), shape=(n, n))
    graph.sum_duplicates()  # sorts each row's columns, in place (a repeat: True or True)
    graph.data = np.broadcast_to(np.float64(1.0), (graph.nnz,))
    return graph
