r"""The support-graph routines every solver shares, below all of them.

Edges of an MDP, backward reachability, maximal end components, the one strongly
connected decomposition with its levels (:func:`levels`) and the block order the
solvers walk (:class:`Blocks`).  All of them look only at which transitions have
positive probability, so they are exact.  A large graph is walked by compiled kernels
(:mod:`~mitld_lp.solvers.compiled_graph`, chosen by :mod:`~mitld_lp.solvers.walks`)
with the same results.  This module imports no other solver module but those two and
:mod:`~mitld_lp.solvers.result`: :mod:`~mitld_lp.solvers.analysis`,
:mod:`~mitld_lp.solvers.quotient` and :mod:`~mitld_lp.solvers.topological` all build
on it.
"""

from __future__ import annotations

import enum
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp

from mitld_lp.mdp import MDP, as_state_mask
from mitld_lp.solvers.level_search import PROBE_LEVELS, searched_levels, thin
from mitld_lp.solvers.result import read_only
from mitld_lp.solvers.rows import gather_ranges
from mitld_lp.solvers.walks import compiled_walks
from mitld_lp.util.arrays import unique
from mitld_lp.util.traversal import SMALL, breadth_first_order, strong_components

__all__ = [
    "Sense", "attractor",
    "Blocks",
    "Edges",
    "Reversed",
    "EndComponents",
    "Level",
    "Levels",
    "backward_reachable",
    "blocks_from",
    "compiled_end_components",
    "edges",
    "graph_blocks",
    "graph_view",
    "levels",
    "maximal_end_components",
    "state_levels",
    "segmented_argmax",
]


class Sense(enum.StrEnum):
    """Whether a value is maximised or minimised over the policies: the one word every
    solver of a quotient takes (a ``StrEnum``: ``Sense.MIN == "min"``).  Each member
    knows its reductions, so a solver is written once for both."""

    MAX = "max"
    MIN = "min"

    def best(self, a: np.ndarray, b: np.ndarray | float) -> np.ndarray:
        """The elementwise better of ``a`` and ``b``."""
        return np.maximum(a, b) if self is Sense.MAX else np.minimum(a, b)

    def reduce(self, values: np.ndarray, starts: np.ndarray) -> np.ndarray:
        """The best of each segment of ``values`` (rows) starting at ``starts``."""
        op = np.maximum if self is Sense.MAX else np.minimum
        return op.reduceat(values, starts, axis=0)

    def gain(self, candidate: np.ndarray, current: np.ndarray) -> np.ndarray:
        """How much ``candidate`` improves on ``current`` (positive: better)."""
        return candidate - current if self is Sense.MAX else current - candidate


@dataclass(frozen=True, slots=True)
class Edges:
    """The positive entries of ``mdp.matrix`` as parallel arrays (one per transition)."""

    choice: np.ndarray  # the choice (row) of the transition
    source: np.ndarray  # the state owning that choice
    succ: np.ndarray  # the successor state (column)
    prob: np.ndarray  # the probability, > 0


def edges(mdp: MDP) -> Edges:
    coo = sp.coo_array(mdp.matrix)
    keep = coo.data > 0
    choice = np.asarray(coo.row[keep], dtype=np.int64)
    succ = np.asarray(coo.col[keep], dtype=np.int64)
    return Edges(choice, mdp.choice_state()[choice], succ, np.asarray(coo.data[keep]))


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


