"""The numba kernel of the step-bounded reachability bracket (imported only through
:mod:`mitld_lp.solvers.horizon`; compiled once, cached on disk).

One call runs up to ``steps`` steps of :func:`mitld_lp.solvers.horizon.horizon_reach`'s
backward induction over the world's undecided states, both bounds in one pass over the
transitions: per choice the float sums ``sum P^ lo`` and ``sum P^ hi``, each turned into
a bound by its row's factors (:mod:`mitld_lp.solvers.rounding`: the slack subtracted or
added, the factor applied, one float outward), the best over the state's choices, ``lo``
kept at least 0 and ``hi`` at most 1 (the exact values are probabilities).  The same
operations as :func:`mitld_lp.solvers.rounding.below` / ``above`` with
``np.nextafter`` outward, in one loop instead of a dozen array passes.
"""

from __future__ import annotations

import numpy as np

from mitld_lp.util import kernel_loader

numba = kernel_loader.lazy_numba(globals())

__all__ = ["reach_steps"]


@numba.njit(cache=True, nogil=True)
def reach_steps(steps, first, undecided, choices, branches, targets, probs, count,
                low_of, high_of, slack_of, lo, hi, lo2, hi2, minimise, multi_of,
                policy):  # pragma: no cover - compiled
    """Up to ``steps`` steps from ``lo``/``hi`` (the bounds after ``first`` steps), the
    two pairs of vectors swapped each step (``lo2``/``hi2`` the other pair; the states
    outside ``undecided`` hold their fixed values in both).  Row ``first + j`` of
    ``policy`` (when it has rows) takes, for each state ``s`` with ``multi_of[s] >= 0``,
    the local index of the choice that is best for the bound the policy is read from
    (``lo`` for a maximum, ``hi`` for a minimum; the first such choice).  Returns the
    steps done: fewer than ``steps`` when a step left both vectors unchanged (a fixed
    point of the rounded operator, so every later step gives the same; its row of
    ``policy`` is written), the result then in the pair the last step wrote; the caller
    reads which pair from the parity."""
    keep = policy.shape[0] > 0
    for j in range(steps):
        changed = False
        for k in range(undecided.size):
            s = undecided[k]
            best_lo = -1.0 if not minimise else 2.0
            best_hi = -1.0 if not minimise else 2.0
            pick = 0
            c0 = choices[s]
            for c in range(c0, choices[s + 1]):
                a = 0.0
                b = 0.0
                for e in range(branches[c], branches[c + 1]):
                    t = targets[e]
                    p = probs[e]
                    a += p * lo[t]
                    b += p * hi[t]
                n = count[c]
                a = np.nextafter((a - slack_of[n]) * low_of[n], -np.inf)
                b = np.nextafter((b + slack_of[n]) * high_of[n], np.inf)
                if not minimise:
                    if a > best_lo:
                        best_lo = a
                        pick = c - c0
                    if b > best_hi:
                        best_hi = b
                else:
                    if b < best_hi:
                        best_hi = b
                        pick = c - c0
                    if a < best_lo:
                        best_lo = a
            if best_lo < 0.0:
                best_lo = 0.0
            if best_hi > 1.0:
                best_hi = 1.0
            if best_lo != lo[s] or best_hi != hi[s]:
                changed = True
            lo2[s] = best_lo
            hi2[s] = best_hi
            if keep and multi_of[s] >= 0:
                policy[first + j, multi_of[s]] = pick
        lo, lo2 = lo2, lo
        hi, hi2 = hi2, hi
        if not changed:
            return j + 1
    return steps
