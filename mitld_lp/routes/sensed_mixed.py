"""End components of information states that keep some hypotheses persistent and not
others (a task with a safety part seen through sensors, :mod:`mitld_lp.routes.sensed_solve`).

A run of information states that settles in an end component ``B`` (its states visited
for ever) keeps each hypothesis in the automaton states it shows in ``B``: the
hypotheses persistent in every state of ``B`` are accepted, the others not.  The weight
of a set of hypotheses is a martingale while the run stays in ``B`` (no mass leaves it),
so staying in ``B`` from ``y`` is worth the posterior weight at ``y`` of the hypotheses
persistent throughout ``B``.  Two models follow, each the information-state MDP with two
new absorbing states (won, lost) and a *stop* choice at some states, to won with a
credit and to lost with the rest (:func:`with_stops`):

* the upper end credits every state of a mixed end component with the weight of its own
  persistent hypotheses, at least what any end component through it is worth: the best
  stopping problem with these credits dominates every policy's value (the Snell envelope
  of a bounded reward dominates its limit), so its maximum bounds every
  observation-based policy;
* the lower end credits each state of a maximal end component ``D`` with the weight of
  the hypotheses persistent in all of ``D``; its optimal policy, a stop played as an
  internal choice of ``D`` (the controller then acts on the information state as
  always), is evaluated on its own chain (:func:`chain_value`), whose bottom components
  are credited with the weight of the hypotheses persistent in each: the exact value of
  the controller, certified as any chain's, and the answer's ``lower``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from mitld_lp.mdp import ABSORB, MDP, absorbing_states
from mitld_lp.product import Absorbing
from mitld_lp.sensing.belief import InfoState

__all__ = ["with_stops", "persistent_weight", "component_credit", "chain_value",
           "real_policy"]


def persistent_weight(state: InfoState, keep: frozenset[int],
                      among: frozenset[tuple[int, ...]] | None = None) -> float:
    """The posterior weight of ``state``'s hypotheses in a persistent automaton state
    (``keep``), only those whose times are in ``among`` if given."""
    return math.fsum(w for (times, q), w in zip(state.hypotheses, state.weights, strict=True)
                     if q in keep and (among is None or times in among))


def _kept(state: InfoState, keep: frozenset[int]) -> frozenset[tuple[int, ...]]:
    return frozenset(times for times, q in state.hypotheses if q in keep)


def component_credit(mdp: MDP, members: np.ndarray, where: np.ndarray,
                     keep: frozenset[int]) -> dict[int, float]:
    """Per state ``y`` of ``where``: the weight at ``y`` of the hypotheses persistent in
    every state of its component (``members[y]``, a component number, -1 for none)."""
    held: dict[int, frozenset[tuple[int, ...]]] = {}
    for y in np.flatnonzero(members >= 0):
        state = mdp.states[y]
        if isinstance(state, InfoState):
            m = int(members[y])
            mine = _kept(state, keep)
            held[m] = held[m] & mine if m in held else mine
    return {int(y): persistent_weight(mdp.states[y], keep, held.get(int(members[y])))
            for y in np.flatnonzero(where & (members >= 0))}


def with_stops(mdp: MDP, credit: Mapping[int, float]) -> MDP:
    """``mdp`` with two new absorbing states, won (a target) and lost (a sink), and at
    each state ``y`` of ``credit`` one more choice, last in its row group (action
    ``stop``): to won with ``credit[y]``, to lost with the rest."""
    n = mdp.n_states
    groups = np.asarray(mdp.row_groups, dtype=np.int64)
    matrix = sp.csr_array(mdp.matrix)
    stop = len(mdp.action_names)
    rows: list[sp.csr_array] = []
    actions: list[np.ndarray] = []
    sizes = np.diff(groups)
    for y in range(n):
        rows.append(sp.csr_array(matrix[groups[y]:groups[y + 1]], shape=(sizes[y], n + 2)))
        actions.append(np.asarray(mdp.choice_actions[groups[y]:groups[y + 1]]))
        if y in credit:
            c = min(max(credit[y], 0.0), 1.0)
            rows.append(sp.csr_array(([c, 1.0 - c], ([0, 0], [n, n + 1])), shape=(1, n + 2)))
            actions.append(np.array([stop], dtype=np.int32))
            sizes[y] += 1
    for k in (n, n + 1):
        rows.append(sp.csr_array(([1.0], ([0], [k])), shape=(1, n + 2)))
        actions.append(np.array([ABSORB], dtype=np.int32))
    pad = np.zeros(2, dtype=bool)
    return MDP(
        matrix=sp.csr_array(sp.vstack(rows, format="csr")),
        row_groups=np.concatenate([[0], np.cumsum(np.concatenate([sizes, [1, 1]]))]),
        choice_actions=np.concatenate(actions).astype(np.int32),
        action_names=(*mdp.action_names, "stop"), initial=mdp.initial,
        target=np.concatenate([np.asarray(mdp.target, dtype=bool), [True, False]]),
        sink=np.concatenate([np.asarray(mdp.sink, dtype=bool), [False, True]]),
        truncated=np.concatenate([np.asarray(mdp.truncated, dtype=bool), pad]),
        states=(*mdp.states, Absorbing.TARGET, Absorbing.SINK))


def real_policy(mdp: MDP, stopped: MDP, policy: np.ndarray, inside: np.ndarray
                ) -> np.ndarray:
    """A policy of :func:`with_stops`'s model ``stopped`` as a policy of ``mdp``: a
    stop played as ``inside[y]`` (an internal choice of its end component), every other
    choice as the same row of ``mdp``."""
    out = np.full(mdp.n_states, -1, dtype=np.int64)
    first, first_stopped = mdp.row_groups[:-1], stopped.row_groups[:-1][:mdp.n_states]
    for y in np.flatnonzero(np.asarray(policy[:mdp.n_states]) >= 0):
        k = int(policy[y]) - int(first_stopped[y])
        out[y] = inside[y] if k >= mdp.row_groups[y + 1] - first[y] else first[y] + k
    return out


def chain_value(mdp: MDP, policy: np.ndarray, keep: frozenset[int]) -> MDP:
    """The chain of ``policy`` on ``mdp`` as a model of one choice per state, whose
    value is the policy's probability of the task (module docs): each bottom strongly
    connected component of undecided states is replaced by its credit, to won with the
    weight of the hypotheses persistent in all of it (:func:`with_stops`' two states)."""
    n = mdp.n_states
    matrix = sp.csr_array(mdp.matrix)
    ends = absorbing_states(mdp)
    rows = np.where(ends, mdp.row_groups[:-1], policy)
    if (rows < 0).any():
        raise ValueError("chain_value: the policy leaves a state without a choice")
    chain = sp.csr_array(matrix[rows])
    _, comp = connected_components(chain, directed=True, connection="strong")
    src = np.repeat(np.arange(n), np.diff(chain.indptr))
    leaving = comp[src] != comp[chain.indices]
    bottom = np.ones(comp.max() + 1, dtype=bool)
    bottom[comp[src[leaving]]] = False
    members = np.where(bottom[comp] & ~ends, comp, -1)
    credit = component_credit(mdp, members, members >= 0, keep)
    one = MDP(matrix=chain, row_groups=np.arange(n + 1, dtype=np.int64),
              choice_actions=np.asarray(mdp.choice_actions)[rows].astype(np.int32),
              action_names=mdp.action_names, initial=mdp.initial, target=mdp.target,
              sink=mdp.sink, truncated=mdp.truncated, states=mdp.states)
    stopped = with_stops(one, credit)
    # a credited state keeps its stop alone: drop the chain's row there
    groups = np.asarray(stopped.row_groups, dtype=np.int64)
    keep_rows = np.ones(stopped.n_choices, dtype=bool)
    keep_rows[groups[:-1][list(credit)]] = False
    sizes = np.diff(groups)
    sizes[list(credit)] -= 1
    return MDP(matrix=sp.csr_array(stopped.matrix[np.flatnonzero(keep_rows)]),
               row_groups=np.concatenate([[0], np.cumsum(sizes)]),
               choice_actions=np.asarray(stopped.choice_actions)[keep_rows],
               action_names=stopped.action_names, initial=stopped.initial,
               target=stopped.target, sink=stopped.sink, truncated=stopped.truncated,
               states=stopped.states)