class Reversed:
    """The edges ``source -> succ`` of a graph of ``n`` states reversed once, for
    several backward searches (:meth:`reaching`) from different seeds: 4 bytes of index
    an edge (8 past 2**31 edges and states); the weights SciPy's search is handed are
    one value repeated (a view of stride 0: the search reads only the structure), and
    the virtual node's row of seeds is written at the end of each search's view of the
    same arrays.  The rows are sorted once by ``succ`` (a stable argsort, 8 bytes an
    edge while it lives), not through a COO matrix and its float copy of the weights."""

    def __init__(self, n: int, source: np.ndarray, succ: np.ndarray) -> None:
        source, succ = np.asarray(source), np.asarray(succ)
        m = succ.size
        index = np.int32 if n + m < np.iinfo(np.int32).max else np.int64
        self.n, self.nnz = n, m
        self.indices = np.empty(m + n, dtype=index)
        order = np.argsort(succ, kind="stable")
        if source.dtype == index:  # no copy of the sources in the order
            np.take(source, order, out=self.indices[:m], mode="clip")
        else:
            self.indices[:m] = source[order]
        del order
        self.indptr = np.zeros(n + 2, dtype=index)
        np.cumsum(np.bincount(succ, minlength=n), out=self.indptr[1:n + 1])
        self.weights = np.broadcast_to(np.float64(1.0), (m + n,))

    def reaching(self, seeds: np.ndarray) -> np.ndarray:
        """The states with a path to a ``seeds`` state (a mask), the seeds included."""
        n = self.n
        seed_idx = np.flatnonzero(seeds)
        if seed_idx.size == 0:
            return np.zeros(n, dtype=bool)
        stop = self.nnz + seed_idx.size
        self.indices[self.nnz:stop] = seed_idx
        self.indptr[n + 1] = stop
        graph = sp.csr_array((self.weights[:stop], self.indices[:stop], self.indptr),
                             shape=(n + 1, n + 1), copy=False)
        order = breadth_first_order(graph, n)
        reached = np.zeros(n + 1, dtype=bool)
        reached[np.asarray(order)] = True
        return reached[:n]


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
    if walks is not None:
        return compiled_end_components(walks, mdp, np.flatnonzero(states_mask))
    cstate = mdp.choice_state()
    e = _edge_ends(mdp)
    alive = states_mask.copy()
    allowed = alive[cstate]
    while True:
        allowed &= alive[cstate]
        allowed[e.choice[~alive[e.succ]]] = False
        still = alive & (np.bincount(cstate[allowed], minlength=n) > 0)
        keep = allowed[e.choice]
        graph = _support(n, e.source[keep], e.succ[keep])
        _, scc = strong_components(graph)
        cross = keep & (scc[e.source] != scc[e.succ])
        if not cross.any() and np.array_equal(still, alive):
            break
        allowed[e.choice[cross]] = False
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


def _edge_ends(mdp: MDP) -> Edges:
    """:func:`edges` without the probabilities, in the matrix's index type (4 bytes an
    entry where it fits, not 8), the choices' rows in their order."""
    m = sp.csr_array(mdp.matrix)
    index = m.indices.dtype
    choice = np.repeat(np.arange(m.shape[0], dtype=index), np.diff(m.indptr))
    succ = m.indices
    positive = m.data > 0
    if not positive.all():
        choice, succ = choice[positive], succ[positive]
    source = np.repeat(np.arange(mdp.n_states, dtype=index), np.diff(mdp.row_groups))[choice]
    return Edges(choice, source, succ, np.zeros(0))


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


def segmented_argmax(
    values: np.ndarray, row_groups: np.ndarray, *, tie: float = 0.0,
    prefer: np.ndarray | None = None, sense: Sense = Sense.MAX,
) -> np.ndarray:
    """Per group ``row_groups[i]:row_groups[i+1]`` (all non-empty), the index of the max
    (the min with ``sense=Sense.MIN``).

    Entries within ``tie`` of the group's best *relative to it* (``|best - value| <=
    tie * |best|``: a value of 1e-30 is told apart from one of 1.1e-30 whatever
    ``tie`` below 0.1) count as tied; among them the one with the largest ``prefer``
    wins, then the lowest index.  Fully vectorised.
    """
    starts = np.asarray(row_groups[:-1], dtype=np.int64)
    counts = np.diff(row_groups)
    best = np.repeat(sense.reduce(values, starts), counts)
    tied = sense.gain(values, best) >= -tie * np.abs(best)
    if prefer is not None:
        key = np.where(tied, prefer, -np.inf)
        top = np.maximum.reduceat(key, starts)
        tied &= key >= np.repeat(top, counts)
    idx = np.where(tied, np.arange(values.shape[0]), np.iinfo(np.int64).max)
    return np.minimum.reduceat(idx, starts)


