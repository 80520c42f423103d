r"""The support-graph routines every solver shares, below all of them.

Edges of an MDP, the attractor, the one strongly connected decomposition with its
levels (:func:`levels`) and the block order the solvers walk (:class:`Blocks`); the
backward searches (:mod:`~mitld_lp.solvers.reach`) and the maximal end components
(:mod:`~mitld_lp.solvers.end_components`) live in modules of their own below this one,
their names importable from here.  All of them look only at which transitions have
positive probability, so they are exact.  A large graph is walked by compiled kernels
(:mod:`~mitld_lp.solvers.compiled_graph`, chosen by :mod:`~mitld_lp.solvers.walks`, an
attractor by :mod:`~mitld_lp.solvers.analysis_gates`) with the same results.  This module
imports no solver module but those, the level search, the rows and
:mod:`~mitld_lp.solvers.result`: :mod:`~mitld_lp.solvers.analysis`,
:mod:`~mitld_lp.solvers.quotient` and :mod:`~mitld_lp.solvers.topological` build on it.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp

from mitld_lp.mdp import MDP
from mitld_lp.solvers.analysis_gates import attractor_walks, component_walks
from mitld_lp.solvers.end_components import (
    EndComponents,
    compiled_end_components,
    maximal_end_components,
)
from mitld_lp.solvers.level_search import PROBE_LEVELS, reaching, searched_levels, thin
from mitld_lp.solvers.reach import Reversed, backward_reachable
from mitld_lp.solvers.result import read_only
from mitld_lp.solvers.rows import gather_ranges, row_entries
from mitld_lp.solvers.walks import compiled_walks
from mitld_lp.util.arrays import index_dtype, unique
from mitld_lp.util.traversal import SMALL, breadth_first_order, strong_components

__all__ = [
    "Sense", "attractor", "attractor_spared", "attractors", "Blocks", "Edges", "Reversed",
    "EndComponents", "Level", "Levels", "backward_reachable", "blocks_from", "toward",
    "components_reaching", "compiled_end_components", "edges", "graph_blocks", "graph_view",
    "levels", "maximal_end_components", "state_components", "state_levels", "segmented_argmax",
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
    """:func:`attractor_spared`'s set of states (the docs there)."""
    return attractor_spared(matrix, row_groups, seeds, hit)[0]


