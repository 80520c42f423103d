"""The numba kernels of the step-bounded reachability bracket (imported only through
:mod:`mitld_lp.solvers.horizon`; compiled once, cached on disk).

:func:`reach_steps` runs steps of :func:`mitld_lp.solvers.horizon.horizon_reach`'s
backward induction over the states active at each step, both bounds in one pass over
their transitions: per choice the float sums ``sum P^ lo`` and ``sum P^ hi``, each
turned into a bound by its row's factors (:mod:`mitld_lp.solvers.rounding`: the slack
subtracted or added, the factor applied; the factors' margin covers these two float
operations), the best over the state's choices, ``lo`` kept at least 0 and ``hi`` at
most 1 (the exact values are probabilities; a choice whose successors all have the
upper bound 0 has the exact value 0, not its slack): the operations of
:func:`mitld_lp.solvers.rounding.below` / ``above`` in one loop instead of a dozen array
passes.  (``np.nextafter`` outward after them, as
:func:`mitld_lp.solvers.step_bounded.horizon_bracket` does after adding a reward, is not
needed without a reward: it doubled a step's time on resource-gathering.)
:func:`distances` is the breadth-first search that says which states are active.
"""

from __future__ import annotations

import numpy as np

from mitld_lp.util import kernel_loader

numba = kernel_loader.lazy_numba(globals())

__all__ = ["distances", "reach_steps"]


@numba.njit(cache=True, nogil=True)
def distances(n, starts, expand, choices, branches, targets, backward):  # pragma: no cover
    """Breadth-first steps from ``starts`` over the world's moves (``backward``: against
    them), -1 where never reached; only states with ``expand`` set are moved from
    (forward) or moved to (backward: a predecessor is counted only if it may move)."""
    dist = np.full(n, -1, dtype=np.int64)
    queue = np.empty(n, dtype=np.int64)
    head, tail = 0, 0
    for s in starts:
        if dist[s] < 0:
            dist[s] = 0
            queue[tail] = s
            tail += 1
    if backward:  # the predecessor lists, state to state
        deg = np.zeros(n + 1, dtype=np.int64)
        for s in range(n):
            for e in range(branches[choices[s]], branches[choices[s + 1]]):
                deg[targets[e] + 1] += 1
        for s in range(n):
            deg[s + 1] += deg[s]
        fill = deg[:-1].copy()
        pred = np.empty(deg[n], dtype=np.int64)
        for s in range(n):
            for e in range(branches[choices[s]], branches[choices[s + 1]]):
                t = targets[e]
                pred[fill[t]] = s
                fill[t] += 1
        while head < tail:
            t = queue[head]
            head += 1
            for i in range(deg[t], deg[t + 1]):
                s = pred[i]
                if expand[s] and dist[s] < 0:
                    dist[s] = dist[t] + 1
                    queue[tail] = s
                    tail += 1
        return dist
    while head < tail:
        s = queue[head]
        head += 1
        if not expand[s]:
            continue
        for e in range(branches[choices[s]], branches[choices[s + 1]]):
            t = targets[e]
            if dist[t] < 0:
                dist[t] = dist[s] + 1
                queue[tail] = t
                tail += 1
    return dist


@numba.njit(cache=True, nogil=True)
def reach_steps(first, last, steps, order, ends, ahead, choices, branches, targets, probs,
                count, low_of, high_of, slack_of, lo, hi, lo2, hi2, minimise, multi,
                picks, offsets):  # pragma: no cover - compiled
    """Steps ``first`` to ``last - 1`` of ``steps`` (step ``j`` makes ``v_{j+1}`` from
    ``v_j``): the states of ``order[:ends[j]]`` (undecided states by their backward
    distance to the goal: those that can reach it within ``j + 1`` steps) whose forward
    distance ``ahead`` from the initial state is at most ``steps - j - 1`` (the states
    ``v_{j+1}`` is read at); every other state keeps its value, which is never read
    stale (:mod:`mitld_lp.solvers.horizon`).  The pairs (``lo``, ``hi``) and (``lo2``,
    ``hi2``) swap each step.  When ``picks`` has entries, each step's active states with
    ``multi`` set write, in order from ``offsets[j]``, the local index of the choice best
    for the bound the policy is read from (``lo`` for a maximum, ``hi`` for a minimum;
    the first such choice)."""
    keep = picks.size > 0
    for j in range(first, last):
        w = offsets[j] if keep else 0
        for k in range(ends[j]):
            s = order[k]
            if ahead[s] > steps - j - 1:
                continue
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
                a = (a - slack_of[n]) * low_of[n]
                if b == 0.0:  # exactly 0 if every successor's bound is (not underflow)
                    for e in range(branches[c], branches[c + 1]):
                        if hi[targets[e]] != 0.0:
                            b = slack_of[n]
                            break
                    b *= high_of[n]
                else:
                    b = (b + slack_of[n]) * high_of[n]
                if not minimise:
                    if a > best_lo:
                        best_lo = a
                        pick = c - c0
                    best_hi = max(b, best_hi)
                else:
                    if b < best_hi:
                        best_hi = b
                        pick = c - c0
                    best_lo = min(a, best_lo)
            lo2[s] = max(best_lo, 0.0)
            hi2[s] = min(best_hi, 1.0)
            if keep and multi[s]:
                picks[w] = pick
                w += 1
        lo, lo2 = lo2, lo
        hi, hi2 = hi2, hi
    return 0