def attractor(matrix: sp.csr_array, row_groups: np.ndarray, seeds: np.ndarray,
              hit: np.ndarray | None = None) -> np.ndarray:
    r"""The states from which *every* policy reaches ``seeds`` with positive
    probability, on the support graph of ``matrix`` (rows: choices grouped per state by
    ``row_groups``; columns: states; no zero stored): the least set

    .. math:: X = \mathit{seeds} \cup \{ s \mid \text{every choice } c \text{ of } s
              \text{ is hit: } \mathit{post}(c) \cap X \ne \emptyset
              \text{ or } \mathit{hit}(c) \}

    (``hit``: choices that count as hit from the start, e.g. those that may leave to a
    losing state outside the matrix).  Its complement is where some policy avoids the
    seeds for ever: ``Prob0E`` of a minimum when the seeds are the target.  Solved
    backwards from the seeds a frontier at a time (a choice is hit once, a state joins
    when its last choice is), vectorised per round; the predecessors are the matrix's
    pattern in column order (one counting sort).  A large matrix is walked compiled
    (:func:`~mitld_lp.solvers.walks.compiled_walks`), a state at a time: the same set."""
    n_choices = int(matrix.indptr.size - 1)
    walks = compiled_walks(matrix.nnz)
    if walks is not None:
        hit = np.zeros(n_choices, dtype=bool) if hit is None else np.array(hit, dtype=bool)
        return walks.backward(matrix.indptr, matrix.indices, np.asarray(row_groups),
                              np.array(seeds, dtype=bool), hit, True)
    n = row_groups.shape[0] - 1
    counts = np.diff(row_groups)
    owner = np.repeat(np.arange(n, dtype=np.int64), counts)
    pattern = sp.csc_array(sp.csr_array(
        (np.ones(matrix.nnz, dtype=bool), matrix.indices, matrix.indptr), shape=matrix.shape))
    col_ptr, col_rows = pattern.indptr, pattern.indices
    hit = np.zeros(n_choices, dtype=bool) if hit is None else np.array(hit, dtype=bool)
    remaining = counts - np.bincount(owner[hit], minlength=n)
    inside = np.array(seeds, dtype=bool)
    inside |= (remaining == 0) & (counts > 0)
    stamp = np.empty(max(n, n_choices), dtype=np.int64)  # scratch of _distinct
    frontier = np.flatnonzero(inside)
    while frontier.size:
        rows = col_rows[gather_ranges(col_ptr[frontier], col_ptr[frontier + 1])]
        rows = _distinct(np.asarray(rows[~hit[rows]], dtype=np.int64), stamp)
        hit[rows] = True
        owners = owner[rows]
        np.subtract.at(remaining, owners, 1)
        joined = owners[(remaining[owners] == 0) & ~inside[owners]]
        frontier = _distinct(joined, stamp)
        inside[frontier] = True
    return inside


