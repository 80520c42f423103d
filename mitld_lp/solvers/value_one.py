r"""The goal's states of value 1 found before the analysis makes its quotient (for
:func:`~mitld_lp.solvers.analysis.analyse`), on the product's pattern alone, as Storm's
*prob01* finds them before any number: the quotient is then built once, of the states
whose value is unknown, not of every maybe state and then cut (QVBS csma 4-2: 232,132 of
its 232,810 maybe states have value 1; zeroconf 1000-4: 49,892 of 214,063).

* a minimum's (``Prob1A``, :func:`prob1a_first`): the maybe states with no path through
  maybe states to a prob-0 state (:func:`~mitld_lp.solvers.reach.reaching_through`);
* a maximum's (``Prob1E``, :func:`prob1e_first`) where no end component is collapsed
  (the quotient's states are then the maybe states themselves): the maybe states
  outside the :func:`~mitld_lp.solvers.graph.attractor` of the prob-0 states over the
  maybe states' choices, and the lift's strategy there read from the same attractor
  (:func:`attractor_strategy`, kept in ``Quotient.shared`` under
  :data:`ATTRACTOR_STRATEGY`).

Both are the sets, hits and strategy the same search on the quotient gives: a prob-0
state is a seed either way (on the quotient, a kept one is a seed and a removed one makes
its readers' choices hit), and a removed state of another kind never joins (it has no
choice in the search, as its column has none in the quotient).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mitld_lp.mdp import MDP
from mitld_lp.solvers.graph import EndComponents, attractor_spared, toward
from mitld_lp.solvers.quotient_rows import row_columns, take_ranges
from mitld_lp.solvers.reach import Reversed, reaching_through
from mitld_lp.solvers.result import read_only
from mitld_lp.solvers.rows import gather_ranges
from mitld_lp.util.arrays import index_dtype

__all__ = ["ATTRACTOR_STRATEGY", "SureStrategy", "attractor_strategy", "choices_of",
           "prob1a_first", "prob1e_first"]


def prob1a_first(m: sp.csr_array, row_groups: np.ndarray, maybe: np.ndarray,
                 zero: np.ndarray, back: Reversed | np.ndarray | None = None) -> np.ndarray:
    """``(n,)`` bool: a minimum's ``maybe`` states of value 1 for the target whose
    prob-0 states are ``zero``: those with no path through ``maybe`` states to one.
    With ``back`` (the state graph reversed, :func:`~mitld_lp.solvers.graph.
    components_reaching`'s) and the other states closed (:func:`_closed`: every entry
    of their choices stays among them, as a product's absorbing targets do), no path
    to ``zero`` runs through them, so the plain backward search on ``back`` gives the
    same states, with no edge list gathered and reversed for it (QVBS csma 4-2: 0.015
    -> 0.004 s of CPU).  ``back`` may be that search's answer already (``(n,)`` bool, the
    states reaching ``zero``: :mod:`~mitld_lp.solvers.analysis_reach`'s pass)."""
    sure = np.zeros(maybe.size, dtype=bool)
    if back is not None and _closed(m, np.asarray(row_groups), ~maybe & ~zero):
        reached = back if isinstance(back, np.ndarray) else back.reaching(zero)
        sure[maybe] = ~reached[maybe]
    else:
        sure[maybe] = ~reaching_through(m, row_groups, maybe, zero)[maybe]
    return sure


def _closed(m: sp.csr_array, row_groups: np.ndarray, states: np.ndarray) -> bool:
    """Whether every entry of the choices of ``states`` lies in a column of ``states``."""
    at = np.flatnonzero(states)
    # the columns read a slice at a time (take_ranges), not an index array every entry
    return bool(np.all(states[take_ranges(m.indices, m.indptr[row_groups[at]],
                                          m.indptr[row_groups[at + 1]])]))


def prob1e_first(mdp: MDP, m: sp.csr_array, maybe: np.ndarray, zero: np.ndarray,
                 no_mecs: EndComponents, *, internal_hit: bool = False,
                 ) -> tuple[np.ndarray, SureStrategy | None]:
    """``(n,)`` bool: a maximum's ``maybe`` states of value 1 for the target whose
    prob-0 states are ``zero``, where no end component is collapsed (``no_mecs``):
    those outside the attractor of ``zero`` over the ``maybe`` states' choices (the
    pattern of their rows, every other state without a choice); and the lift's
    strategy there (:func:`attractor_strategy`, None where there is none), read from
    the choices the attractor spared, numbered as the quotient of every maybe state
    would number them.  ``internal_hit``: ``no_mecs`` has components, each one state,
    whose internal choices count as hit from the start (their state kept as its own:
    :func:`~mitld_lp.solvers.analysis_singles.prob1e_single_states`)."""
    n = mdp.n_states
    groups = np.asarray(mdp.row_groups)
    states = np.flatnonzero(maybe)
    kept, _ = choices_of(groups, states)
    per_state = np.zeros(n, dtype=np.int64)
    per_state[states] = groups[states + 1] - groups[states]
    sub_groups = np.concatenate([[0], np.cumsum(per_state)])
    del per_state
    indptr = np.concatenate([[0], np.cumsum(m.indptr[kept + 1] - m.indptr[kept])]
                            ).astype(m.indptr.dtype)
    pattern = sp.csr_array((np.broadcast_to(np.float64(1.0), (int(indptr[-1]),)),
                            row_columns(m, kept), indptr),
                           shape=(kept.size, n), copy=False)
    lose, hit = attractor_spared(pattern, sub_groups, zero,
                                 np.asarray(no_mecs.internal)[kept] if internal_hit else None)
    del pattern, sub_groups
    sure = np.zeros(n, dtype=bool)
    sure[states] = ~lose[states]
    if not sure.any():
        return sure, None
    # the quotient of every maybe state's numbering: its states, groups and choices
    state_map = np.full(n, -1, dtype=index_dtype(n))
    state_map[states] = np.arange(states.size)
    row_groups = np.concatenate([[0], np.cumsum(groups[states + 1] - groups[states])]
                                ).astype(np.int64)
    played = attractor_strategy(mdp, sure[states], ~hit, row_groups,
                                kept.astype(index_dtype(mdp.n_choices), copy=False),
                                state_map, states.size, no_mecs)
    return sure, played


def choices_of(row_groups: np.ndarray, states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The choices of ``states`` (ascending ids) in ascending order, and each one's
    state: read from their ranges of ``row_groups``, as ``np.flatnonzero(mask[
    choice_state])`` would give them with no array a choice of the whole product."""
    lo, hi = row_groups[states], row_groups[states + 1]
    return gather_ranges(lo, hi), np.repeat(states, hi - lo)




ATTRACTOR_STRATEGY = "attractor strategy"
"""The key in ``Quotient.shared`` of a maximum's strategy for its removed value-1 states
(:func:`attractor_strategy`, a :class:`SureStrategy`)."""


@dataclass(frozen=True, slots=True, eq=False)
class SureStrategy:
    """A strategy of some states: ``states`` (ascending) and each one's choice (a row of
    the product).  Equal to another with the same arrays (two analyses of one product
    compare equal, as their other records do)."""

    states: np.ndarray
    choices: np.ndarray

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, SureStrategy)
                and self.states.dtype == other.states.dtype
                and self.choices.dtype == other.choices.dtype
                and np.array_equal(self.states, other.states)
                and np.array_equal(self.choices, other.choices))

    __hash__ = None  # type: ignore[assignment]  # mutable-looking arrays: unhashable


def attractor_strategy(mdp: MDP, sure: np.ndarray, spared: np.ndarray,
                        row_groups: np.ndarray, kept: np.ndarray | None,
                        state_map: np.ndarray | None, n_plain: int, mecs: EndComponents,
                        ) -> SureStrategy | None:
    """A maximum's strategy for the product states of the reduced states ``sure``
    (``Prob1E`` of the goal, about to leave the quotient), read from the attractor that
    found them (:func:`prob1e_first`, or the analysis's ``_one`` on a quotient
    with collapsed end components): each such reduced state plays its first choice
    ``spared`` (one that cannot lose: its support stays among the ``sure`` states, and
    what leaves the quotient goes to the target), a collapsed end component's through
    the member that owns that exit, the other members a step along a breadth-first tree
    of the component's internal choices toward it (as
    :func:`~mitld_lp.solvers.quotient.lift_policy` does).  It reaches the target almost
    surely: a closed class of its chain among the ``sure`` states would map to a set
    of reduced states each with a choice staying among them, holding an end component
    of the quotient, which has none (its maximal ones are collapsed; a member's walk
    reaches the exit's owner with positive probability).  The product states ascending
    and each one's choice (rows of ``mdp``); None if a state
    has no such choice (never, by the attractor's fixed point: the caller keeps the
    second search then).  ``kept`` and ``state_map`` None: the reduced states and
    choices are the product's own (an attractor over the product's rows, ``n_plain`` its
    states: no component collapsed), so each state's first spared choice is its own
    play, with no array a state of the product mapped."""
    red = np.flatnonzero(sure)
    rows, owner = choices_of(row_groups, red)
    free = spared[rows]
    rows, owner = rows[free], owner[free]
    # each state's first (owner ascending, choices_of's order): where the owner changes,
    # np.unique's first occurrences without its sort (QVBS zeroconf_dl: 1.5 ms)
    first = np.flatnonzero(np.diff(owner, prepend=-1) != 0)  # owners are not negative
    has = owner[first]
    if has.size != red.size:  # pragma: no cover - the attractor spares one a state
        return None
    itype = index_dtype(mdp.n_choices)
    if state_map is None:  # the product's own rows: each sure state plays its first
        return SureStrategy(read_only(red.astype(index_dtype(mdp.n_states), copy=False)),
                            read_only(rows[first].astype(itype, copy=False)))
    play = np.full(sure.size, -1, dtype=np.int64)
    play[red] = kept[rows[first]]
    del rows, owner, free, has, first
    mapped = state_map >= 0
    states = np.flatnonzero(mapped)
    states = states[sure[state_map[states]]]
    choices = play[state_map[states]]
    if sure[n_plain:].any():  # members of a collapsed end component: toward its exit
        exits = play[n_plain:][sure[n_plain:]]
        owners = mdp.state_of(exits)
        member = np.asarray(mecs.mec_of)[states] >= 0
        walk = member & ~np.isin(states, owners)
        if walk.any():  # none where each such component is one state (a self-loop)
            internal = np.flatnonzero(mecs.internal)
            internal = internal[sure[n_plain + np.asarray(mecs.mec_of)[
                mdp.state_of(internal)]]]
            step = toward(mdp, internal, owners)
            if np.any(step[states[walk]] < 0):  # pragma: no cover - strongly connected
                return None
            choices[walk] = step[states[walk]]
    return SureStrategy(read_only(states.astype(index_dtype(mdp.n_states), copy=False)),
                        read_only(choices.astype(itype, copy=False)))
