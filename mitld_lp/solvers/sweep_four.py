"""The block kernel's sweeps for two models at once (four columns: each model's lower
and upper bound), their sums in scalars (imported only by
:mod:`mitld_lp.solvers.compiled_kernels`, which calls them for ``k == 4``).

The general sweeps (``compiled_kernels.update`` and ``checked``) add each column's sum
in an array (``acc``) and keep each column's best in another; on two models (the sensed
case, every task with both truncation models, the bus family) every entry's four
products went through memory, and a store to those arrays (or to ``track``'s flags)
could alias the bounds' rows, so each state's entries were read again.  Here the sums,
the bests and the guesses' trial and failure flags are locals: the same operations in
the same order (each sum from the choice's exit reward, its entries in order; a best
replaced only by a strictly better value; a choice that never leaves worth 0; ``x /
1.0`` left out, which is ``x``), so the same bits.  The flags are read from ``track`` at
the sweep's start and written back at its end; one set mid-sweep stops its guess's
updates from the next state on, as it did."""

from __future__ import annotations

import numpy as np

from mitld_lp.util import kernel_loader

numba = kernel_loader.lazy_numba(globals())

__all__ = ["plain4", "verifying4", "watched4"]

OFF = 8  # compiled_kernels.OFF: track's header (its slots per column follow)
K = 4


@numba.njit(cache=True, nogil=True, inline="always")
def _update4(indptr, indices, data, starts, leave, exits, local, s,
             minimise):  # pragma: no cover - compiled
    """``s``'s four bounds updated (``compiled_kernels.update`` for ``k == 4``)."""
    b0 = np.inf if minimise else -np.inf
    b1 = b0
    b2 = b0
    b3 = b0
    for c in range(starts[s], starts[s + 1]):
        v0 = exits[c, 0]
        v1 = exits[c, 1]
        v2 = exits[c, 2]
        v3 = exits[c, 3]
        for e in range(indptr[c], indptr[c + 1]):
            t = indices[e]
            if t != s:
                w = data[e]
                v0 += w * local[t, 0]
                v1 += w * local[t, 1]
                v2 += w * local[t, 2]
                v3 += w * local[t, 3]
        lv = leave[c]
        if lv != 1.0:  # x / 1.0 is x: the same bits without the divides
            if lv > 0.0:
                v0 /= lv
                v1 /= lv
                v2 /= lv
                v3 /= lv
            else:
                v0 = v1 = v2 = v3 = 0.0
        if minimise:
            if v0 < b0:
                b0 = v0
            if v1 < b1:
                b1 = v1
            if v2 < b2:
                b2 = v2
            if v3 < b3:
                b3 = v3
        else:
            if v0 > b0:
                b0 = v0
            if v1 > b1:
                b1 = v1
            if v2 > b2:
                b2 = v2
            if v3 > b3:
                b3 = v3
    _keep4(local, s, b0, b1, b2, b3)


@numba.njit(cache=True, nogil=True, inline="always")
def _keep4(local, s, b0, b1, b2, b3):  # pragma: no cover - compiled
    """``compiled_kernels.keep``: each best clipped to [0, 1], a lower bound only raised,
    an upper one only lowered."""
    v = min(max(b0, 0.0), 1.0)
    if v > local[s, 0]:
        local[s, 0] = v
    v = min(max(b1, 0.0), 1.0)
    if v < local[s, 1]:
        local[s, 1] = v
    v = min(max(b2, 0.0), 1.0)
    if v > local[s, 2]:
        local[s, 2] = v
    v = min(max(b3, 0.0), 1.0)
    if v < local[s, 3]:
        local[s, 3] = v


@numba.njit(cache=True, nogil=True)
def plain4(indptr, indices, data, starts, leave, exits, local, order,
           minimise):  # pragma: no cover - compiled
    """One sweep of ``local``'s four columns through the states in ``order``."""
    for i in range(local.shape[0]):  # as compiled_kernels' sweeps: a state a place
        _update4(indptr, indices, data, starts, leave, exits, local, order[i], minimise)


@numba.njit(cache=True, nogil=True, inline="always")
def _gap(lo, hi, tol, precision, floor):  # pragma: no cover - compiled
    """A pair's gap over its threshold (``compiled_kernels.threshold`` of its lower
    bound, the same expression)."""
    return (hi - lo) / (tol if precision < 0.0 else min(tol, max(precision * lo, floor)))


@numba.njit(cache=True, nogil=True)
def watched4(indptr, indices, data, starts, leave, exits, local, order, minimise, guess,
             track, tol, precision, floor):  # pragma: no cover - compiled
    """``compiled_kernels._watched`` for four columns: each bound's change written into
    ``guess``, each column's largest change into ``track``; returns the largest gap over
    its threshold among the states swept (read as each is set: the caller uses it only
    when ``order`` holds every state once, then it is ``_over``'s maximum)."""
    m0 = track[OFF + 4 * K]
    m1 = track[OFF + 4 * K + 1]
    m2 = track[OFF + 4 * K + 2]
    m3 = track[OFF + 4 * K + 3]
    over = 0.0
    for i in range(local.shape[0]):
        s = order[i]
        a0 = local[s, 0]
        a1 = local[s, 1]
        a2 = local[s, 2]
        a3 = local[s, 3]
        _update4(indptr, indices, data, starts, leave, exits, local, s, minimise)
        lo0 = local[s, 0]
        hi0 = local[s, 1]
        lo1 = local[s, 2]
        hi1 = local[s, 3]
        d = abs(lo0 - a0)
        guess[s, 0] = d
        if d > m0:
            m0 = d
        d = abs(hi0 - a1)
        guess[s, 1] = d
        if d > m1:
            m1 = d
        d = abs(lo1 - a2)
        guess[s, 2] = d
        if d > m2:
            m2 = d
        d = abs(hi1 - a3)
        guess[s, 3] = d
        if d > m3:
            m3 = d
        r = _gap(lo0, hi0, tol, precision, floor)
        if r > over:
            over = r
        r = _gap(lo1, hi1, tol, precision, floor)
        if r > over:
            over = r
    track[OFF + 4 * K] = m0
    track[OFF + 4 * K + 1] = m1
    track[OFF + 4 * K + 2] = m2
    track[OFF + 4 * K + 3] = m3
    return over