@dataclass(frozen=True, slots=True, eq=False)
class Blocks:
    """The SCCs of a quotient's state graph, grouped by level (see the module docs).

    Attributes:
        component: ``(n_reduced_states,)`` the SCC of each reduced state.
        level: ``(n_components,)`` the level of each SCC (0: no successor SCC).
        size: ``(n_components,)`` the number of states of each SCC.
        by_level: reduced states sorted by the level of their SCC (stable).
        level_starts: ``(n_levels + 1,)`` the states of level ``k`` are
            ``by_level[level_starts[k]:level_starts[k+1]]``.
        self_loop: ``(n_reduced_choices,)`` ``P_hat(c, owner(c))``, the probability
            that a choice stays where it is.
    """

    component: np.ndarray
    level: np.ndarray
    size: np.ndarray
    by_level: np.ndarray
    level_starts: np.ndarray
    self_loop: np.ndarray

    @property
    def n_levels(self) -> int:
        return int(self.level_starts.shape[0] - 1)

    @property
    def n_components(self) -> int:
        return int(self.size.shape[0])

    def states_at(self, level: int) -> np.ndarray:
        return self.by_level[self.level_starts[level] : self.level_starts[level + 1]]

    def single(self, states: np.ndarray) -> np.ndarray:
        """Which of ``states`` form a component of their own."""
        return self.size[self.component[states]] == 1

    def walk(self, *, skip: np.ndarray | None = None,
             upstream_first: bool = False) -> Iterator[Level]:
        """The one level loop every solver runs: the levels downstream first (values
        need what they lead to), or upstream first (flows need what leads to them), each
        with its states (less the ``skip`` ones) split into single states and the states
        of non-trivial components, which the solvers take as one block."""
        order = range(self.n_levels - 1, -1, -1) if upstream_first else range(self.n_levels)
        for level in order:
            states = self.states_at(level)
            if skip is not None:
                states = states[~skip[states]]
            one = self.single(states)
            yield Level(level, states, states[one], states[~one])


class Level(NamedTuple):
    """One level of a :meth:`Blocks.walk`: its ``states``, of which ``single`` form a
    component of their own and ``rest`` lie in non-trivial components."""

    index: int
    states: np.ndarray
    single: np.ndarray
    rest: np.ndarray


def graph_view(matrix: sp.csr_array, row_groups: np.ndarray) -> sp.csr_array:
    """``(n, n)`` bool: ``s -> s'`` iff a choice of ``s`` has an entry for ``s'`` (a
    state's choices are consecutive rows, so its successors are a slice of the matrix's
    column indices); an entry of probability 0 is an edge too, so it must not be stored.
    The duplicates (several choices to one successor, often two thirds of the entries)
    are merged: scipy's strongly connected components did not finish on a graph with
    them (scipy 1.17, 1e4 states)."""
    n = row_groups.shape[0] - 1
    index = np.int32 if max(n, matrix.nnz) < 2**31 else np.int64
    graph = sp.csr_array((np.ones(matrix.nnz, dtype=bool), matrix.indices.astype(index),
                          np.asarray(matrix.indptr[row_groups], dtype=index)), shape=(n, n))
    graph.sum_duplicates()
    return graph


@dataclass(frozen=True, slots=True, eq=False)
class Levels:
    """Components of the state graph, their levels and which targets they can reach."""

    component: np.ndarray  # (n,) the component of each state
    level: np.ndarray  # (n_components,)
    reach: np.ndarray  # (n_components, k) bool: can reach target set j


