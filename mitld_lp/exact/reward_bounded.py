"""Reward-bounded reachability, exactly: ``Pmax=? [left U{"r"}<=B right]`` on a
:class:`~mitld_lp.worlds.prism_rewards.RewardMDP` with integer rewards, answered by
unfolding the collected reward into the states.

The unfolded MDP's states are ``(s, a)``: state ``s`` with reward ``a`` in ``0..B``
collected so far, from ``(initial, 0)``; a ``right`` state is the target (absorbing),
a state where neither ``left`` nor ``right`` holds is dead (absorbing, never the
target); elsewhere choice ``c`` (reward ``r(c)``) leads to ``(t, a + r(c))`` with its
probabilities while ``a + r(c) <= B``, and to one absorbing over-budget state when the
reward passes ``B``.  A path of the unfolding reaches the target exactly when the
original path satisfies the reward-bounded until (the reward counted is the choices'
before ``right``, as Storm counts it), and the schedulers of the unfolding are the
original model's schedulers that also see the reward collected, which is all an optimal
one needs; so ``Pmax`` (``Pmin``) of reaching the target on the unfolding is the answer,
found in rationals by :func:`mitld_lp.exact.solve.solve_exact` (policy iteration, the
optimum exactly).

The size is bounded before the work by the states and the transitions times ``B + 1``;
where that bound passes the world's ``max_states`` or
:data:`mitld_lp.defaults.EXACT_MAX_TRANSITIONS`, the unfolding (usually far smaller:
QVBS's firewire, 4,093 states and a bound of 200, unfolds to 78,887 states, not
823,000) is explored under those budgets and stops the moment it passes one
(:class:`ExactTooLarge` naming the count and the bound).
"""

from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp import defaults
from mitld_lp.exact.errors import ExactError, ExactTooLarge
from mitld_lp.exact.reward import to_fraction
from mitld_lp.worlds.prism_rewards import RewardMDP

__all__ = ["BoundedAnswer", "solve_reward_bounded", "unfold"]

log = logging.getLogger("mitld_lp.exact")


@dataclass(frozen=True, slots=True)
class BoundedAnswer:
    """The optimum at the initial state (``value``, a :class:`Fraction`) and the size of
    the unfolded MDP it was found on (``states``, ``transitions``)."""

    value: Fraction
    states: int
    transitions: int


def _integer_rewards(model: RewardMDP, reward: str) -> list[int]:
    rewards = [to_fraction(r) for r in model.rewards]
    bad = next((r for r in rewards if r.denominator != 1 or r < 0), None)
    if bad is not None:
        raise ExactError(f"reward structure \"{reward}\": a reward {bad} that is not a "
                         "non-negative integer; a reward bound is unfolded over integer "
                         "rewards")
    return [int(r) for r in rewards]