def attractor_spared(matrix: sp.csr_array, row_groups: np.ndarray, seeds: np.ndarray,
                     hit: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
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
    (:func:`~mitld_lp.solvers.analysis_gates.attractor_walks`), a state at a time: the
    same set.

    Returned with the choices **hit** at the end (``(n_choices,)`` bool: those of
    ``hit`` and those with an entry into the set; both walks mark every such choice).
    A state outside the set with a choice keeps at least one not hit (else it would have
    joined), its whole support outside the set: the choices *spared*, by which a policy
    stays out of the set."""
    n_choices = int(matrix.indptr.size - 1)
    walks = attractor_walks(matrix.nnz)
    if walks is not None:
        hit = np.zeros(n_choices, dtype=bool) if hit is None else np.array(hit, dtype=bool)
        inside = walks.backward(matrix.indptr, matrix.indices, np.asarray(row_groups),
                                np.array(seeds, dtype=bool), hit, True)  # hits into hit
        return inside, hit
    return _attract(_choices_reversed(matrix, row_groups), seeds, hit)


def attractors(matrix: sp.csr_array, row_groups: np.ndarray, seed_sets: list[np.ndarray],
               ) -> list[np.ndarray]:
    """:func:`attractor` of each of ``seed_sets``: one reversed pattern for all."""
    back = None if attractor_walks(matrix.nnz) else _choices_reversed(matrix, row_groups)
    return [attractor(matrix, row_groups, s) if back is None else _attract(back, s, None)[0]
            for s in seed_sets]


def _choices_reversed(matrix: sp.csr_array, row_groups: np.ndarray) -> tuple:
    """The NumPy attractor's graph: each choice's state and each column's choices (CSC),
    4 bytes an index where the sizes allow (csma 4-2: 10 MB less than int64)."""
    n, n_choices = row_groups.shape[0] - 1, int(matrix.indptr.size - 1)
    index = np.int32 if max(n, n_choices) < 2**31 - 1 else np.int64
    owner = np.repeat(np.arange(n, dtype=index), np.diff(row_groups).astype(index))
    pattern = sp.csc_array(sp.csr_array(
        (np.ones(matrix.nnz, dtype=bool), matrix.indices, matrix.indptr), shape=matrix.shape))
    return row_groups, index, owner, pattern.indptr, pattern.indices


def _attract(back: tuple, seeds: np.ndarray, hit: np.ndarray | None,
             ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`attractor_spared`'s NumPy walk on :func:`_choices_reversed`'s graph."""
    row_groups, index, owner, col_ptr, col_rows = back
    n, n_choices = row_groups.shape[0] - 1, owner.size
    counts = np.diff(row_groups).astype(index)
    hit = np.zeros(n_choices, dtype=bool) if hit is None else np.array(hit, dtype=bool)
    remaining = counts.copy()
    if hit.any():
        remaining -= np.bincount(owner[hit], minlength=n).astype(index)
    inside = np.array(seeds, dtype=bool)
    inside |= (remaining == 0) & (counts > 0)
    del counts
    stamp = np.empty(max(n, n_choices), dtype=index)  # scratch of _distinct
    frontier = np.flatnonzero(inside)
    while frontier.size:
        rows = col_rows[gather_ranges(col_ptr[frontier], col_ptr[frontier + 1])]
        rows = _distinct(np.asarray(rows[~hit[rows]], dtype=np.int64), stamp)
        hit[rows] = True
        owners = owner[rows]
        if owners.size < SORTED_COUNTS:
            np.subtract.at(remaining, owners, 1)
        else:  # a wide frontier: its owners counted by a sort, not ufunc.at
            owners.sort()
            first = np.flatnonzero(np.concatenate(([True], owners[1:] != owners[:-1])))
            owners = owners[first]
            remaining[owners] -= np.diff(first, append=rows.size)
        joined = owners[(remaining[owners] == 0) & ~inside[owners]]
        frontier = _distinct(joined, stamp)
        inside[frontier] = True
    return inside, hit


SORTED_COUNTS = 2048
"""From this many choices hit in one round of :func:`attractor`'s NumPy walk, their
owners' counts are taken by a sort instead of ``np.subtract.at`` (which cost about 1 ms
a round of 3,000 on QVBS csma 4-2's 600,267 states: its random writes; the same
counts): 0.080 -> 0.059 s for the whole attractor there.  On narrow rounds (QVBS
firewire_dl 3-600: 275 choices a round) the sort's extra calls cost more than they
save."""


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
    The duplicates (often two thirds of the entries) are merged: scipy's strongly
    connected components did not finish on a graph with them (scipy 1.17, 1e4 states)."""
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
    level: np.ndarray  # (n_components,); None from state_components where not walked
    reach: np.ndarray  # (n_components, k) bool: can reach target set j
    later: Callable[[], np.ndarray] | None = None  # state_components: the levels walked


def levels(graph: sp.csr_array, seeds: np.ndarray | None = None) -> Levels:
    """The strongly connected components of ``graph``, their levels (Kahn's algorithm
    run backwards: sinks are level 0, a component's level is one more than its highest
    successor's) and which components can reach a state of each seed set (``seeds``:
    ``(n, k)`` bool): propagated up the same walk on a small graph, else one compiled
    search a set once the levels are known (:func:`~mitld_lp.solvers.level_search.
    reaching`: the same sets, without two NumPy calls a level and a set).  A large
    graph is walked compiled (:func:`~mitld_lp.solvers.walks.compiled_walks`): the
    same components, numbered alike, and levels.  Else a graph SciPy decomposed whose
    levels turn out thin is finished by SciPy's searches
    (:mod:`~mitld_lp.solvers.level_search`), alike."""
    walks = compiled_walks(graph.nnz)
    if walks is not None and graph.has_canonical_format and walks.fits(graph.shape[0],
                                                                        graph.nnz):
        return _compiled_levels(walks, graph.indptr, graph.indices, seeds)
    return leveled(graph.shape[0] + graph.nnz, *_condensed(graph), seeds)


def leveled(size: int, n_comp: int, comp: np.ndarray, out_degree: np.ndarray,
             preds_of: sp.csr_array, seeds: np.ndarray | None) -> Levels:
    """:func:`levels` of a graph of ``size`` nodes plus entries, condensed
    (:func:`_condensed`; ``out_degree`` is used up)."""
    if seeds is None:
        seeds = np.zeros((comp.size, 0), dtype=bool)
    # the counts in the degrees' own type: ufunc.at on mixed types takes numpy's
    # generic loop, 50-80x slower (2 of 3 s of the analysis on a 2e6-state product);
    # cast once here, as the offsets, not at every level (a deadline makes thousands)
    pred_ptr, preds = preds_of.indptr.astype(np.int64), preds_of.indices
    times = preds_of.data.astype(out_degree.dtype)
    k = seeds.shape[1]
    # a small graph's reach walked up its levels (csgraph not imported for it), a large
    # one's searched once a seed set when the levels are known (:func:`reaching`)
    walked = size <= SMALL
    reach = np.zeros((n_comp, k if walked else 0), dtype=bool)
    for j in range(reach.shape[1]):
        reach[comp[seeds[:, j]], j] = True
    level = np.full(n_comp, -1, dtype=np.int64)
    stamp = np.empty(n_comp, dtype=np.int64)  # scratch of _distinct
    frontier = sinks = np.flatnonzero(out_degree == 0)
    depth, done, since, probe = 0, 0, 0, PROBE_LEVELS
    while frontier.size:  # SMALL: csgraph found the components, and can search
        if depth == probe and size > SMALL:
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
        if walked:
            below = np.repeat(frontier, count)
            for j in range(k):  # the frontier's reach is final: its successors are done
                reach[above[reach[below, j]], j] = True
        np.subtract.at(out_degree, above, times[at])
        frontier = _distinct(above[out_degree[above] == 0], stamp)
        depth += 1
    if np.any(level < 0):  # pragma: no cover - the graph of components is acyclic
        raise AssertionError("the component graph has a cycle")
    return Levels(comp, level, reach if walked else reaching(preds_of, comp, seeds))


def _condensed(graph: sp.csr_array) -> tuple[int, np.ndarray, np.ndarray, sp.csr_array]:
    """The strongly connected components of ``graph`` (their count, each node's), each
    component's out-degree to the others (with multiplicity) and its predecessors
    (``preds_of``: row ``d`` lists the components with an edge to ``d``; its data the
    multiplicities)."""
    return condensation(graph, *strong_components(graph))


def condensation(graph: sp.csr_array, n_comp: int, comp: np.ndarray,
                  ) -> tuple[int, np.ndarray, np.ndarray, sp.csr_array]:
    """:func:`_condensed` of ``graph`` whose components ``comp`` are known."""
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
    return n_comp, comp, out_degree, preds_of


def state_components(matrix: sp.csr_array, row_groups: np.ndarray,
                     seeds: np.ndarray) -> Levels:
    """The components of ``graph_view(matrix, row_groups)`` and which reach each seed set
    (``seeds``: ``(n, k)`` bool), with ``level`` None: no level walk where the graph
    is large and walked by SciPy (the walk was half the analysis of QVBS csma 4-2: the
    quotient's own levels are what the solvers read, :func:`~mitld_lp.solvers.analysis.
    analyse`).  Where the levels cost nothing more (the compiled walk finds all three
    in one pass) they are kept: :func:`state_levels`'s answer.  A small graph's are
    walked and set aside (the same path whatever the size, for the analysis and its
    tests).  ``later()`` gives the levels :func:`levels` finds, from the same
    condensation (once: it uses up the out-degrees)."""
    walks = compiled_walks(matrix.nnz)
    if walks is not None:
        return state_levels(matrix, row_groups, seeds)
    graph = graph_view(matrix, row_groups)
    if graph.shape[0] + graph.nnz <= SMALL:  # csgraph not imported for it
        found = levels(graph, seeds)
        return Levels(found.component, None, found.reach,  # type: ignore[arg-type]
                      lambda: found.level)
    size = graph.shape[0] + graph.nnz
    n_comp, comp, out_degree, preds_of = _condensed(graph)
    del graph

    def later() -> np.ndarray:  # the walk levels() makes, on the same condensation
        return leveled(size, n_comp, comp, out_degree, preds_of, None).level

    return Levels(comp, None, reaching(preds_of, comp, seeds),  # type: ignore[arg-type]
                  later)


def components_reaching(matrix: sp.csr_array, row_groups: np.ndarray, seeds: np.ndarray,
                        ) -> tuple[Levels, np.ndarray, Reversed | None]:
    """:func:`state_components`, and which *states* reach each seed set (``(n, k)``
    bool: their components' ``reach``).  Where SciPy walks a large graph, no
    condensation is made for the reach: one breadth-first search a seed set on the
    state graph reversed (:class:`~mitld_lp.solvers.reach.Reversed`: a state reaches
    a seed iff its component does), the condensation only if ``later()`` asks for the
    levels (QVBS csma 4-2: the condensation and its search were 0.02 of the
    analysis's 0.12 s of CPU, the reversal and search 0.006).  ``reach`` is then None
    in the record, and the reversed graph is returned third for further searches (None
    where it was not made).  Where the components are fewer than half the states, the
    condensation is searched as :func:`state_components` does (QVBS zeroconf 1000-4:
    87,952 components of 301,219 states, whose levels are walked anyway)."""
    if component_walks(matrix.nnz, row_groups.shape[0] - 1) is not None:  # no slower
        found = state_components(matrix, row_groups, seeds)
        return found, found.reach[found.component], None
    graph = graph_view(matrix, row_groups)
    size = graph.shape[0] + graph.nnz
    if size <= SMALL:  # csgraph not imported for it
        found = state_components(matrix, row_groups, seeds)
        return found, found.reach[found.component], None
    # SciPy reads the structure only: data a float64 view of stride 0, not its float64
    # copy of every edge (csma 4-2: 8.7 MB at the analysis's peak)
    n_comp, label = strong_components(sp.csr_array(
        (np.broadcast_to(np.float64(1.0), (graph.nnz,)), graph.indices, graph.indptr),
        shape=graph.shape, copy=False))
    n = graph.shape[0]
    if 2 * n_comp < n:  # few components: their condensation is the smaller graph
        n_comp, comp, out_degree, preds_of = condensation(graph, n_comp, label)
        del graph
        found = Levels(comp, None, reaching(preds_of, comp, seeds),  # type: ignore[arg-type]
                       lambda: leveled(size, n_comp, comp, out_degree, preds_of, None).level)
        return found, found.reach[comp], None
    # reversed from the graph's rows (starts): no source an edge (csma 4-2: 9 MB)
    back = Reversed(n, None, graph.indices, starts=graph.indptr)
    del graph  # rebuilt by later() if asked, not kept through the analysis (csma: 7 B/t)
    reach = np.zeros((n, seeds.shape[1]), dtype=bool)
    for j in range(seeds.shape[1]):
        reach[:, j] = back.reaching(seeds[:, j])
    comp = np.asarray(label, dtype=index_dtype(n))  # later()'s condensation reads it
    del label  # SciPy's int32 labels kept as they are: no int64 copy (csma: 2.2 B/t)

    def later() -> np.ndarray:  # the walk levels() makes, on the same components
        _, c, out_degree, preds_of = condensation(graph_view(matrix, row_groups), n_comp,
                                                   comp)
        return leveled(size, n_comp, c, out_degree, preds_of, None).level

    return Levels(comp, None, None, later), reach, back  # type: ignore[arg-type]


def state_levels(matrix: sp.csr_array, row_groups: np.ndarray, seeds: np.ndarray | None = None,
                 walks: Any = None) -> Levels:
    """:func:`levels` of ``graph_view(matrix, row_groups)`` (no stored zero), the state
    graph built by the compiled walk itself where they are used (``walks``: whatever the
    size, :func:`~mitld_lp.solvers.analysis_gates.level_walks`)."""
    walks = compiled_walks(matrix.nnz) if walks is None else walks
    n = row_groups.shape[0] - 1
    if walks is None or not walks.fits(n, matrix.nnz):  # past int32: NumPy's walk
        return levels(graph_view(matrix, row_groups), seeds)
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
    # int32 as the state graph's (fits checked): one compiled signature, not two a process
    ptr, succ = ptr.astype(np.int32, copy=False), succ.astype(np.int32, copy=False)
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


def toward(mdp: MDP, choices: np.ndarray, roots: np.ndarray) -> np.ndarray:
    """Per state of ``mdp``, its first choice among ``choices`` that has its parent as a
    successor in a breadth-first tree of the edges of ``choices`` reversed, from the
    ``roots`` (``-1`` for a root and a state the tree does not reach): followed, each
    step moves one level closer to a root with positive probability."""
    n = mdp.n_states
    local, succ, data = row_entries(sp.csr_array(mdp.matrix), choices)
    positive = data > 0
    e_choice = choices[local[positive]]
    e_succ = np.asarray(succ[positive], dtype=np.int64)
    e_source = mdp.state_of(e_choice)
    del local, succ, data, positive
    rows = np.concatenate([e_succ, np.full(roots.size, n, dtype=np.int64)])
    cols = np.concatenate([e_source, roots])
    graph = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n + 1, n + 1))
    _, pred = breadth_first_order(graph, n, return_predecessors=True)
    closer = e_succ == pred[e_source]
    cand_state, cand_choice = e_source[closer], e_choice[closer]
    ordering = np.lexsort((cand_choice, cand_state))
    cand_state, cand_choice = cand_state[ordering], cand_choice[ordering]
    first = np.unique(cand_state, return_index=True)[1]
    step = np.full(n, -1, dtype=np.int64)
    step[cand_state[first]] = cand_choice[first]
    step[roots] = -1
    return step
