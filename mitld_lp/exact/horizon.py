"""Step-bounded expected rewards in rational arithmetic: Storm's ``R{"r"}max=? [C<=k]``
(the reward collected in the first ``k`` steps) and ``R{"r"}max=? [I=k]`` (the state
reward at step ``k``), minimised or maximised, on an MDP whose probabilities and rewards
are rationals (:class:`mitld_lp.worlds.prism_rewards.RewardMDP`).

Backward induction over the ``k`` steps, as Storm and PRISM define them:

* ``C<=k``: ``v_0 = 0``, ``v_{j+1}(s) = opt_c [ r(c) + sum_t P_c(t) v_j(t) ]`` with
  ``r(c)`` the choice's reward (its state's state reward plus its action reward);
* ``I=k``: ``v_0(s) = `` the state reward of ``s``, ``v_{j+1}(s) = opt_c sum_t P_c(t)
  v_j(t)`` (action rewards play no part);

and the answer is ``v_k`` at the initial state.  Each ``v_j`` is the optimum over every
scheduler of the ``j`` steps left (finite horizon: the Bellman recursion is the
definition), so ``v_k`` is the exact optimum; an optimal scheduler needs the steps done,
and :attr:`HorizonAnswer.policy` gives one: the choice at step ``i`` (from 0) in each
state, a maximiser (minimiser) of ``v_{k-i}``.

Every value is a python-flint ``fmpq``; the work is ``k`` times the transitions (checked
against :data:`mitld_lp.defaults.EXACT_MAX_TRANSITIONS` by :func:`check_horizon` before it
starts).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np

from mitld_lp.exact.errors import ExactError, TimeUp
from mitld_lp.exact.reward import to_fraction
from mitld_lp.solvers.step_bounded import check_horizon
from mitld_lp.worlds.prism_rewards import RewardMDP

__all__ = ["HorizonAnswer", "check_horizon", "solve_horizon"]


@dataclass(frozen=True, slots=True, eq=False)
class HorizonAnswer:
    """The optimum at the initial state (``value``, a :class:`Fraction`) and an optimal
    time-dependent policy: ``policy[i, s]`` the choice at step ``i`` in state ``s``
    (``k`` rows; none for ``k = 0``)."""

    value: Fraction
    policy: np.ndarray


def solve_horizon(model: RewardMDP, kind: str, steps: int, sense: str, *,
                  time_limit: float | None = None) -> HorizonAnswer:
    """``C<=steps`` (``kind`` "cumulative") or ``I=steps`` ("instantaneous"), ``sense``
    "min" or "max" (module docs).  Raises :class:`ExactTooLarge` past the budget
    (:func:`check_horizon`), :class:`TimeUp` past ``time_limit`` seconds."""
    if sense not in ("min", "max"):
        raise ValueError(f"sense must be 'min' or 'max', got {sense!r}")
    if kind not in ("cumulative", "instantaneous"):
        raise ValueError(f"kind must be 'cumulative' or 'instantaneous', got {kind!r}")
    if steps < 0:
        raise ValueError(f"steps must be >= 0, got {steps}")
    try:
        from flint import fmpq
    except ImportError:
        raise ExactError("a step-bounded reward is computed in rational arithmetic with "
                         "python-flint: pip install 'mitld_lp[exact]'") from None
    check_horizon(model, steps)
    deadline = time.perf_counter() + (float("inf") if time_limit is None else time_limit)

    def rational(x: Any) -> Any:
        x = to_fraction(x)
        return fmpq(x.numerator, x.denominator)

    n = model.n_states
    p = [rational(x) for x in model.probabilities]
    indptr, indices = model.indptr.tolist(), model.indices.tolist()
    groups = model.groups.tolist()
    if kind == "cumulative":
        r = [rational(x) for x in model.rewards]
        v = [fmpq(0)] * n
    else:
        r = [fmpq(0)] * int(groups[-1])
        v = [rational(x) for x in model.state_rewards] or [fmpq(0)] * n
    better = (lambda a, b: a > b) if sense == "max" else (lambda a, b: a < b)
    policy = np.zeros((steps, n), dtype=np.int64)
    for left in range(1, steps + 1):  # v has ``left - 1`` steps to go
        if time.perf_counter() > deadline:
            raise TimeUp
        new = [fmpq(0)] * n
        row = policy[steps - left]
        for s in range(n):
            best, arg = None, -1
            for c in range(groups[s], groups[s + 1]):
                q = r[c]
                for e in range(indptr[c], indptr[c + 1]):
                    q += p[e] * v[indices[e]]
                if best is None or better(q, best):
                    best, arg = q, c
            new[s] = fmpq(0) if best is None else best
            row[s] = arg
        v = new
    return HorizonAnswer(value=to_fraction(v[model.initial]), policy=policy)