def unfold(model: RewardMDP, bound: int, reward: str, *,
           max_states: int = defaults.MAX_STATES) -> tuple[Any, list[Any]]:
    """The unfolded :class:`mitld_lp.mdp.MDP` (module docs) and its exact probabilities
    (one python-flint ``fmpq`` per entry of its matrix)."""
    from flint import fmpq

    from mitld_lp.mdp import MDP

    states_guess = model.n_states * (bound + 1) + 1
    transitions_guess = int(model.indices.size) * (bound + 1)
    if states_guess > max_states or transitions_guess > defaults.EXACT_MAX_TRANSITIONS:
        log.info("reward bound %d: the unfolding may take %d states and %d transitions; "
                 "explored under the budgets", bound, states_guess, transitions_guess)

    def too_large(what: str, count: int, guess: int, budget: str) -> ExactTooLarge:
        return ExactTooLarge(
            f"reward bound {bound}: unfolding the {bound + 1:,} rewards 0..{bound} into "
            f"the {model.n_states:,} states passed {count:,} {what} (it may take "
            f"{guess:,}), more than {budget}")

    rewards = _integer_rewards(model, reward)
    p = [fmpq(to_fraction(x).numerator, to_fraction(x).denominator)
         for x in model.probabilities]
    groups, indptr, indices = (model.groups.tolist(), model.indptr.tolist(),
                               model.indices.tolist())
    target, left = model.target.tolist(), (None if model.left is None
                                           else model.left.tolist())
    over = 0  # the over-budget state
    index: dict[tuple[int, int], int] = {(-1, -1): over}
    keys: list[tuple[int, int]] = [(-1, -1)]

    def state(key: tuple[int, int]) -> int:
        at = index.get(key)
        if at is None:
            at = index[key] = len(keys)
            keys.append(key)
            queue.append(key)
        return at

    queue: deque[tuple[int, int]] = deque()
    initial = state((model.initial, 0))
    row_groups, cols, values, rows_ptr = [0], [], [], [0]

    def loop(at: int) -> None:
        cols.append(at)
        values.append(fmpq(1))
        rows_ptr.append(len(cols))
        row_groups.append(len(rows_ptr) - 1)

    loop(over)
    while queue:
        if len(keys) > max_states:
            raise too_large("states", len(keys), states_guess,
                            f"max_states = {max_states:,} (--max-world-states)")
        if len(cols) > defaults.EXACT_MAX_TRANSITIONS:
            raise too_large("transitions", len(cols), transitions_guess,
                            f"the {defaults.EXACT_MAX_TRANSITIONS:,} answered exactly "
                            "(mitld_lp.defaults.EXACT_MAX_TRANSITIONS)")
        s, a = queue.popleft()
        at = index[(s, a)]
        if target[s] or (left is not None and not left[s]):
            loop(at)
            continue
        for c in range(groups[s], groups[s + 1]):
            b = a + rewards[c]
            if b > bound:
                cols.append(over)
                values.append(fmpq(1))
            else:
                for e in range(indptr[c], indptr[c + 1]):
                    cols.append(state((indices[e], b)))
                    values.append(p[e])
            rows_ptr.append(len(cols))
        row_groups.append(len(rows_ptr) - 1)
    n = len(keys)
    matrix = sp.csr_array((np.array([float(Fraction(int(v.p), int(v.q))) for v in values]),
                           np.asarray(cols, dtype=np.int64),
                           np.asarray(rows_ptr, dtype=np.int64)),
                          shape=(len(rows_ptr) - 1, n))
    goal = np.array([k[0] >= 0 and target[k[0]] for k in keys], dtype=bool)
    mdp = MDP(row_groups=np.asarray(row_groups, dtype=np.int64), matrix=matrix,
              choice_actions=np.zeros(len(rows_ptr) - 1, dtype=np.int32),
              action_names=("choice",), initial=initial, target=goal,
              sink=np.zeros(n, dtype=bool), truncated=np.zeros(n, dtype=bool),
              states=keys)
    return mdp, values


def solve_reward_bounded(model: RewardMDP, posed: Any, *,
                         max_states: int = defaults.MAX_STATES) -> BoundedAnswer:
    """``posed`` (a :class:`mitld_lp.worlds.reward_bounded.RewardBounded`) on its built
    ``model``: the optimum in rationals (module docs)."""
    try:
        import flint  # noqa: F401
    except ImportError:
        raise ExactError("a reward-bounded probability is computed in rational arithmetic "
                         "with python-flint: pip install 'mitld_lp[exact]'") from None
    from mitld_lp.exact.solve import solve_exact

    mdp, values = unfold(model, posed.bound, posed.reward, max_states=max_states)
    start = np.asarray(mdp.row_groups[:-1], dtype=np.int64)
    solution = solve_exact(mdp, values, mdp.target, posed.query.objective, start,
                           max_block=defaults.EXACT_MAX_BLOCK)
    return BoundedAnswer(value=to_fraction(solution.values[mdp.initial]),
                         states=mdp.n_states, transitions=len(values))
