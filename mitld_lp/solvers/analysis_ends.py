"""A maximum's end components for :func:`~mitld_lp.solvers.analysis.analyse` (and the
certificate's, :func:`end_components`), and where there is none the goal's value-1 states
with them (:func:`ends_and_sure`).

The end components of the maybe states lie among the states of non-trivial components
and those with a choice that stays put (:func:`may_cycle`).  On a large product one
attractor pass first shows whether there is any (:func:`_none_among`).  Where the goal's
value-1 states are found on the product's rows anyway (a maximum's ``Prob1E`` where no end
component is collapsed, :func:`~mitld_lp.solvers.analysis_singles.prob1e_on_product`), that
attractor comes first: every end component of the maybe states outside its seeds lies
outside it (the first of its states to join would need its staying choice hit from a state
not yet joined), and one that meets the seeds lies among them (its states reach the same
states), so among the states it leaves and the maybe states among its seeds, whose rows
alone are walked
(:func:`~mitld_lp.solvers.compiled_graph.closed_among`) in place of the pass over the whole
product's (QVBS zeroconf 1000-4: 49,892 of 214,063 maybe states, 122,602 of 697,823
entries; the sensed bus case: none of 43,930).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.mdp import MDP
from mitld_lp.solvers.analysis_patterns import candidates_pattern
from mitld_lp.solvers.analysis_singles import product_attractor, product_strategy
from mitld_lp.solvers.graph import (
    EndComponents,
    compiled_end_components,
    maximal_end_components,
)
from mitld_lp.solvers.result import read_only
from mitld_lp.solvers.rows import gather_ranges
from mitld_lp.solvers.value_one import SureStrategy
from mitld_lp.solvers.walks import compiled_walks
from mitld_lp.util.arrays import index_dtype

__all__ = ["end_components", "ends_and_sure", "may_cycle", "singles"]


def may_cycle(mdp: MDP, comp: np.ndarray) -> np.ndarray:
    """``(n_states,)`` bool: the states an end component may hold, given each state's
    strongly connected component ``comp`` in ``mdp``'s support graph (no zero stored):
    those of a non-trivial component, and those with a choice that stays put (it has
    entries, all in its own column: :func:`_stays_put`).  An end component is
    strongly connected: it is one of these states or lies among them."""
    size = np.bincount(comp, minlength=int(comp.max(initial=-1)) + 1)
    out = (size > 1)[comp]
    out[_stays_put(mdp)] = True
    return out


def _stays_put(mdp: MDP) -> np.ndarray:
    """The states (ascending, maybe repeated) with a choice all of whose entries lie in
    their own column (:func:`_staying_choices`' owners)."""
    return mdp.state_of(_staying_choices(mdp)) if mdp.matrix.nnz else \
        np.zeros(0, dtype=np.int64)


def _staying_choices(mdp: MDP) -> np.ndarray:
    """The choices (ascending) all of whose entries lie in their own state's column.
    Such a choice's first entry does: only the choices whose first entry does (few: a
    product's self-loops) have their other entries read, not a minimum and a maximum
    over every entry of the matrix and a reduction over every choice (0.044 -> 0.02 s
    of CPU on QVBS csma 4-2's 1.1 million entries; the same states).  A choice with no
    entry stays nowhere (none in a product) and a state with no choice has none that
    stays."""
    m = mdp.matrix
    if not m.nnz:
        return np.zeros(0, dtype=np.int64)
    own = mdp.choice_state()
    lo, hi = m.indptr[:-1], m.indptr[1:]
    cand = np.flatnonzero((hi > lo) & (m.indices[np.minimum(lo, m.nnz - 1)] == own))
    lo, hi = lo[cand], hi[cand]
    apart = m.indices[gather_ranges(lo, hi)] != np.repeat(own[cand], hi - lo)
    pure = np.ones(cand.size, dtype=bool)
    pure[np.repeat(np.arange(cand.size), hi - lo)[apart]] = False
    return cand[pure]


def _self_loops_only(mdp: MDP, maybe: np.ndarray) -> EndComponents:
    """The maximal end components of the ``maybe`` states of a product whose strongly
    connected components are single states (acyclic apart from self-loops: a deadline's
    clock counts time): each ``maybe`` state with a choice that stays put is one, alone,
    its internal choices those that stay put; numbered by their states, ascending, as
    the rounds number them (:func:`end_components`).  No sub-MDP, no rounds: the end
    components of such a graph need no search (QVBS zeroconf_dl 1000-1-30: 3,070
    self-loops)."""
    n = mdp.n_states
    stay = _staying_choices(mdp)
    stay = stay[maybe[mdp.state_of(stay)]]
    if not stay.size:  # none: the stride-0 record
        return EndComponents.none(n, mdp.n_choices)
    mec_of = np.full(n, -1, dtype=index_dtype(n))
    internal = np.zeros(mdp.n_choices, dtype=bool)
    internal[stay] = True
    members = np.unique(mdp.state_of(stay))
    mec_of[members] = np.arange(members.size)
    return EndComponents(read_only(mec_of), read_only(internal), int(members.size))


def singles(comp: np.ndarray) -> bool:
    """Whether ``comp`` labels some state and every component holds one state (a count
    a component; the analysis's fused pass knows it without one: ``singles`` below)."""
    return bool(comp.size) and int(np.bincount(comp).max()) == 1


def end_components(mdp: MDP, comp: np.ndarray, maybe: np.ndarray,
                   one_each: bool | None = None) -> EndComponents:
    """The maximal end components of the ``maybe`` states (module docs), given each
    state's strongly connected component ``comp`` in ``mdp``'s support graph: searched
    by :func:`~mitld_lp.solvers.graph.maximal_end_components` on the sub-MDP of the
    candidates (the states of non-trivial components and those with a choice that
    stays put), with one extra absorbing state standing for everything else; none
    searched for when there is no candidate (an acyclic product) or, on the compiled
    walks, when one attractor pass shows there is none (:func:`_none_among`).  The
    same components as :func:`~mitld_lp.solvers.graph.maximal_end_components` on
    ``maybe``, numbered in another order (which it is, on a matrix that stores a
    zero).  Where every component is one state, :func:`_self_loops_only`; ``one_each``:
    whether it is (:func:`singles`), where the caller knows (else counted here)."""
    m = mdp.matrix
    if m.nnz and not bool(np.all(m.data > 0)):  # a stored zero is no edge: not a loop
        return maximal_end_components(mdp, maybe)
    if singles(comp) if one_each is None else one_each:  # acyclic apart from self-loops
        return _self_loops_only(mdp, maybe)
    return _searched(mdp, comp, maybe)


def _searched(mdp: MDP, comp: np.ndarray, maybe: np.ndarray, some: bool = False,
              ) -> EndComponents:
    """:func:`end_components` by the search (no stored zero); ``some``: an end component
    is known to lie among the ``maybe`` states (:func:`ends_and_sure`), so no pass tests it."""
    n = mdp.n_states
    m = mdp.matrix
    walks = compiled_walks(m.nnz)
    if walks is not None and not some and _none_among(walks, m, np.asarray(mdp.row_groups),
                                                     maybe):
        return EndComponents.none(n, mdp.n_choices)
    cand = np.flatnonzero(maybe & may_cycle(mdp, comp))
    if cand.size == 0:
        return EndComponents.none(n, mdp.n_choices)
    mec_of = np.full(n, -1, dtype=index_dtype(n))  # kept by both quotients
    internal = np.zeros(mdp.n_choices, dtype=bool)
    if walks is not None and walks.fits(n, m.nnz):  # the rounds among the candidates
        found = compiled_end_components(walks, mdp, cand)
        if not found.n_mecs:
            return EndComponents.none(n, mdp.n_choices)
        return EndComponents(read_only(found.mec_of.astype(mec_of.dtype, copy=False)),
                             found.internal, found.n_mecs)
    lo, hi = mdp.row_groups[cand], mdp.row_groups[cand + 1]
    choices = gather_ranges(lo, hi)
    sub = candidates_pattern(m, choices, cand, n)
    k = cand.size + 1
    row_groups = np.concatenate([[0], np.cumsum(hi - lo), [choices.size + 1]])
    no = np.zeros(k, dtype=bool)
    small = MDP(matrix=sub, row_groups=row_groups,
                choice_actions=np.zeros(choices.size + 1, dtype=np.int32), action_names=(),
                initial=0, target=no, sink=no, truncated=no, states=range(k))
    found = maximal_end_components(small, np.arange(k) < cand.size)
    mec_of[cand] = found.mec_of[: cand.size]
    internal[choices] = found.internal[: choices.size]
    return EndComponents(read_only(mec_of), read_only(internal), found.n_mecs)


def _none_among(walks: Any, m: sp.csr_array, groups: np.ndarray, maybe: np.ndarray,
                ) -> bool:
    """Whether no end component lies among the ``maybe`` states, shown by one compiled
    :func:`~mitld_lp.solvers.graph.attractor` pass instead of de Alfaro's rounds: the
    states from which every policy leaves them (or stops: a state with no choice) with
    positive probability.  Its complement among them is closed (each such state has a
    choice whose support stays there), so it holds an end component iff it is not
    empty; an end component's states never join (each keeps a choice inside it).  A
    rare event's product (QVBS zeroconf 1000-4: 213,268 candidates, none) is decided
    here in one pass over the pattern, with the attractor's kernel, which the
    quotient's prob-1 states load anyway.  ``m`` stores no zero (the caller checked)."""
    seeds = ~maybe | (np.diff(groups) == 0)
    left = walks.backward(m.indptr, m.indices, groups, seeds,
                          np.zeros(m.shape[0], dtype=bool), True)
    return bool(np.all(left[maybe]))


def ends_and_sure(mdp: MDP, comp: np.ndarray, maybe: np.ndarray, zero: np.ndarray,
                  one_each: bool | None = None,
                  ) -> tuple[EndComponents, tuple[np.ndarray, SureStrategy | None] | None]:
    """:func:`end_components` of the ``maybe`` states, and where there is none and the
    compiled walks search them, :func:`~mitld_lp.solvers.analysis_singles.
    prob1e_on_product`'s answer for the prob-0 states ``zero`` (else None: the caller
    finds it): its attractor first, then the end components' test on the maybe states
    it leaves alone (module docs).  The same components, sets and strategy.  ``one_each``:
    :func:`end_components`'s (counted once here where the caller passes None)."""
    m = mdp.matrix
    walks = compiled_walks(m.nnz)
    if walks is None or not walks.fits(max(mdp.n_states, mdp.n_choices), m.nnz) \
            or (m.nnz and not bool(np.all(m.data > 0))):
        return end_components(mdp, comp, maybe, one_each), None
    one_each = singles(comp) if one_each is None else one_each
    if one_each:
        return end_components(mdp, comp, maybe, one_each), None
    got = product_attractor(mdp, m, maybe, zero, None)
    if got is None:  # the targets not closed: the copied pattern's route
        return end_components(mdp, comp, maybe, one_each), None
    sure = maybe & ~got[0]
    # the maybe states the attractor left, and those it started from: a maybe state of
    # prob 0 for the goal (it reaches a truncated state only) may lie in an end component
    # of such states, all of them seeds
    among = sure | (maybe & zero)
    at = np.flatnonzero(among)
    if at.size and walks.closed_among(m.indptr, m.indices, np.asarray(mdp.row_groups), at,
                                      among):
        return _searched(mdp, comp, maybe, some=True), None  # some: searched as before
    none = EndComponents.none(mdp.n_states, mdp.n_choices)
    return none, product_strategy(mdp, sure, got[1], none)