@numba.njit(cache=True, nogil=True)
def verifying4(indptr, indices, data, starts, leave, exits, work, order, minimise,
               track):  # pragma: no cover - compiled
    """``compiled_kernels.checked`` over the states in ``order`` for four columns, on the
    packed rows: ``work[t]`` holds ``t``'s four bounds, then its four guesses (one cache
    line).  Each guess's sum is widened by a bound on its rounding error (a lower guess
    lowered, an upper one raised), a guess on trial replaced by its clipped update,
    flagged when that moved it the wrong way, out of the trial when it crossed the
    proven bound on its pair's other side."""
    on0 = track[OFF + 3 * K]  # the guesses' trials (1: on trial, 3: crossed)
    on1 = track[OFF + 3 * K + 1]
    on2 = track[OFF + 3 * K + 2]
    on3 = track[OFF + 3 * K + 3]
    bad0 = track[OFF + 5 * K]  # 1: the guess moved the wrong way in this sweep
    bad1 = track[OFF + 5 * K + 1]
    bad2 = track[OFF + 5 * K + 2]
    bad3 = track[OFF + 5 * K + 3]
    for i in range(work.shape[0]):
        s = order[i]
        b0 = np.inf if minimise else -np.inf
        b1 = b2 = b3 = g0 = g1 = g2 = g3 = b0
        for c in range(starts[s], starts[s + 1]):
            v0 = exits[c, 0]
            v1 = exits[c, 1]
            v2 = exits[c, 2]
            v3 = exits[c, 3]
            u0 = v0
            u1 = v1
            u2 = v2
            u3 = v3
            first = indptr[c]
            last = indptr[c + 1]
            for e in range(first, last):
                t = indices[e]
                if t != s:
                    w = data[e]
                    v0 += w * work[t, 0]
                    v1 += w * work[t, 1]
                    v2 += w * work[t, 2]
                    v3 += w * work[t, 3]
                    u0 += w * work[t, 4]
                    u1 += w * work[t, 5]
                    u2 += w * work[t, 6]
                    u3 += w * work[t, 7]
            lv = leave[c]
            if lv != 1.0:  # x / 1.0 is x: the same bits without the divides
                if lv > 0.0:
                    v0 /= lv
                    v1 /= lv
                    v2 /= lv
                    v3 /= lv
                    u0 /= lv
                    u1 /= lv
                    u2 /= lv
                    u3 /= lv
                else:
                    v0 = v1 = v2 = v3 = u0 = u1 = u2 = u3 = 0.0
            wide = (last - first + 8) * 2.0**-52
            u0 = u0 * (1.0 - wide)
            u1 = u1 * (1.0 + wide)
            u2 = u2 * (1.0 - wide)
            u3 = u3 * (1.0 + wide)
            if minimise:
                if v0 < b0:
                    b0 = v0
                if v1 < b1:
                    b1 = v1
                if v2 < b2:
                    b2 = v2
                if v3 < b3:
                    b3 = v3
                if u0 < g0:
                    g0 = u0
                if u1 < g1:
                    g1 = u1
                if u2 < g2:
                    g2 = u2
                if u3 < g3:
                    g3 = u3
            else:
                if v0 > b0:
                    b0 = v0
                if v1 > b1:
                    b1 = v1
                if v2 > b2:
                    b2 = v2
                if v3 > b3:
                    b3 = v3
                if u0 > g0:
                    g0 = u0
                if u1 > g1:
                    g1 = u1
                if u2 > g2:
                    g2 = u2
                if u3 > g3:
                    g3 = u3
        _keep4(work, s, b0, b1, b2, b3)
        if on0 == 1.0:
            v = min(max(g0, 0.0), 1.0)
            if v < work[s, 4]:
                bad0 = 1.0
            work[s, 4] = v
            if v > work[s, 1]:
                on0 = 3.0  # beyond the other side's proven bound
        if on1 == 1.0:
            v = min(max(g1, 0.0), 1.0)
            if v > work[s, 5]:
                bad1 = 1.0
            work[s, 5] = v
            if v < work[s, 0]:
                on1 = 3.0
        if on2 == 1.0:
            v = min(max(g2, 0.0), 1.0)
            if v < work[s, 6]:
                bad2 = 1.0
            work[s, 6] = v
            if v > work[s, 3]:
                on2 = 3.0
        if on3 == 1.0:
            v = min(max(g3, 0.0), 1.0)
            if v > work[s, 7]:
                bad3 = 1.0
            work[s, 7] = v
            if v < work[s, 2]:
                on3 = 3.0
    track[OFF + 3 * K] = on0
    track[OFF + 3 * K + 1] = on1
    track[OFF + 3 * K + 2] = on2
    track[OFF + 3 * K + 3] = on3
    track[OFF + 5 * K] = bad0
    track[OFF + 5 * K + 1] = bad1
    track[OFF + 5 * K + 2] = bad2
    track[OFF + 5 * K + 3] = bad3
