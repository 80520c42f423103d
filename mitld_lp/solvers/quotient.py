"""The support-graph analyses of an MDP and the reduction every solver works on.

Every solver of this package (the occupancy LP, interval iteration, the topological
order of both) and the controller's *hopeless* set start from the same preprocessing:
remove the target and prob-0 states, collapse the maximal end components of the rest.
:func:`reduce` does it once and returns a :class:`Quotient` that maps answers back;
``synthesize`` builds one per model and hands it to every solver.

All analyses work on the *support* graph (which transitions have positive probability),
never on the probabilities themselves, so they are exact.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from mitld_lp.mdp import MDP, absorbing_states, as_state_mask
from mitld_lp.solvers.result import read_only

if TYPE_CHECKING:
    from mitld_lp.solvers.topological import Blocks

__all__ = [
    "EndComponents",
    "Quotient",
    "backward_reachable",
    "greedy_choices",
    "lift_policy",
    "maximal_end_components",
    "prob0_max",
    "prob1_max",
    "quotient_for",
    "reduce",
    "segmented_argmax",
]


@dataclass(frozen=True, slots=True)
class _Edges:
    """The positive entries of ``mdp.matrix`` as parallel arrays (one per transition)."""

    choice: np.ndarray  # the choice (row) of the transition
    source: np.ndarray  # the state owning that choice
    succ: np.ndarray  # the successor state (column)
    prob: np.ndarray  # the probability, > 0


def _edges(mdp: MDP) -> _Edges:
    coo = sp.coo_array(mdp.matrix)
    keep = coo.data > 0
    choice = np.asarray(coo.row[keep], dtype=np.int64)
    succ = np.asarray(coo.col[keep], dtype=np.int64)
    return _Edges(choice, mdp.choice_state()[choice], succ, np.asarray(coo.data[keep]))


def backward_reachable(
    n: int, source: np.ndarray, succ: np.ndarray, seeds: np.ndarray
) -> np.ndarray:
    """States with a path (along the edges ``source -> succ``) to a ``seeds`` state.

    One breadth-first search on the reversed graph from a virtual node ``n`` that points
    at every seed; the seeds themselves are included.
    """
    seed_idx = np.flatnonzero(seeds)
    if seed_idx.size == 0:
        return np.zeros(n, dtype=bool)
    index = np.int32 if n < np.iinfo(np.int32).max else np.int64  # 4 bytes an edge if it can
    rows = np.concatenate([succ, np.full(seed_idx.size, n)], dtype=index)
    cols = np.concatenate([source, seed_idx], dtype=index)
    graph = sp.csr_array(
        (np.ones(rows.size, dtype=np.float64), (rows, cols)), shape=(n + 1, n + 1)
    )
    del rows, cols
    order = csgraph.breadth_first_order(graph, n, directed=True, return_predecessors=False)
    reached = np.zeros(n + 1, dtype=bool)
    reached[np.asarray(order)] = True
    return reached[:n]


def prob0_max(mdp: MDP, target: np.ndarray) -> np.ndarray:
    """States from which *every* policy reaches ``target`` with probability 0.

    ``Pmax(s |= F target) = 0`` iff no path of the support graph leads from ``s`` to a
    target state (the complement of the backward-reachable set of ``target``).
    """
    target = as_state_mask(mdp, target, "target")
    e = _edges(mdp)
    return ~backward_reachable(mdp.n_states, e.source, e.succ, target)


def prob1_max(mdp: MDP, target: np.ndarray) -> np.ndarray:
    """States from which *some* policy reaches ``target`` with probability 1.

    The standard nested fixpoint (Baier & Katoen, Alg. 46)::

        Prob1max = nu R. mu Y. target | { s | exists choice c of s:
                                              post(c) <= R  and  post(c) & Y != {} }

    The inner least fixpoint is backward reachability of ``target`` along the choices
    whose whole support lies in ``R``; the outer loop shrinks ``R`` to that set until it
    stops changing (at most ``n_states`` rounds, usually a handful).
    """
    target = as_state_mask(mdp, target, "target")
    n = mdp.n_states
    e = _edges(mdp)
    inside = backward_reachable(n, e.source, e.succ, target)  # = not prob0
    while True:
        leaves = np.zeros(mdp.n_choices, dtype=bool)
        leaves[e.choice[~inside[e.succ]]] = True
        keep = ~leaves[e.choice]
        nxt = backward_reachable(n, e.source[keep], e.succ[keep], target)
        if np.array_equal(nxt, inside):
            return inside
        inside = nxt


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
    Each round is vectorised (one ``csgraph.connected_components`` call).
    """
    states_mask = as_state_mask(mdp, states_mask, "states_mask")
    n = mdp.n_states
    cstate = mdp.choice_state()
    e = _edges(mdp)
    alive = states_mask.copy()
    allowed = alive[cstate]
    while True:
        allowed &= alive[cstate]
        allowed[e.choice[~alive[e.succ]]] = False
        still = alive & (np.bincount(cstate[allowed], minlength=n) > 0)
        keep = allowed[e.choice]
        graph = sp.csr_matrix(
            (np.ones(int(keep.sum())), (e.source[keep], e.succ[keep])), shape=(n, n)
        )
        _, scc = csgraph.connected_components(graph, directed=True, connection="strong")
        cross = keep & (scc[e.source] != scc[e.succ])
        if not cross.any() and np.array_equal(still, alive):
            break
        allowed[e.choice[cross]] = False
        alive = still
    mec_of = np.full(n, -1, dtype=np.int64)
    if alive.any():
        _, ids = np.unique(scc[alive], return_inverse=True)
        mec_of[alive] = ids
    n_mecs = int(mec_of.max()) + 1 if alive.any() else 0
    return EndComponents(read_only(mec_of), read_only(allowed), n_mecs)


