"""The prob-0 / prob-1 analyses of an MDP and the reduction every solver works on.

Every solver of this package (the occupancy LP, interval iteration, the topological
order of both) and the controller's *hopeless* set start from the same preprocessing:
remove the target and prob-0 states, collapse the maximal end components of the rest
(for a maximum; for a minimum the prob-0 states are ``Prob0E`` and no end component is
left to collapse).
:func:`reduce` does it once and returns a :class:`Quotient` that maps answers back;
``synthesize`` builds one per model and hands it to every solver.

All analyses work on the *support* graph (which transitions have positive probability),
never on the probabilities themselves, so they are exact.  The graph routines and the
:class:`Quotient` record live below this module (:mod:`mitld_lp.solvers.graph`,
:mod:`mitld_lp.solvers.reduced`) and are re-exported here.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from mitld_lp.mdp import MDP, absorbing_states, as_state_mask
from mitld_lp.solvers.analysis import ATTRACTOR_STRATEGY, SureStrategy, analyse
from mitld_lp.solvers.analysis_staying import recorded_staying
from mitld_lp.solvers.graph import (
    EndComponents,
    Sense,
    attractor,
    backward_reachable,
    edges,
    maximal_end_components,
    segmented_argmax,
    toward,
)
from mitld_lp.solvers.reduced import Qualitative, Quotient, greedy_choices
from mitld_lp.solvers.result import read_only
from mitld_lp.solvers.rows import first_choice_without, gather_ranges, row_entries
from mitld_lp.util import kernel_loader
from mitld_lp.util.arrays import SLICE_STATES, index_dtype

__all__ = [
    "EndComponents",
    "Qualitative",
    "Quotient",
    "Sense",
    "backward_reachable",
    "first_staying",
    "greedy_choices",
    "lift_policy",
    "maximal_end_components",
    "prob0_max",
    "prob0_min",
    "prob1_max",
    "prob1_min",
    "quotient_for",
    "reduce",
    "segmented_argmax",
    "staying_choices",
]


def prob0_max(mdp: MDP, target: np.ndarray) -> np.ndarray:
    """States from which *every* policy reaches ``target`` with probability 0.

    ``Pmax(s |= F target) = 0`` iff no path of the support graph leads from ``s`` to a
    target state (the complement of the backward-reachable set of ``target``).
    """
    target = as_state_mask(mdp, target, "target")
    e = edges(mdp)
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
    e = edges(mdp)
    inside = backward_reachable(n, e.source, e.succ, target)  # = not prob0
    while True:
        leaves = np.zeros(mdp.n_choices, dtype=bool)
        leaves[e.choice[~inside[e.succ]]] = True
        keep = ~leaves[e.choice]
        nxt = backward_reachable(n, e.source[keep], e.succ[keep], target)
        if np.array_equal(nxt, inside):
            return inside
        inside = nxt


def prob0_min(mdp: MDP, target: np.ndarray) -> np.ndarray:
    """States from which *some* policy reaches ``target`` with probability 0
    (``Prob0E``): the complement of the states from which every choice, step after
    step, keeps a positive probability of reaching it
    (:func:`~mitld_lp.solvers.graph.attractor`)."""
    target = as_state_mask(mdp, target, "target")
    return ~attractor(sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups), target)


def prob1_min(mdp: MDP, target: np.ndarray) -> np.ndarray:
    """States from which *every* policy reaches ``target`` with probability 1
    (``Prob1A``): those with no path, before the target, to a state of
    :func:`prob0_min` (from there some policy avoids the target for ever; conversely a
    policy that avoids it with positive probability ends, almost surely, in states
    that avoid it for ever)."""
    target = as_state_mask(mdp, target, "target")
    e = edges(mdp)
    keep = ~target[e.source]
    return ~backward_reachable(mdp.n_states, e.source[keep], e.succ[keep],
                               prob0_min(mdp, target))


def reduce(mdp: MDP, target: np.ndarray, *, sense: Sense = Sense.MAX) -> Quotient:
    """Remove target and prob-0 states, then collapse the MECs of the rest.

    See :class:`Quotient`.  A choice internal to a MEC is dropped (it only moves inside
    the MEC); every other choice of a maybe state is kept, with its transitions into a
    MEC redirected to the MEC's reduced state (so a choice may keep a self-loop of
    probability < 1 on its collapsed MEC).  For ``sense=Sense.MIN`` the prob-0 states
    are :func:`prob0_min`'s and no end component remains to collapse.  One model's
    :func:`mitld_lp.solvers.analysis.analyse`, its states of value 1 kept (the
    record as documented; the plain route's analysis removes them).
    """
    return analyse(mdp, as_state_mask(mdp, target, "target"), sense=sense,
                   without_one=False)[0]


def quotient_for(mdp: MDP, target: np.ndarray, quotient: Quotient | None,
                 sense: Sense = Sense.MAX) -> Quotient:
    """``quotient`` if given (checked to be the reduction for ``target`` in ``sense``),
    else ``reduce(mdp, target, sense=sense)``: how every solver takes the caller's
    reduction."""
    if quotient is None:
        return reduce(mdp, target, sense=sense)
    target = as_state_mask(mdp, target, "target")
    if not np.array_equal(quotient.target, target):
        raise ValueError("quotient: it was reduced for another target than the one given")
    if quotient.sense is not Sense(sense):
        raise ValueError(f"quotient: it was reduced for a {quotient.sense}imum, not the "
                         f"{Sense(sense)}imum asked for")
    return quotient


def _outside(mdp: MDP, quotient: Quotient, policy: np.ndarray) -> None:
    """:func:`lift_policy`'s choices of the states the quotient removed, written into
    ``policy`` (``(n_states,)`` int64; every other state gets its first choice, which
    the lift overwrites).  Made again for each policy lifted, in place and a slice of
    states at a time: no per-state array is kept for the quotient's life, nor made
    beside ``policy`` (the first-choice copy, the prob-0 states' indices and the
    int32 copy kept in ``quotient.shared`` were 9 bytes a transition of QVBS csma 4-2's
    LP stage, at its peak); only a maximum's searched attractor strategy
    (:func:`_almost_surely`, where the analysis recorded none) is kept there, as the
    states and choices it covers."""
    policy[:] = mdp.row_groups[:-1]
    stay = _staying(quotient)
    if stay is not None:  # the analysis's record: the same choices, no search
        policy[stay.states] = stay.choices
    elif quotient.sense is Sense.MIN and quotient.prob0.any():
        # only the prob-0 states with a second choice are searched: a state's one
        # choice is its first (QVBS csma 4-2: 28,447 of 367,456, where every prob-0
        # state's rows were read, three quarters of its LP stage's CPU)
        zero = np.asarray(quotient.prob0)
        groups = np.asarray(mdp.row_groups)
        for lo in range(0, policy.size, SLICE_STATES):
            hi = min(lo + SLICE_STATES, policy.size)
            many = np.flatnonzero(zero[lo:hi] & (groups[lo + 1:hi + 1] - groups[lo:hi] > 1))
            if many.size:
                many += lo
                policy[many] = staying_choices(mdp, zero, many)
    played = _sure_played(mdp, quotient)
    if played is not None:
        policy[played.states] = played.choices
    del played
    policy[quotient.target] = -1
    policy[absorbing_states(mdp)] = -1


def _staying(quotient: Quotient) -> SureStrategy | None:
    """A minimum's staying choices on its prob-0 states of several choices, as the
    analysis recorded them from the attractor that found those states
    (:mod:`~mitld_lp.solvers.analysis_staying`: :func:`first_staying`'s integers);
    None for a maximum or a quotient built otherwise (the lift then searches)."""
    if quotient.sense is not Sense.MIN:
        return None
    return recorded_staying(quotient.shared, quotient.prob0)


def _sure_played(mdp: MDP, quotient: Quotient) -> SureStrategy | None:
    """A maximum's removed value-1 states and the choices they play, toward the target
    (:func:`_recorded`'s, else :func:`_searched`'s); None for a minimum or where none."""
    if quotient.sense is not Sense.MAX:
        return None
    sure = np.asarray(quotient.qualitative.one) & (quotient.state_map < 0) & ~quotient.target
    if not sure.any():
        return None
    played = _recorded(quotient, sure)
    return _searched(mdp, quotient, sure) if played is None else played


def _searched(mdp: MDP, quotient: Quotient, sure: np.ndarray) -> SureStrategy:
    """:func:`_almost_surely`'s strategy of the ``sure`` states, searched once per
    model and kept in ``quotient.shared`` (the iteration's policy and the LP's are
    lifted on it): the states it covers and their choices, not an array of every
    state."""
    key = ("almost surely", id(quotient.prob0), id(quotient.target))  # one per model
    kept = quotient.shared.get(key)
    if kept is not None and kept[0] is quotient.prob0 and kept[1] is quotient.target:
        return kept[2]
    step = _almost_surely(mdp, sure, np.asarray(quotient.target))
    states = np.flatnonzero(sure)
    played = SureStrategy(read_only(states), read_only(step[states]))
    quotient.shared[key] = (quotient.prob0, quotient.target, played)
    return played


def first_staying(mdp: MDP, inside: np.ndarray, lo: int = 0, hi: int | None = None
                  ) -> np.ndarray:
    """Per state ``lo .. hi - 1``, its first choice whose every successor of positive
    probability lies ``inside`` (``(n_states,)`` bool), else its first choice; in
    :func:`~mitld_lp.util.arrays.index_dtype` of the choices' count.

    A minimum's removed states of value 0 (``Prob0E``) play it in the lifted policy:
    one such choice exists there, and staying avoids the target for ever.  A state of
    one choice has it for both: only the states with more choices are searched
    (:func:`staying_choices`), :data:`SLICE_STATES` states at a time."""
    groups = np.asarray(mdp.row_groups)
    hi = mdp.n_states if hi is None else hi
    inside = np.asarray(inside, dtype=bool)
    out = groups[lo:hi].astype(index_dtype(mdp.n_choices))
    for s0 in range(lo, hi, SLICE_STATES):
        s1 = min(s0 + SLICE_STATES, hi)
        many = np.flatnonzero(groups[s0 + 1:s1 + 1] - groups[s0:s1] > 1)
        if many.size:
            many += s0
            out[many - lo] = staying_choices(mdp, inside, many)
    return out


def staying_choices(mdp: MDP, inside: np.ndarray, states: np.ndarray) -> np.ndarray:
    """:func:`first_staying` of the ``states`` (increasing), int64: the first choice
    with no entry of positive probability outside (a stored zero is no edge), read a
    chunk of entries at a time (:func:`~mitld_lp.solvers.rows.first_choice_without`),
    or a state at a time compiled where :func:`lift_compiled` says so (the same
    integers)."""
    if lift_compiled(states.size):
        from mitld_lp.solvers.lift_kernels import first_staying

        return first_staying(mdp.row_groups, mdp.matrix, inside, states)
    m = mdp.matrix
    return first_choice_without(mdp.row_groups, m, states,
                                lambda e: ~inside[m.indices[e]] & (m.data[e] > 0))


LIFT_KERNEL_MIN_STATES = 1024
"""The fewest states :func:`staying_choices` searches compiled
(:mod:`mitld_lp.solvers.lift_kernels`), once the kernels' load is paid and its machine
code is cached (``mitld-lp warm``): never a compile in a solve."""

_LIFT_WARM: list[bool] = []  # whether the lift's kernel is cached, looked up once


def lift_compiled(n_states: int) -> bool:
    """Whether :func:`staying_choices` of ``n_states`` states runs compiled."""
    if n_states < LIFT_KERNEL_MIN_STATES or not kernel_loader.compiled_paid():
        return False
    if not _LIFT_WARM:
        _LIFT_WARM.append(kernel_loader.module_cached("mitld_lp.solvers.lift_kernels",
                                                      "first_staying_kernel"))
    return _LIFT_WARM[0]


def _lift_states_compiled(mdp: MDP, quotient: Quotient, chosen: np.ndarray) -> bool:
    """Whether :func:`lift_policy` runs as one compiled pass over the states
    (:func:`_lifted_compiled`): no end component collapsed (the caller asks), a product of at
    least :data:`LIFT_KERNEL_MIN_STATES` states, the kernels' load paid and this kernel
    cached, and the state map, the chosen choices and the matrix's index arrays int32
    (the signature ``warm`` compiles: no compile in a solve)."""
    if mdp.n_states < LIFT_KERNEL_MIN_STATES or not kernel_loader.compiled_paid():
        return False
    m = mdp.matrix
    if np.asarray(quotient.state_map).dtype != np.int32 or chosen.dtype != np.int32 \
            or m.indices.dtype != np.int32 or m.indptr.dtype != np.int32:
        return False
    if not _LIFT_STATES_WARM:
        _LIFT_STATES_WARM.append(kernel_loader.module_cached(
            "mitld_lp.solvers.lift_kernels", "lift_states_kernel"))
    return _LIFT_STATES_WARM[0]


_LIFT_STATES_WARM: list[bool] = []  # whether the whole lift's kernel is cached, looked up once


def _lifted_compiled(mdp: MDP, quotient: Quotient, chosen: np.ndarray) -> np.ndarray:
    """:func:`lift_policy` where no end component is collapsed, the states in one
    compiled pass (:func:`~mitld_lp.solvers.lift_kernels.lift_states`: the same
    integers as :func:`_outside` and the gather, without their passes over every
    state), then a maximum's removed value-1 states' choices (:func:`_sure_played`)."""
    from mitld_lp.solvers.lift_kernels import lift_states

    ends = absorbing_states(mdp)
    ends |= np.asarray(quotient.target)
    stay = _staying(quotient)
    policy = lift_states(np.asarray(mdp.row_groups), mdp.matrix, quotient.prob0,
                         quotient.sense is Sense.MIN and stay is None, quotient.state_map,
                         chosen, ends)
    if stay is not None:  # the analysis's record, where the kernel searched (never an end)
        keep = (quotient.state_map[stay.states] < 0) & ~ends[stay.states]
        policy[stay.states[keep]] = stay.choices[keep]
    del stay
    played = _sure_played(mdp, quotient)
    if played is not None:  # never a target's or an absorbing state's -1 (as _outside)
        keep = ~ends[played.states]
        policy[played.states[keep]] = played.choices[keep]
    return policy


def _recorded(quotient: Quotient, sure: np.ndarray) -> SureStrategy | None:
    """The strategy the analysis recorded for the ``sure`` states from the attractor
    that found them (:func:`mitld_lp.solvers.analysis._attractor_strategy`, kept in
    ``quotient.shared``), if it covers exactly these states; else None (a quotient
    built otherwise: :func:`_almost_surely` searches one)."""
    played = quotient.shared.get(ATTRACTOR_STRATEGY)
    if played is None:
        return None
    states = played.states
    if states.size != int(np.count_nonzero(sure)) or not bool(np.all(sure[states])):
        return None
    return played


def _almost_surely(mdp: MDP, sure: np.ndarray, target: np.ndarray) -> np.ndarray:
    """An attractor strategy of the ``sure`` states (value 1 for a maximum, ``Prob1E``
    less the target): per state, a choice whose whole support stays among ``sure`` and
    ``target`` and that moves, with positive probability, one step closer to the
    target along a breadth-first tree of such choices
    (:func:`~mitld_lp.solvers.graph.toward`).  The chain it makes never leaves them
    and, from every state, reaches the target with positive probability within ``n``
    steps: it reaches it almost surely (value 1, as the quotient's lift says).  ``-1``
    for the other states.  The analysis's own quotients carry such a strategy already
    (:func:`_recorded`): this search is for the others."""
    choices = gather_ranges(mdp.row_groups[:-1][sure], mdp.row_groups[1:][sure])
    local, succ, data = row_entries(sp.csr_array(mdp.matrix), choices)
    stays = sure | target
    leaves = np.zeros(choices.size, dtype=bool)
    # a stored zero is not an edge (the analysis's graph drops them too)
    leaves[local[~stays[succ] & (data > 0)]] = True
    step = toward(mdp, choices[~leaves], np.flatnonzero(target))
    if np.any(step[sure] < 0):  # pragma: no cover - Prob1E has such a tree
        raise AssertionError("a state of value 1 has no choice toward the target")
    return step


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
      the other prob-0 states get their first choice (every choice has value 0 there),
      and so do a minimum's states of value 1 the analysis removed (``Prob1A``: every
      choice reaches the target almost surely there); a maximum's removed states of
      value 1 (``Prob1E``) play an attractor strategy (the one the analysis read from
      the attractor that found them, else :func:`_almost_surely`'s): it reaches the
      target almost surely, so the controller achieves their value 1;
      for a minimum, their first choice that stays among them (``Prob0E``: one does,
      and staying avoids the target for ever).
    """
    chosen = quotient.choice_origin[np.asarray(reduced_choice, dtype=np.int64)]
    if not quotient.mecs.n_mecs and _lift_states_compiled(mdp, quotient, chosen):
        return _lifted_compiled(mdp, quotient, chosen)
    policy = np.empty(mdp.n_states, dtype=np.int64)  # int64 as promised
    _outside(mdp, quotient, policy)

    if chosen.size:  # a gather kept where plain (a removed state's -1 reads the last
        # entry and is not kept), a slice of states at a time: not the plain states'
        # indices, their reduced states and choices, three int64 arrays a state, nor one
        # gather over every state
        state_map, mec_of = quotient.state_map, quotient.mecs.mec_of
        for lo in range(0, policy.size, SLICE_STATES):
            hi = lo + SLICE_STATES
            reduced = state_map[lo:hi]
            plain = reduced >= 0
            plain &= mec_of[lo:hi] < 0
            np.copyto(policy[lo:hi], chosen[reduced], where=plain)

    mecs = quotient.mecs
    if mecs.n_mecs == 0:
        return policy
    exits = chosen[quotient.n_plain :]
    owners = mdp.state_of(exits)  # not choice_state(): an int64 a choice of the product
    policy[owners] = exits
    # each other member: a step along a breadth-first tree of the internal choices,
    # toward the exit's owner (graph.toward)
    step = toward(mdp, np.flatnonzero(mecs.internal), owners)
    members = np.flatnonzero(mecs.mec_of >= 0)
    others = np.setdiff1d(members, owners)
    if np.any(step[others] < 0):  # pragma: no cover - MECs are strongly connected
        raise AssertionError("a MEC member cannot reach its exit inside the MEC")
    policy[others] = step[others]
    return policy
