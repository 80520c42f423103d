"""A sparse Markov decision process: one CSR matrix with a row per (state, action).

The rows of state ``s`` are ``row_groups[s]:row_groups[s+1]`` (its *choices*); row ``c``
of ``matrix`` is the successor distribution of choice ``c`` and sums to 1.  Every state
has at least one choice; the absorbing states (``target``, ``sink``, ``truncated``) have
exactly one, a self-loop, whose action label is ``ABSORB`` (-1).

This module holds the record only: the product builds it, the controller runs on it, the
exports write it.  The analyses of its support graph (prob-0/1 states, end components)
and the reduction every solver works on are in :mod:`mitld_lp.solvers.quotient`.

Three disjoint absorbing classes are kept apart:

* ``target``    -- the automaton accepted: the task is satisfied;
* ``sink``      -- the automaton rejected: the task can no longer be satisfied;
* ``truncated`` -- a truncated event clock ran past its truncation point.  Counting it
  as losing gives a lower bound on the optimum, as winning an upper bound.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

__all__ = ["ABSORB", "MDP", "absorbing_states", "as_state_mask"]

ABSORB = -1
"""Action label of the self-loop choice of an absorbing state."""


@dataclass(frozen=True, slots=True, eq=False)
class MDP:
    """A finite MDP with a reachability objective.

    Attributes:
        matrix: ``(n_choices, n_states)`` CSR array of transition probabilities.
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

    matrix: sp.csr_array
    row_groups: np.ndarray
    choice_actions: np.ndarray
    action_names: tuple[str, ...]
    initial: int
    target: np.ndarray
    sink: np.ndarray
    truncated: np.ndarray
    states: Sequence[Hashable]

    @property
    def n_states(self) -> int:
        return int(self.row_groups.shape[0] - 1)

    @property
    def n_choices(self) -> int:
        return int(self.row_groups[-1])

    @property
    def n_transitions(self) -> int:
        """Number of nonzero (choice, successor) entries."""
        return int(self.matrix.nnz)

    def choices(self, state: int) -> range:
        """The row indices of ``state``'s choices."""
        return range(int(self.row_groups[state]), int(self.row_groups[state + 1]))

    def choice_state(self) -> np.ndarray:
        """``(n_choices,)``: the state each choice belongs to."""
        return np.repeat(np.arange(self.n_states), np.diff(self.row_groups))

    def action_name(self, choice: int) -> str:
        a = int(self.choice_actions[choice])
        return "absorb" if a == ABSORB else self.action_names[a]


def absorbing_states(mdp: MDP) -> np.ndarray:
    """``(n_states,)`` bool: states whose only choice is an ``ABSORB`` self-loop."""
    first = np.asarray(mdp.row_groups[:-1], dtype=np.int64)
    return (np.diff(mdp.row_groups) == 1) & (np.asarray(mdp.choice_actions)[first] == ABSORB)


def as_state_mask(mdp: MDP, mask: np.ndarray, name: str) -> np.ndarray:
    """``mask`` checked to be a bool array with one entry per state (else ValueError)."""
    mask = np.asarray(mask)
    if mask.dtype != np.bool_ or mask.shape != (mdp.n_states,):
        raise ValueError(
            f"{name}: expected a bool mask of shape ({mdp.n_states},), "
            f"got dtype {mask.dtype} and shape {mask.shape}"
        )
    return mask
