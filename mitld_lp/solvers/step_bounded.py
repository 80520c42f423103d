"""Step-bounded expected rewards (``C<=k``, ``I=k``) past the exact budget: the same
backward induction as :mod:`mitld_lp.exact.horizon`, in floating point with every
step's value bounded below and above (a certified bracket, not an estimate).

Two vectors ``lo <= v_j <= hi`` are carried through the ``k`` steps.  A choice's
expectation ``sum_t P_c(t) v(t)`` is bounded by the float row sum of the stored
probabilities (each the double nearest the exact rational, so within ``u = 2^-53`` of it)
times the factors of :func:`mitld_lp.solvers.rounding.rounding` (the sum's rounding
error, ``gamma_n``, and the probabilities' allowance; ``lo``, ``hi >= 0``); the
reward, bounded by the doubles below and above it, is added and the sum moved one float
outward; the optimum over a state's choices of bounds is a bound of the optimum.  So
``lo_k <= v_k <= hi_k`` at every state, by induction on the steps.

The work, ``k`` times the transitions and choices, is checked against
:data:`mitld_lp.defaults.HORIZON_MAX_WORK` before it starts.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from mitld_lp import defaults
from mitld_lp.solvers.rounding import UNIT, above, below, float_down, float_up, rounding
from mitld_lp.util.stops import ExactTooLarge, TimeUp

if TYPE_CHECKING:
    from mitld_lp.worlds.prism_rewards import RewardMDP

__all__ = ["check_horizon", "horizon_bracket"]


def check_horizon(model: RewardMDP, steps: int,
                  budget: int = defaults.EXACT_MAX_TRANSITIONS,
                  setting: str = "EXACT_MAX_TRANSITIONS", what: str = "answered exactly"
                  ) -> None:
    """:class:`ExactTooLarge` when ``steps`` times the model's transitions and choices
    passes ``budget`` (the work of the backward induction, before it starts; ``setting``
    names the budget in :mod:`mitld_lp.defaults`, ``what`` what it allows)."""
    work = steps * (int(model.indices.size) + int(model.groups[-1]))
    if work > budget:
        raise ExactTooLarge(
            f"step-bounded reward: {steps:,} steps x {int(model.indices.size):,} "
            f"transitions and {int(model.groups[-1]):,} choices = {work:,} updates, more "
            f"than the {budget:,} {what} (mitld_lp.defaults.{setting})")


def horizon_bracket(model: RewardMDP, kind: str, steps: int, sense: str, *,
                    time_limit: float | None = None,
                    budget: int = defaults.HORIZON_MAX_WORK) -> tuple[float, float]:
    """``(lower, upper)`` around the optimum at the initial state of ``C<=steps``
    (``kind`` "cumulative") or ``I=steps`` ("instantaneous"), ``sense`` "min" or "max"
    (module docs).  Raises :class:`~mitld_lp.exact.errors.ExactTooLarge` past
    ``budget``, :class:`TimeUp` past ``time_limit`` seconds."""
    if sense not in ("min", "max") or kind not in ("cumulative", "instantaneous"):
        raise ValueError(f"kind {kind!r} / sense {sense!r}")
    check_horizon(model, steps, budget, "HORIZON_MAX_WORK", "of the floating-point bracket")
    deadline = time.perf_counter() + (float("inf") if time_limit is None else time_limit)
    n, m = model.n_states, int(model.groups[-1])
    matrix = sp.csr_array((np.array([float(p) for p in model.probabilities]),
                           model.indices, model.indptr), shape=(m, n))
    bounds = rounding(matrix, 2.0 * UNIT)  # each double within u of its rational
    rows = np.arange(m)
    if kind == "cumulative":
        r_lo = np.array([float_down(r) for r in model.rewards])
        r_hi = np.array([float_up(r) for r in model.rewards])
        lo, hi = np.zeros(n), np.zeros(n)
    else:
        r_lo = r_hi = np.zeros(m)
        state = model.state_rewards or (0,) * n
        lo = np.array([float_down(r) for r in state], dtype=float)
        hi = np.array([float_up(r) for r in state], dtype=float)
    starts = model.groups[:-1]
    pick = np.maximum.reduceat if sense == "max" else np.minimum.reduceat
    for _ in range(steps):
        if time.perf_counter() > deadline:
            raise TimeUp
        q_lo = np.nextafter(r_lo + below(bounds, rows, matrix @ lo), -np.inf)
        q_hi = np.nextafter(r_hi + above(bounds, rows, matrix @ hi), np.inf)
        lo, hi = np.maximum(pick(q_lo, starts), 0.0), pick(q_hi, starts)
    return float(lo[model.initial]), float(hi[model.initial])