def levels(graph: sp.csr_array, seeds: np.ndarray | None = None) -> Levels:
    """The strongly connected components of ``graph``, their levels (Kahn's algorithm
    run backwards: sinks are level 0, a component's level is one more than its highest
    successor's) and, propagated up the same walk, which components can reach a state
    of each seed set (``seeds``: ``(n, k)`` bool).  A large graph is walked compiled
    (:func:`~mitld_lp.solvers.walks.compiled_walks`): the same components, numbered
    alike, and levels.  Else a graph SciPy decomposed whose levels turn out thin is
    finished by SciPy's searches (:mod:`~mitld_lp.solvers.level_search`), alike."""
    walks = compiled_walks(graph.nnz)
    if walks is not None and graph.has_canonical_format:
        return _compiled_levels(walks, graph.indptr, graph.indices, seeds)
    n_comp, comp = strong_components(graph)
    # the per-edge arrays in the graph's own index type (4 bytes an edge when it can)
    index = graph.indices.dtype
    small = np.asarray(comp, dtype=index)
    comp = np.asarray(comp, dtype=np.int64)
    owner = np.repeat(np.arange(graph.shape[0], dtype=index), np.diff(graph.indptr))
    up, down = small[owner], small[graph.indices]
    del owner, small
    cross = up != down
    up, down = up[cross], down[cross]
    del cross
    out_degree = np.bincount(up, minlength=n_comp)
    # predecessors grouped by component, by a counting sort (coo -> csr, which sums
    # the duplicates: its data are the multiplicities the out-degrees counted)
    preds_of = sp.csr_array((np.ones(up.size, dtype=index), (down, up)),
                            shape=(n_comp, n_comp))
    del up, down
    if seeds is None:
        seeds = np.zeros((graph.shape[0], 0), dtype=bool)
    # the counts in the degrees' own type: ufunc.at on mixed types takes numpy's
    # generic loop, 50-80x slower (2 of 3 s of the analysis on a 2e6-state product);
    # cast once here, as the offsets, not at every level (a deadline makes thousands)
    pred_ptr, preds = preds_of.indptr.astype(np.int64), preds_of.indices
    times = preds_of.data.astype(out_degree.dtype)
    k = seeds.shape[1]
    reach = np.zeros((n_comp, k), dtype=bool)
    for j in range(k):
        reach[comp[seeds[:, j]], j] = True
    level = np.full(n_comp, -1, dtype=np.int64)
    stamp = np.empty(n_comp, dtype=np.int64)  # scratch of _distinct
    frontier = sinks = np.flatnonzero(out_degree == 0)
    depth, done, since, probe = 0, 0, 0, PROBE_LEVELS
    while frontier.size:  # SMALL: csgraph found the components, and can search
        if depth == probe and graph.shape[0] + graph.nnz > SMALL:
            found = (thin(done - since, probe, n_comp, preds.size)
                     and searched_levels(preds_of, sinks, comp, seeds))
            if found:  # thin levels: the rest searched whole
                return Levels(comp, *found)
            probe, since = 2 * probe, done
        level[frontier] = depth
        done += frontier.size
        lo = pred_ptr[frontier]
        count = pred_ptr[frontier + 1] - lo
        at = np.repeat(lo - np.cumsum(count) + count, count)  # gather_ranges, inline
        at += np.arange(at.size)
        above = np.asarray(preds[at], dtype=np.int64)
        below = np.repeat(frontier, count)
        for j in range(k):  # the frontier's reach is final: its successors are done
            reach[above[reach[below, j]], j] = True
        np.subtract.at(out_degree, above, times[at])
        frontier = _distinct(above[out_degree[above] == 0], stamp)
        depth += 1
    if np.any(level < 0):  # pragma: no cover - the graph of components is acyclic
        raise AssertionError("the component graph has a cycle")
    return Levels(comp, level, reach)


def state_levels(matrix: sp.csr_array, row_groups: np.ndarray,
                 seeds: np.ndarray | None = None) -> Levels:
    """:func:`levels` of ``graph_view(matrix, row_groups)`` (no stored zero), the state
    graph built by the compiled walk itself where they are used."""
    walks = compiled_walks(matrix.nnz)
    if walks is None:
        return levels(graph_view(matrix, row_groups), seeds)
    n = row_groups.shape[0] - 1
    if seeds is None:
        seeds = np.zeros((n, 0), dtype=bool)
    comp, level, reach = walks.state_levels(matrix.indptr, matrix.indices,
                                            np.asarray(row_groups),
                                            np.ascontiguousarray(seeds, dtype=bool), SMALL)
    return Levels(np.asarray(comp, dtype=np.int64), level, reach)


