"""A sparse Markov decision process: one CSR matrix with a row per (state, action).

The rows of state ``s`` are ``row_groups[s]:row_groups[s+1]`` (its *choices*); row ``c``
of ``matrix`` is the successor distribution of choice ``c`` and sums to 1.  Every state
has at least one choice; the absorbing states (``target``, ``sink``, ``truncated``) have
exactly one, a self-loop, whose action label is ``ABSORB`` (-1).

This module holds the record only, and the shape it shares with every MDP-shaped record
(:class:`MDPShape`): the product builds it, the controller runs on it, the exports write
it.  The analyses of its support graph (prob-0/1 states, end components) and the
reduction every solver works on are in :mod:`mitld_lp.solvers.quotient`.

Three disjoint absorbing classes are kept apart:

* ``target``    -- the automaton accepted: the task is satisfied;
* ``sink``      -- the automaton rejected: the task can no longer be satisfied;
* ``truncated`` -- a truncated event clock ran past its truncation point.  Counting it
  as losing gives a lower bound on the optimum, as winning an upper bound.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.util.arrays import index_dtype

__all__ = ["ABSORB", "MDP", "MDPShape", "ActionChoices", "absorbing_states",
           "as_state_mask"]

ABSORB = -1
"""Action label of the self-loop choice of an absorbing state."""

STATE_OF_SLICE = 1 << 16
"""Choices :meth:`MDPShape.state_of` searches at a time."""


class MDPShape:
    """The shape every MDP-shaped record shares, defined once: the product's :class:`MDP`,
    the interval MDP (:class:`mitld_lp.product.imdp.IntervalMDP`), the robust game
    (:class:`mitld_lp.solvers.robust_graph.RobustGame`), the MEC quotient
    (:class:`mitld_lp.solvers.reduced.Quotient`), the certificates' row model
    (:class:`mitld_lp.solvers.certify_chain.RowModel`), a DRN file's model
    (:class:`mitld_lp.files.drn.DrnModel`); a constrained synthesis's merged model holds
    an :class:`MDP`.

    States are ``0 .. n_states-1``; the choices of state ``s`` are the consecutive rows
    ``row_groups[s]:row_groups[s+1]`` (Storm's *row groups*, every state has at least one
    choice); each choice has one successor distribution, row ``c`` of ``matrix``, unless
    the record says otherwise in :meth:`distributions` (the interval MDP's branches and
    the robust game's vertex rows: several per choice).

    A base class rather than a :class:`typing.Protocol`: a protocol would name these
    members, but each record would still derive them from its arrays, which is the
    repetition this class removes; the records inherit them (``__slots__ = ()``, so the
    frozen, slotted dataclasses stay slotted), and code that takes any of them names
    this class.
    """

    __slots__ = ()

    row_groups: np.ndarray
    matrix: sp.csr_array

    @property
    def n_states(self) -> int:
        return int(self.row_groups.shape[0] - 1)

    @property
    def n_choices(self) -> int:
        return int(self.row_groups[-1])

    @property
    def n_transitions(self) -> int:
        """Number of stored (distribution, successor) entries."""
        return int(self.distributions()[0].nnz)

    def choices(self, state: int) -> range:
        """The row indices of ``state``'s choices."""
        return range(int(self.row_groups[state]), int(self.row_groups[state + 1]))

    def choice_state(self) -> np.ndarray:
        """``(n_choices,)`` int64: the state each choice belongs to.  Counted up from
        where each state's choices start: the one array it returns, no per-state
        temporaries (the analysis asks for it while the quotient is built)."""
        starts = self.row_groups[1:-1]
        out = np.bincount(starts, minlength=self.n_choices + 1)[: self.n_choices]
        return np.cumsum(out, out=out)

    def state_of(self, choices: np.ndarray) -> np.ndarray:
        """``(len(choices),)``: the state each of ``choices`` belongs to, as
        ``choice_state()[choices]`` without the array a choice of the whole model (a
        binary search in ``row_groups``).  Int32 where the states fit in it
        (:func:`~mitld_lp.util.arrays.index_dtype`), else int64, searched
        :data:`STATE_OF_SLICE` choices at a time: the search's own int64 answer is never
        one of the whole array (its callers gather and index with it; no compiled kernel
        reads it).  The prob-one attractor's edge sources (``solvers.quotient``) were
        5 bytes a transition of QVBS zeroconf_dl's peak."""
        choices = np.asarray(choices)
        if choices.ndim != 1:
            out = np.searchsorted(self.row_groups, choices, side="right")
            out -= 1
            return out
        out = np.empty(choices.shape[0], dtype=index_dtype(self.n_states))
        for lo in range(0, out.shape[0], STATE_OF_SLICE):
            part = np.searchsorted(self.row_groups, choices[lo : lo + STATE_OF_SLICE],
                                   side="right")
            np.subtract(part, 1, out=out[lo : lo + STATE_OF_SLICE], casting="unsafe")
        return out

    def distributions(self) -> tuple[sp.csr_array, np.ndarray | None]:
        """``(rows, groups)``: the successor distributions, one CSR row each, and the
        rows of choice ``c``, ``groups[c]:groups[c+1]`` (``None``: row ``c`` alone)."""
        return self.matrix, None

    def successors(self, choice: int) -> np.ndarray:
        """The states ``choice`` reaches with positive probability in some of its
        distributions, increasing."""
        rows, groups = self.distributions()
        first, last = (choice, choice + 1) if groups is None else (
            int(groups[choice]), int(groups[choice + 1]))
        lo, hi = int(rows.indptr[first]), int(rows.indptr[last])
        return np.unique(rows.indices[lo:hi][rows.data[lo:hi] > 0])


@dataclass(frozen=True, slots=True, eq=False, kw_only=True)
class ActionChoices(MDPShape):
    """What the product's two records share beside their rows (:class:`MDP`, and the
    interval MDP, :class:`mitld_lp.product.imdp.IntervalMDP`): the states' choices, the
    robot's action of each, the initial state, the absorbing states and what each state
    stands for.  Made by keyword only (the fields of a record built on it follow these).

    Attributes:
        row_groups: ``(n_states + 1,)`` int64; choices of state ``s`` are the rows
            ``row_groups[s]:row_groups[s+1]``.
        choice_actions: ``(n_choices,)`` int32 index into ``action_names`` (``ABSORB`` for
            the self-loop of an absorbing state).
        action_names: the robot's action names.
        initial: index of the initial state.
        target, sink, truncated: ``(n_states,)`` bool masks, pairwise disjoint.
        states: per state, the record it stands for (for the product: a
            :class:`mitld_lp.product.ProductState`), so that answers map back.
    """

    row_groups: np.ndarray
    choice_actions: np.ndarray
    action_names: tuple[str, ...]
    initial: int
    target: np.ndarray
    sink: np.ndarray
    truncated: np.ndarray
    states: Sequence[Hashable]

    def action_name(self, choice: int) -> str:
        a = int(self.choice_actions[choice])
        return "absorb" if a == ABSORB else self.action_names[a]

    def choice_fields(self) -> dict[str, Any]:
        """These fields by name, to make another record over the same choices."""
        return {f.name: getattr(self, f.name) for f in fields(ActionChoices)}


@dataclass(frozen=True, slots=True, eq=False, kw_only=True)
class MDP(ActionChoices):
    """A finite MDP with a reachability objective: its choices (:class:`ActionChoices`)
    and their rows.

    Attributes:
        matrix: ``(n_choices, n_states)`` CSR array of transition probabilities.
    """

    matrix: sp.csr_array


def absorbing_states(mdp: MDP) -> np.ndarray:
    """``(n_states,)`` bool: states whose only choice is an ``ABSORB`` self-loop.

    Read from the ``ABSORB`` choices themselves (a handful: the target, sink and
    truncated states' loops), their states found by :meth:`MDPShape.state_of`, not from
    per-state arrays of every state's choice count and first action (an int64 and an
    int32 a state: on QVBS csma 4-2 they were the lifted policy's memory peak)."""
    out = np.zeros(mdp.n_states, dtype=bool)
    actions = np.asarray(mdp.choice_actions)
    loops = np.flatnonzero(actions == ABSORB)
    if loops.size:
        states = mdp.state_of(loops)
        groups = mdp.row_groups
        alone = (groups[states + 1] - groups[states]) == 1
        out[states[alone]] = True
    return out


def as_state_mask(mdp: MDP, mask: np.ndarray, name: str) -> np.ndarray:
    """``mask`` checked to be a bool array with one entry per state (else ValueError)."""
    mask = np.asarray(mask)
    if mask.dtype != np.bool_ or mask.shape != (mdp.n_states,):
        raise ValueError(
            f"{name}: expected a bool mask of shape ({mdp.n_states},), "
            f"got dtype {mask.dtype} and shape {mask.shape}"
        )
    return mask
