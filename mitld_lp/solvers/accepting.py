"""The target of an obligation (safety) objective: the accepting end components.

A run satisfies an obligation formula iff its automaton eventually stays in *persistent*
states (:attr:`mitld_lp.automata.dta.DTA.persistent`: accepting or safe) forever.  In a
finite MDP the maximal probability of that equals the maximal probability of reaching
the union of the maximal end components (MECs) of the sub-MDP of persistent states
(Baier & Katoen, Thm. 10.127 and Alg. 47): inside such a component a policy that plays
only its internal choices stays in it (so in persistent states) forever with
probability 1, and a run that stays in persistent states forever ends, with probability
1, in an end component of them.  So the reachability solvers (reduction, LP, interval
iteration) apply unchanged with that union as the target, and the controller keeps the
run inside by playing internal choices there.

All analyses are on the support graph only, so the union is exact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mitld_lp.mdp import MDP, absorbing_states, as_state_mask
from mitld_lp.solvers.quotient import EndComponents, maximal_end_components
from mitld_lp.solvers.result import read_only

__all__ = ["AcceptingComponents", "accepting_end_components", "keep_inside", "escapes"]


@dataclass(frozen=True, slots=True, eq=False)
class AcceptingComponents:
    """The MECs of the sub-MDP of persistent states.

    Attributes:
        union: ``(n_states,)`` bool, the states of those MECs: the reachability target.
        mecs: the MECs themselves (``mecs.internal``: the choices that stay in their MEC).
        keep: ``(n_states,)`` int64, per state of ``union`` one internal choice (the
            first in row order), ``-1`` elsewhere and at absorbing states (whose only
            choice is their self-loop).
    """

    union: np.ndarray
    mecs: EndComponents
    keep: np.ndarray


def accepting_end_components(mdp: MDP, persistent: np.ndarray) -> AcceptingComponents:
    """The union of the maximal end components inside ``persistent`` states.

    ``persistent[s]``: staying in persistent states forever from ``s`` satisfies the
    objective.  The MECs are the greatest fixpoint of :func:`maximal_end_components`
    restricted to those states and to the choices whose whole support stays inside.
    """
    persistent = as_state_mask(mdp, persistent, "persistent")
    mecs = maximal_end_components(mdp, persistent)
    union = mecs.mec_of >= 0
    keep = np.full(mdp.n_states, -1, dtype=np.int64)
    internal = np.flatnonzero(mecs.internal)
    owner = mdp.choice_state()[internal]
    # the first internal choice of each owner: ``internal`` is sorted, so np.unique's
    # first index per owner is the lowest row
    owners, first = np.unique(owner, return_index=True)
    keep[owners] = internal[first]
    keep[absorbing_states(mdp)] = -1
    return AcceptingComponents(read_only(union), mecs, read_only(keep))


def keep_inside(components: AcceptingComponents, policy: np.ndarray) -> np.ndarray:
    """``policy`` with every state of the accepting components playing its ``keep``
    choice (so that, once there, the run never leaves); unchanged elsewhere."""
    out = np.array(policy, dtype=np.int64, copy=True)
    inside = components.union
    out[inside] = components.keep[inside]
    return out


def escapes(mdp: MDP, policy: np.ndarray, region: np.ndarray) -> np.ndarray:
    """``(n_states,)`` bool: the states of ``region`` whose ``policy`` choice can move
    outside ``region`` in one step (``-1``: the state stops there; it does not escape).

    Empty for :func:`keep_inside` on the accepting components: the certificate that the
    controller cannot leave them."""
    region = as_state_mask(mdp, region, "region")
    policy = np.asarray(policy, dtype=np.int64)
    states = np.flatnonzero(region & (policy >= 0))
    out = np.zeros(mdp.n_states, dtype=bool)
    if states.size == 0:
        return out
    rows = sp.csr_array(mdp.matrix)[policy[states]]
    outside = np.asarray(rows @ (~region).astype(np.float64)).ravel()
    out[states[outside > 0]] = True
    return out
