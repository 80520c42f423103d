"""The record every solver works on: the MEC quotient of an MDP (:class:`Quotient`).

Built by :func:`mitld_lp.solvers.analysis.analyse` (:func:`mitld_lp.solvers.quotient.
reduce` for one model); kept here, below the analysis and the solvers, so that each can
name it without importing the others.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.mdp import MDPShape
from mitld_lp.solvers.graph import Blocks, EndComponents, Sense, segmented_argmax
from mitld_lp.solvers.rows import first_choice_without

__all__ = ["Qualitative", "Quotient", "greedy_choices", "keeping_zero"]


@dataclass(frozen=True, slots=True, eq=False)
class Qualitative:
    """The states whose optimal probability of reaching the target (in ``sense``) the
    support graph decides, before any number is computed (Storm's *prob01*): exactly
    0 on ``zero``, exactly 1 on ``one``, and strictly between 0 and 1 everywhere else.

    Attributes:
        sense: the optimum they are about.
        zero: ``(n_states,)`` bool: ``Prob0A`` for a maximum (no path to the target),
            ``Prob0E`` for a minimum (some policy avoids the target for ever).
        one: ``(n_states,)`` bool, the target included: ``Prob1E`` for a maximum (some
            policy reaches it almost surely), ``Prob1A`` for a minimum (every policy
            does).
        unreachable: ``(n_states,)`` bool, ``Prob0A`` (no path to the target, so no
            policy's value is above 0 there); ``zero`` itself for a maximum.
    """

    sense: Sense
    zero: np.ndarray
    one: np.ndarray
    unreachable: np.ndarray

    @property
    def inside(self) -> np.ndarray:
        """``(n_states,)`` bool: the states whose value is strictly between 0 and 1."""
        return ~(self.zero | self.one)


@dataclass(frozen=True, slots=True, eq=False)
class Quotient(MDPShape):
    """The *maybe* part of an MDP with its maximal end components collapsed: a total
    reward (the one-step probability of entering the target) to optimise in a
    ``sense`` on a model with no end component.

    Built by :func:`reduce`.  Target states (value 1) and prob-0 states (value 0) are
    removed (and by :func:`~mitld_lp.solvers.analysis.analyse`, the plain route's, the
    goal's other states of value 1 too: Prob1A / Prob1E, their probability counted in
    ``to_target``); for a maximum every MEC of the remaining *maybe* states becomes one state
    whose choices are the choices of its members that are not internal to it (they
    leave the MEC with positive probability).  For a minimum the prob-0 states are
    ``Prob0E`` (some policy avoids the target for ever), and no end component is left
    among the others (its states could avoid the target for ever): nothing is
    collapsed.  Either way the result has no end components, so every policy leaves
    the maybe states with probability 1: the occupancy LP is bounded and both
    sequences of interval iteration converge to the optimum.

    Reduced states are numbered: first the maybe states outside any MEC (in the order of
    the original states), then one state per MEC (``n_plain + mec id``).
    MDP-shaped (:class:`~mitld_lp.mdp.MDPShape`), with rows short of 1 by what enters the
    target or prob-0 in one step.

    Attributes:
        target: ``(n_states,)`` bool, the original target mask (value 1).
        prob0: ``(n_states,)`` bool, the states removed with value 0: ``Prob0A`` (no
            path to the target) for a maximum, ``Prob0E`` for a minimum.
        state_map: ``(n_states,)`` the reduced state of each original state, ``-1``
            for removed (target / prob-0) ones; int32 where the count of states
            allows, else int64 (:func:`mitld_lp.util.arrays.index_dtype`).
        mecs: the MECs of the maybe states (ids as in ``mecs.mec_of``).
        n_plain: number of maybe states outside any MEC.
        matrix: ``(n_reduced_choices, n_reduced_states)`` CSR, probability of moving
            between reduced states (mass to target / prob-0 states is not in it).
        to_target: ``(n_reduced_choices,)`` probability of entering ``target`` in one
            step; the rest of a row's mass (``1 - to_target - row sum``) enters prob-0.
        row_groups: ``(n_reduced_states + 1,)`` the choices of each reduced state.
        choice_origin: ``(n_reduced_choices,)`` the original choice of each reduced
            one (increasing among one original state's choices); int32 where the count
            of choices allows, else int64.
        initial: the reduced initial state, or ``-1`` if the initial state was removed.
        initial_value: the value of the initial state if it was removed (1.0 if it is a
            target state, 0.0 if it is prob-0), else ``nan``.
        order: the strongly connected components of the reduced states in levels,
            downstream first (:class:`~mitld_lp.solvers.topological.Blocks`), from the
            one analysis that made the quotient; every solver walks it.
        zero: ``(n_reduced_states,)`` bool, reduced states known to have value 0: a
            quotient shared with a larger target (:func:`mitld_lp.solvers.analysis.
            analyse`) keeps the states that reach only the larger one; empty for
            :func:`reduce`'s own.
        layers: the component of each *original* state in the product's support graph
            and a level per component: the product's where the compiled walk found them,
            else the quotient's own levels lifted to the components whose states all stay
            in the quotient, -1 for the others (a reader of a -1 finds levels of its own:
            ``certify_chain.chain``, ``certify._repair_levels``,
            ``evaluation._solve_transient``).
        sense: whether the solvers maximise or minimise on it.
        qualitative: the values the graph decides (:class:`Qualitative`, per original
            state).
    """

    target: np.ndarray
    prob0: np.ndarray
    state_map: np.ndarray
    mecs: EndComponents
    n_plain: int
    matrix: sp.csr_array
    to_target: np.ndarray
    row_groups: np.ndarray
    choice_origin: np.ndarray
    initial: int
    initial_value: float
    order: Blocks
    zero: np.ndarray
    layers: tuple[np.ndarray, np.ndarray]
    sense: Sense
    qualitative: Qualitative
    # what the solvers work out once for the quotients of one analysis and keep: a
    # maximum's attractor strategy of its removed value-1 states, recorded by the
    # analysis or searched once per model (:func:`mitld_lp.solvers.quotient.
    # lift_policy`); no array of every state, nothing the size of the matrix
    # (the single-state levels, kept from the iteration to the LP, raised the peak by
    # a fifth on QVBS firewire_dl 3-600 for 0.02 s)
    shared: dict[Any, Any] = field(default_factory=dict, repr=False)

    def lift(self, reduced: np.ndarray) -> np.ndarray:
        """Map a per-reduced-state value vector back to the original states.

        Members of a collapsed MEC all get the MEC's value; a removed state its value
        decided by the graph: 1 on ``qualitative.one`` (the target, and the goal's other
        states of value 1 that :func:`~mitld_lp.solvers.analysis.analyse` removes), 0
        on the prob-0 states.
        """
        values = np.asarray(reduced, dtype=np.float64)
        if values.size == 0:  # nothing kept: every state is of value 1 or 0
            return np.where(self.qualitative.one, 1.0, 0.0)
        # one gather over every state (a removed one, -1, reads the last value and is
        # overwritten), not the kept states' indices and values gathered apart: one
        # float a state and a mask where there were three arrays a state
        out = values[self.state_map]
        np.copyto(out, self.qualitative.one, where=self.state_map < 0)
        return out


def greedy_choices(q: Quotient, v: np.ndarray, *, tie: float = 1e-12) -> np.ndarray:
    """Per reduced state, the reduced choice best for ``q.sense`` (maximising, or
    minimising) ``P(c,target) + sum P(c,s') v(s')``.

    Ties (within ``tie`` relative to the best score, so that values of 1e-30 are told
    apart) go to the choice with the larger one-step probability of entering the target
    for a maximum (a cheap measure of progress), the smaller for a minimum.  On the
    quotient every policy leaves the maybe states almost surely (no end components
    remain), so a greedy policy on exact values is optimal and never loops forever.
    """
    scores = q.to_target + q.matrix @ v
    prefer = q.to_target if q.sense is Sense.MAX else -q.to_target
    return segmented_argmax(scores, q.row_groups, tie=tie, prefer=prefer, sense=q.sense)


def keeping_zero(q: Quotient, *, zero_only: bool = False) -> np.ndarray:
    """Per reduced state, its first choice that keeps a value of 0: no probability of
    entering the target and every successor known to be 0 (``q.zero``).  Every choice
    of a maximum's zero state does (it has no path to the target); a minimum's zero
    state (some policy avoids the target for ever) has one.  The first choice where
    none does.

    A byte an entry (whether its successor may be above 0), or-ed over each choice's
    entries, and the keeping choices' indices only: no int64 row of every entry nor
    float64 arrays of every choice (they were the sensed case's traced peak, at the LP
    stage).  ``zero_only``: only the states of ``q.zero`` are searched (their rows
    alone read), every other state gets its first choice (the LP's callers overwrite
    those: the sensed case has 17 zero states of 43,930, whose search read all 725,036
    entries)."""
    if zero_only:
        return _keeping_zero_of(q, np.flatnonzero(q.zero))
    ptr = q.matrix.indptr
    moves = np.zeros(q.n_choices, dtype=bool)
    if q.matrix.indices.size:
        nonzero = q.zero[q.matrix.indices]
        np.logical_not(nonzero, out=nonzero)
        stored = ptr[1:] > ptr[:-1]  # reduceat reads an empty row as its next entry
        moves[stored] = np.logical_or.reduceat(nonzero, ptr[:-1][stored])
        del nonzero, stored
    keeps = np.flatnonzero(~moves & (q.to_target == 0.0))
    del moves
    groups = np.asarray(q.row_groups)
    out = np.asarray(groups[:-1], dtype=np.int64).copy()
    owner = np.searchsorted(groups, keeps, side="right") - 1  # each one's state
    first = np.ones(keeps.size, dtype=bool)  # (keeps ascending: owners too)
    np.not_equal(owner[1:], owner[:-1], out=first[1:])
    out[owner[first]] = keeps[first]
    return out


def _keeping_zero_of(q: Quotient, states: np.ndarray) -> np.ndarray:
    """:func:`keeping_zero` of ``states`` (increasing), the first choice elsewhere
    (:func:`~mitld_lp.solvers.rows.first_choice_without`: a chunk of their entries at
    a time; a stored zero is still a move)."""
    out = np.asarray(q.row_groups[:-1], dtype=np.int64).copy()
    zero, to_target, m = np.asarray(q.zero, dtype=bool), np.asarray(q.to_target), q.matrix
    out[states] = first_choice_without(q.row_groups, m, states,
                                       lambda e: ~zero[m.indices[e]],
                                       lambda c: to_target[c] == 0.0)
    return out
