r"""A maximum's goal states of value 1 found on the product's pattern where every maximal
end component is one state (for :func:`~mitld_lp.solvers.analysis.analyse`).

A deadline's product is acyclic apart from self-loops: its end components are single
states with a choice that stays put (QVBS zeroconf_dl 1000-1-30: 3,068 of them among
91,929 maybe states, of which 72,908 have value 1).  Collapsing such a component only
drops its staying choices (its state keeps its number's place among the others), so the
quotient's value-1 states are found, as :func:`~mitld_lp.solvers.value_one.prob1e_first`
finds them where there is no end component, by one attractor of the prob-0 states over
the maybe states' choices, the components' staying choices counted as hit from the start
(as if absent: a state joins once its other choices are hit).  The quotient is then built
once, of the states whose value is unknown, instead of every maybe state's quotient built,
searched and cut (``analysis._without_one``); the components whose state has value 1
leave it (:func:`without_states`), the others numbered as before in the same order.

The lift's strategy there is the one :func:`~mitld_lp.solvers.value_one.
attractor_strategy` reads from the same attractor: each such state's first choice the
attractor spared, never a staying one (hit from the start).  It reaches the target almost
surely: a closed class of its chain among those states would be an end component of the
maybe states, so one state with a staying choice, and the choice played there leaves it.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from mitld_lp.mdp import MDP
from mitld_lp.solvers.graph import EndComponents, attractor_spared
from mitld_lp.solvers.quotient_rows import take_ranges
from mitld_lp.solvers.result import read_only
from mitld_lp.solvers.value_one import SureStrategy, attractor_strategy, prob1e_first

__all__ = ["prob1e_on_product", "prob1e_single_states", "product_attractor", "product_strategy",
           "single_states", "without_states"]


def single_states(mecs: EndComponents) -> bool:
    """Whether ``mecs`` has components and each is one state."""
    if not mecs.n_mecs:
        return False
    mec_of = np.asarray(mecs.mec_of)
    return int(np.count_nonzero(mec_of >= 0)) == mecs.n_mecs


def prob1e_single_states(mdp: MDP, m: sp.csr_array, maybe: np.ndarray, zero: np.ndarray,
                         mecs: EndComponents) -> tuple[np.ndarray, SureStrategy | None]:
    """``(n,)`` bool: a maximum's ``maybe`` states of value 1 for the target whose prob-0
    states are ``zero``, where each of the end components ``mecs`` is one state (module
    docs): those outside the attractor of ``zero`` over the ``maybe`` states' choices,
    the components' internal choices hit from the start; and the lift's strategy there
    (None where there is none)."""
    return prob1e_first(mdp, m, maybe, zero, mecs, internal_hit=True)


def without_states(mecs: EndComponents, gone: np.ndarray, mdp: MDP) -> EndComponents:
    """``mecs`` without the components holding a state of ``gone`` (``(n,)`` bool), the
    others numbered in the same order: a removed component's members and internal
    choices are no longer any component's."""
    mec_of = np.asarray(mecs.mec_of)
    members = mec_of >= 0
    drop = np.zeros(mecs.n_mecs, dtype=bool)
    drop[mec_of[members & gone]] = True
    if not drop.any():
        return mecs
    if drop.all():  # none left: the record of none (stride-0 views)
        return EndComponents.none(mec_of.size, np.asarray(mecs.internal).size)
    renumber = np.cumsum(~drop) - 1
    renumber[drop] = -1
    new_of = np.where(members, renumber[np.maximum(mec_of, 0)], -1).astype(mec_of.dtype)
    internal = np.array(mecs.internal, dtype=bool)
    was = np.flatnonzero(internal)
    internal[was[new_of[mdp.state_of(was)] < 0]] = False
    return EndComponents(read_only(new_of), read_only(internal), int(np.count_nonzero(~drop)))


def prob1e_on_product(mdp: MDP, m: sp.csr_array, maybe: np.ndarray, zero: np.ndarray,
                      mecs: EndComponents) -> tuple[np.ndarray, SureStrategy | None] | None:
    """:func:`prob1e_single_states` (and :func:`~mitld_lp.solvers.value_one.
    prob1e_first` where ``mecs`` has none) by one attractor over the product's own rows,
    no pattern of the maybe states' rows copied, where the states neither ``maybe`` nor
    ``zero`` (a product's targets) are closed: every entry of their choices stays among
    them, so none of their choices is hit before one of them joins, and none joins (as
    in the copied pattern, where they have no choice).  The same sets, hits and
    strategy (the maybe states' choices in the same order); None where they are not
    closed (the caller copies the pattern)."""
    got = product_attractor(mdp, m, maybe, zero,
                            np.asarray(mecs.internal) if mecs.n_mecs else None)
    if got is None:
        return None
    return product_strategy(mdp, maybe & ~got[0], got[1], mecs)


def product_attractor(mdp: MDP, m: sp.csr_array, maybe: np.ndarray, zero: np.ndarray,
                      internal: np.ndarray | None) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`prob1e_on_product`'s attractor of ``zero`` over the product's rows
    (``internal``: the choices hit from the start, or None), with its hit choices
    (:func:`~mitld_lp.solvers.graph.attractor_spared`); None where the states neither
    ``maybe`` nor ``zero`` are not closed."""
    groups = np.asarray(mdp.row_groups)
    others = ~maybe & ~zero
    at = np.flatnonzero(others)
    if not bool(np.all(others[take_ranges(m.indices, m.indptr[groups[at]],
                                          m.indptr[groups[at + 1]])])):
        return None
    del at, others
    return attractor_spared(m, groups, zero, internal)


def product_strategy(mdp: MDP, sure: np.ndarray, hit: np.ndarray, mecs: EndComponents,
                     ) -> tuple[np.ndarray, SureStrategy | None]:
    """``sure`` (the maybe states outside :func:`product_attractor`'s set) and the lift's
    strategy there, read from its ``hit`` choices (None where no state is sure)."""
    if not sure.any():
        return sure, None
    # the product's own rows: no map of its states and choices (attractor_strategy)
    return sure, attractor_strategy(mdp, sure, ~hit, np.asarray(mdp.row_groups), None, None,
                                    mdp.n_states, mecs)