# ---------------------------------------------------------------------------------------
# The reduction shared by every solver.
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class Quotient:
    """The *maybe* part of an MDP with its maximal end components collapsed.

    Built by :func:`reduce`.  Target states (value 1) and prob-0 states (value 0) are
    removed; every MEC of the remaining *maybe* states becomes one state whose choices
    are the choices of its members that are not internal to it (they leave the MEC with
    positive probability).  The result has no end components, so every policy leaves
    the maybe states with probability 1: the occupancy LP is bounded and the upper
    sequence of interval iteration converges to the optimum.

    Reduced states are numbered: first the maybe states outside any MEC (in the order of
    the original states), then one state per MEC (``n_plain + mec id``).

    Attributes:
        target: ``(n_states,)`` bool, the original target mask (value 1).
        prob0: ``(n_states,)`` bool, states with max-reach probability 0 (value 0).
        state_map: ``(n_states,)`` int64, the reduced state of each original state,
            ``-1`` for removed (target / prob-0) ones.
        mecs: the MECs of the maybe states (ids as in ``mecs.mec_of``).
        n_plain: number of maybe states outside any MEC.
        matrix: ``(n_reduced_choices, n_reduced_states)`` CSR, probability of moving
            between reduced states (mass to target / prob-0 states is not in it).
        to_target: ``(n_reduced_choices,)`` probability of entering ``target`` in one
            step; the rest of a row's mass (``1 - to_target - row sum``) enters prob-0.
        row_groups: ``(n_reduced_states + 1,)`` the choices of each reduced state.
        choice_origin: ``(n_reduced_choices,)`` the original choice of each reduced one.
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
            and the level of each component: the order in which a policy's chain is
            evaluated (:func:`mitld_lp.solvers.iteration.evaluate_policy`).
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

    @property
    def n_states(self) -> int:
        return int(self.row_groups.shape[0] - 1)

    @property
    def n_choices(self) -> int:
        return int(self.choice_origin.shape[0])

    def choice_state(self) -> np.ndarray:
        """``(n_reduced_choices,)``: the reduced state each reduced choice belongs to."""
        return np.repeat(np.arange(self.n_states), np.diff(self.row_groups))

    def lift(self, reduced: np.ndarray) -> np.ndarray:
        """Map a per-reduced-state value vector back to the original states.

        Members of a collapsed MEC all get the MEC's value; target states get 1 and
        prob-0 states 0.
        """
        out = np.where(self.target, 1.0, 0.0)
        keep = self.state_map >= 0
        out[keep] = np.asarray(reduced, dtype=np.float64)[self.state_map[keep]]
        return out


def reduce(mdp: MDP, target: np.ndarray) -> Quotient:
    """Remove target and prob-0 states, then collapse the MECs of the rest.

    See :class:`Quotient`.  A choice internal to a MEC is dropped (it only moves inside
    the MEC); every other choice of a maybe state is kept, with its transitions into a
    MEC redirected to the MEC's reduced state (so a choice may keep a self-loop of
    probability < 1 on its collapsed MEC).  One model's
    :func:`mitld_lp.solvers.analysis.analyse`.
    """
    from mitld_lp.solvers.analysis import analyse

    return analyse(mdp, as_state_mask(mdp, target, "target"))[0]


def quotient_for(mdp: MDP, target: np.ndarray, quotient: Quotient | None) -> Quotient:
    """``quotient`` if given (checked to be the reduction for ``target``), else
    ``reduce(mdp, target)``: how every solver takes the caller's reduction."""
    if quotient is None:
        return reduce(mdp, target)
    target = as_state_mask(mdp, target, "target")
    if not np.array_equal(quotient.target, target):
        raise ValueError("quotient: it was reduced for another target than the one given")
    return quotient