def _compiled_levels(walks: Any, ptr: np.ndarray, succ: np.ndarray,
                     seeds: np.ndarray | None) -> Levels:
    """:func:`levels` of the graph ``ptr, succ`` (CSR, each row sorted without repeats)
    by the compiled walks: the components labelled as the routine :func:`levels` calls
    labels them (SciPy's search looks at a node's successors from the last, the plain
    walk of a graph of at most :data:`~mitld_lp.util.traversal.SMALL` nodes and entries
    from the first)."""
    n = ptr.shape[0] - 1
    if seeds is None:
        seeds = np.zeros((n, 0), dtype=bool)
    _, comp, level, reach = walks.components_and_levels(
        ptr, succ, n + succ.shape[0] > SMALL, np.ascontiguousarray(seeds, dtype=bool), True)
    return Levels(np.asarray(comp, dtype=np.int64), level, reach)


def _distinct(values: np.ndarray, stamp: np.ndarray) -> np.ndarray:
    """The distinct entries of ``values`` (ids below ``stamp.size``), unsorted: each
    writes its position into ``stamp``, and is kept iff its position stayed."""
    at = np.arange(values.size)
    stamp[values] = at
    return values[stamp[values] == at]


def blocks_from(component: np.ndarray, level_of: np.ndarray, self_loop: np.ndarray,
                ) -> Blocks:
    """The :class:`Blocks` of states whose components (``component``, ids of a larger
    graph's) and levels (``level_of[component]``) are known: ids and levels renumbered
    densely, the order kept.  A layering of a graph is one of every subgraph (an edge
    between components goes down there too), so a decomposition found once serves
    every chain of every policy on it."""
    ids, dense = _renumbered(component)
    used, level = _renumbered(np.asarray(level_of)[ids])
    return _layered(dense, level, ids.size, used.size, self_loop)


def _renumbered(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The sorted distinct ``values`` (non-negative ids) and each value's position
    among them: by a table of the ids present where they are few against the values
    (no sort), else by :func:`~mitld_lp.util.arrays.unique`."""
    values = np.asarray(values, dtype=np.int64)
    top = int(values.max()) + 1 if values.size else 0
    if top <= 4 * values.size + 1024:
        seen = np.zeros(top, dtype=bool)
        seen[values] = True
        return np.flatnonzero(seen), (np.cumsum(seen) - 1)[values]
    ids = unique(values)
    return ids, np.searchsorted(ids, values)


RADIX_LEVELS = 1 << 16
"""Up to this many levels, :class:`Blocks` orders the states by 16-bit level keys."""


def _layered(dense: np.ndarray, level: np.ndarray, n_components: int, n_levels: int,
             self_loop: np.ndarray) -> Blocks:
    """:class:`Blocks` of dense component ids and dense levels (every level from 0 to
    ``n_levels - 1`` has a component).  The states are ordered by level with a stable
    sort of 16-bit keys where the levels fit (numpy sorts those by radix: 6 ms against
    60 ms for 64-bit keys on 600,000 states, the same order)."""
    state_level = level[dense]
    key = state_level.astype(np.uint16) if n_levels <= RADIX_LEVELS else state_level
    by_level = np.argsort(key, kind="stable")
    level_starts = np.zeros(n_levels + 1, dtype=np.int64)
    np.cumsum(np.bincount(state_level, minlength=n_levels), out=level_starts[1:])
    return Blocks(
        component=read_only(dense),
        level=read_only(level),
        size=read_only(np.bincount(dense, minlength=n_components)),
        by_level=read_only(by_level),
        level_starts=read_only(level_starts),
        self_loop=read_only(np.asarray(self_loop, dtype=np.float64)),
    )


def graph_blocks(graph: sp.csr_array, self_loop: np.ndarray) -> Blocks:
    """The SCCs of ``graph`` and their levels (:func:`levels`) as :class:`Blocks`;
    ``self_loop`` is stored as given."""
    found = levels(graph)  # dense ids and levels already: nothing to renumber
    n_levels = int(found.level.max()) + 1 if found.level.size else 0
    return _layered(found.component, found.level, found.level.size, n_levels, self_loop)
