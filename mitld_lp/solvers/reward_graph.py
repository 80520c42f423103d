"""The graph questions of a reward model (:class:`~mitld_lp.worlds.prism_rewards.RewardMDP`),
asked before any number: which choices keep a set (:func:`keeps_inside`), from where the
target is reached with probability 1 (:func:`almost_sure`, Prob1E/Prob1A), and a policy
that walks towards the target layer by layer (:func:`attractor_policy`).  Shared by the
exact rewards (:mod:`mitld_lp.exact.reward`) and the certified float ones
(:mod:`mitld_lp.solvers.reward`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from mitld_lp.worlds.prism_rewards import RewardMDP

__all__ = ["almost_sure", "attractor_policy", "keeps_inside"]


def keeps_inside(model: RewardMDP, inside: np.ndarray) -> np.ndarray:
    """Per choice: every successor is in ``inside``."""
    bad = ~inside[model.indices]
    per_choice = np.add.reduceat(bad.astype(np.int64), model.indptr[:-1]) if bad.size else \
        np.zeros(model.indptr.size - 1, dtype=np.int64)
    empty = np.diff(model.indptr) == 0
    per_choice[empty] = 0
    return per_choice == 0


def _reach(model: RewardMDP, seeds: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """``seeds`` and the states with a ``usable`` choice that has a successor among them,
    to the fixed point (backward search over the choice graph)."""
    owner = model.owner
    inside = seeds.copy()
    while True:
        hit = inside[model.indices]
        choice_hits = np.zeros(model.indptr.size - 1, dtype=bool)
        starts = model.indptr[:-1]
        nonempty = np.diff(model.indptr) > 0
        if hit.size:
            choice_hits[nonempty] = np.logical_or.reduceat(hit, starts[nonempty])
        grow = np.zeros_like(inside)
        grow[owner[choice_hits & usable]] = True
        new = inside | grow
        if (new == inside).all():
            return inside
        inside = new


def almost_sure(model: RewardMDP, sense: str) -> np.ndarray:
    """The states from which the target is reached with probability 1: by some scheduler
    (``sense`` "min": Prob1E, the states of finite ``Rmin``) or by every scheduler
    (``sense`` "max": Prob1A, the states of finite ``Rmax``)."""
    n = model.n_states
    target = model.target
    if sense == "min":
        keep = np.ones(n, dtype=bool)
        while True:  # the greatest set from which the target stays reachable
            usable = keeps_inside(model, keep) & ~target[model.owner]
            reach = _reach(model, target, usable) & keep
            if (reach == keep).all():
                return keep
            keep = reach
    # max: not Prob1A = can reach (avoiding the target) a state where some scheduler
    # avoids the target forever (the greatest set each of whose states has a choice
    # staying in it)
    avoid = ~target
    while True:
        stay = keeps_inside(model, avoid)
        has = np.zeros(n, dtype=bool)
        has[model.owner[stay]] = True
        new = avoid & has
        if (new == avoid).all():
            break
        avoid = new
    bad = _reach(model, avoid, ~target[model.owner])
    return ~bad


def attractor_policy(model: RewardMDP, finite: np.ndarray, useful: np.ndarray) -> np.ndarray:
    """A choice per finite non-target state that keeps ``finite`` and has a successor one
    layer closer to the target (the layers of the backward search)."""
    policy = np.full(model.n_states, -1, dtype=np.int64)
    owner = model.owner
    inside = model.target.copy()
    starts = model.indptr[:-1]
    nonempty = np.diff(model.indptr) > 0
    while True:
        hit = np.zeros(model.indptr.size - 1, dtype=bool)
        if model.indices.size:
            hit[nonempty] = np.logical_or.reduceat(inside[model.indices], starts[nonempty])
        fresh = hit & useful & ~inside[owner] & finite[owner]
        if not fresh.any():
            return policy
        chosen = np.flatnonzero(fresh)
        first = np.unique(owner[chosen], return_index=True)[1]
        states = owner[chosen[first]]
        policy[states] = chosen[first]
        inside[states] = True