def lift_policy(mdp: MDP, quotient: Quotient, reduced_choice: np.ndarray) -> np.ndarray:
    """Turn a policy of the quotient into a deterministic policy of ``mdp``.

    ``reduced_choice[r]`` is the chosen reduced choice (row of ``quotient.matrix``) of
    each reduced state.  The result holds one original choice row per state:

    * a maybe state outside any MEC takes the original of its reduced choice;
    * in a collapsed MEC, the member that owns the chosen exit takes it, and every other
      member takes an internal choice that moves one step closer to that member along a
      breadth-first tree of the MEC's internal choices.  Inside the MEC this is a Markov
      chain that reaches the exit's owner with probability 1, and the exit leaves with
      positive probability, so the policy leaves the MEC almost surely and its value is
      the quotient policy's value;
    * target states and absorbing states (a single ``ABSORB`` self-loop) get ``-1``;
      the other prob-0 states get their first choice (every choice has value 0 there).
    """
    n = mdp.n_states
    policy = np.asarray(mdp.row_groups[:-1], dtype=np.int64).copy()
    policy[quotient.target | absorbing_states(mdp)] = -1

    chosen = quotient.choice_origin[np.asarray(reduced_choice, dtype=np.int64)]
    plain = np.flatnonzero((quotient.state_map >= 0) & (quotient.mecs.mec_of < 0))
    policy[plain] = chosen[quotient.state_map[plain]]

    mecs = quotient.mecs
    if mecs.n_mecs == 0:
        return policy
    exits = chosen[quotient.n_plain :]
    cstate = mdp.choice_state()  # one entry a choice: only where there are MECs
    owners = cstate[exits]
    policy[owners] = exits
    # BFS on the reversed internal-choice graph from the owners (virtual root n).
    e = _edges(mdp)
    internal = mecs.internal[e.choice]
    src, dst = e.source[internal], e.succ[internal]
    rows = np.concatenate([dst, np.full(owners.size, n, dtype=np.int64)])
    cols = np.concatenate([src, owners])
    graph = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n + 1, n + 1))
    _, pred = csgraph.breadth_first_order(graph, n, directed=True, return_predecessors=True)
    members = np.flatnonzero(mecs.mec_of >= 0)
    others = np.setdiff1d(members, owners)
    if np.any(pred[others] < 0):  # pragma: no cover - MECs are strongly connected
        raise AssertionError("a MEC member cannot reach its exit inside the MEC")
    toward = internal & (e.succ == pred[e.source])
    # For each member, the first internal choice that has the BFS parent as a successor.
    cand_state = e.source[toward]
    cand_choice = e.choice[toward]
    ordering = np.lexsort((cand_choice, cand_state))
    cand_state, cand_choice = cand_state[ordering], cand_choice[ordering]
    first = np.unique(cand_state, return_index=True)[1]
    step = np.full(n, -1, dtype=np.int64)
    step[cand_state[first]] = cand_choice[first]
    policy[others] = step[others]
    return policy


# ---------------------------------------------------------------------------------------
# Policies from values on the quotient (used by the LP and by interval iteration).
# ---------------------------------------------------------------------------------------


def segmented_argmax(
    values: np.ndarray, row_groups: np.ndarray, *, tie: float = 0.0,
    prefer: np.ndarray | None = None,
) -> np.ndarray:
    """Per group ``row_groups[i]:row_groups[i+1]`` (all non-empty), the index of the max.

    Entries within ``tie`` of the group's maximum count as tied; among them the one with
    the largest ``prefer`` wins, then the lowest index.  Fully vectorised.
    """
    starts = np.asarray(row_groups[:-1], dtype=np.int64)
    counts = np.diff(row_groups)
    best = np.maximum.reduceat(values, starts)
    tied = values >= np.repeat(best, counts) - tie
    if prefer is not None:
        key = np.where(tied, prefer, -np.inf)
        top = np.maximum.reduceat(key, starts)
        tied &= key >= np.repeat(top, counts)
    idx = np.where(tied, np.arange(values.shape[0]), np.iinfo(np.int64).max)
    return np.minimum.reduceat(idx, starts)


def greedy_choices(q: Quotient, v: np.ndarray, *, tie: float = 1e-12) -> np.ndarray:
    """Per reduced state, the reduced choice maximising ``P(c,target) + sum P(c,s') v(s')``.

    Ties (within ``tie``) go to the choice with the larger one-step probability of
    entering the target, a cheap measure of progress.  On the quotient every policy
    leaves the maybe states almost surely (no end components remain), so a greedy
    policy on exact values is optimal and never loops forever.
    """
    scores = q.to_target + q.matrix @ v
    return segmented_argmax(scores, q.row_groups, tie=tie, prefer=q.to_target)
