"""The block kernel's sweeps for one model (two columns: a lower and an upper bound),
their sums in scalars (imported only by :mod:`mitld_lp.solvers.compiled_kernels`,
which calls them for ``k == 2``): the same operations in the same order as before they
moved here (each sum from the choice's exit reward, its entries in order; ``x / 1.0``
left out, which is ``x``), so the same bits.

Each sweep, the verifying one too, reads each state's gap over its threshold as it
sets the state's bounds and returns the largest.  A state is set once a sweep when the
order names each once, and only a guess proven after the sweep moves a bound, so the
caller need not read the bounds a second time (``compiled_kernels._over``: a pass over
the packed rows of a verification, 32 bytes a state, 1.8 ms a sweep on QVBS
``zeroconf`` 1000-6 ``correct_min``'s block of 550,097 states) unless a guess was
proven."""

from __future__ import annotations

import numpy as np

from mitld_lp.util import kernel_loader

numba = kernel_loader.lazy_numba(globals())

__all__ = ["plain2", "verifying2", "watched2"]

OFF = 8  # compiled_kernels.OFF: track's header (its slots per column follow)


@numba.njit(cache=True, nogil=True, inline="always")
def _divide2(a, b, lv):  # pragma: no cover - compiled
    """Two sums over a choice's ``leave`` (``x / 1.0`` left out: it is ``x``; 0 where the
    choice never leaves)."""
    if lv != 1.0:
        if lv > 0.0:
            return a / lv, b / lv
        return 0.0, 0.0
    return a, b


@numba.njit(cache=True, nogil=True, inline="always")
def _pick2(a, b, best_a, best_b, minimise):  # pragma: no cover - compiled
    """Two bests, each kept or replaced by its new value."""
    if minimise:
        return min(best_a, a), min(best_b, b)
    return max(best_a, a), max(best_b, b)


@numba.njit(cache=True, nogil=True, inline="always")
def _best2(indptr, indices, data, starts, leave, exits, local, s,
           minimise):  # pragma: no cover - compiled
    """State ``s``'s best choice's sums over ``local``'s two columns (each choice's
    self-loop solved, ``x / 1.0`` left out: it is ``x``; a choice that never leaves
    worth 0); the two bests."""
    lo_best = np.inf if minimise else -np.inf
    hi_best = lo_best
    for c in range(starts[s], starts[s + 1]):
        lo = exits[c, 0]
        hi = exits[c, 1]
        for e in range(indptr[c], indptr[c + 1]):
            t = indices[e]
            if t != s:
                w = data[e]
                lo += w * local[t, 0]
                hi += w * local[t, 1]
        lo, hi = _divide2(lo, hi, leave[c])
        lo_best, hi_best = _pick2(lo, hi, lo_best, hi_best, minimise)
    return lo_best, hi_best


@numba.njit(cache=True, nogil=True, inline="always")
def _set2(x, s, lo, hi, tol, precision, floor, over):  # pragma: no cover - compiled
    """State ``s``'s bounds in ``x`` set to the bests ``lo`` and ``hi`` (clipped to [0,
    1]) where they improve them (a lower only raised, an upper only lowered); the new
    bounds and the larger of ``over`` and their gap over its threshold."""
    low = max(x[s, 0], min(max(lo, 0.0), 1.0))
    high = min(x[s, 1], min(max(hi, 0.0), 1.0))
    x[s, 0] = low
    x[s, 1] = high
    r = (high - low) / (tol if precision < 0.0 else min(tol, max(precision * low, floor)))
    return low, high, (r if r > over else over)


@numba.njit(cache=True, nogil=True)
def plain2(indptr, indices, data, starts, leave, exits, local, order, minimise,
           tol, precision, floor):  # pragma: no cover - compiled
    """One sweep of ``local``'s two columns through the states in ``order``; the
    largest gap over its threshold among the states swept, as :func:`watched2`'s."""
    over = 0.0
    for i in range(order.shape[0]):
        s = order[i]
        lo, hi = _best2(indptr, indices, data, starts, leave, exits, local, s, minimise)
        _, _, over = _set2(local, s, lo, hi, tol, precision, floor, over)
    return over


@numba.njit(cache=True, nogil=True)
def watched2(indptr, indices, data, starts, leave, exits, local, order, minimise,
             guess, track, tol, precision, floor):  # pragma: no cover - compiled
    """:func:`plain2`, each bound's change written into ``guess`` and each column's
    largest change into ``track``; returns the largest gap over its threshold among the
    states swept (read as each is set: the caller uses it only when ``order`` holds
    every state once, then it is ``compiled_kernels._over``'s maximum)."""
    m0 = track[OFF + 8]  # OFF + 4 k + j, k = 2: this sweep's largest changes
    m1 = track[OFF + 9]
    over = 0.0
    for i in range(order.shape[0]):
        s = order[i]
        a = local[s, 0]
        b = local[s, 1]
        lo, hi = _best2(indptr, indices, data, starts, leave, exits, local, s, minimise)
        lo, hi, over = _set2(local, s, lo, hi, tol, precision, floor, over)
        d0 = abs(lo - a)
        d1 = abs(hi - b)
        guess[s, 0] = d0
        guess[s, 1] = d1
        if d0 > m0:
            m0 = d0
        if d1 > m1:
            m1 = d1
    track[OFF + 8] = m0
    track[OFF + 9] = m1
    return over


@numba.njit(cache=True, nogil=True)
def verifying2(indptr, indices, data, starts, leave, exits, work, order, minimise,
               track, tol, precision, floor):  # pragma: no cover - compiled
    """``compiled_kernels.checked`` for one model on the packed rows: ``work[t]`` holds
    ``t``'s lower and upper bound and its lower and upper guess side by side.  Each
    guess's sum is widened by a bound on its rounding error (a lower guess lowered, an
    upper one raised), a guess on trial replaced by its clipped update, flagged when
    that moved it the wrong way, out of the trial when it crossed the proven bound on
    its other side.  The trial and failure flags are held in locals for the sweep and
    written back at its end (a flag set mid-sweep stops its guess's updates from the
    next state on).  Returns the largest gap over its threshold of the bounds swept, as
    :func:`watched2` does."""
    lower_on = track[OFF + 6]  # the lower guess's trial (1: on trial, 3: crossed)
    upper_on = track[OFF + 7]
    lower_fell = track[OFF + 10]  # 1: a lower guess fell in this sweep
    upper_rose = track[OFF + 11]
    over = 0.0
    for i in range(order.shape[0]):
        s = order[i]
        lo_best = np.inf if minimise else -np.inf
        hi_best = lo_best
        gl_best = lo_best
        gh_best = lo_best
        for c in range(starts[s], starts[s + 1]):
            lo = exits[c, 0]
            hi = exits[c, 1]
            gl = lo
            gh = hi
            first = indptr[c]
            last = indptr[c + 1]
            for e in range(first, last):
                t = indices[e]
                if t != s:
                    w = data[e]
                    lo += w * work[t, 0]
                    hi += w * work[t, 1]
                    gl += w * work[t, 2]
                    gh += w * work[t, 3]
            lo, hi = _divide2(lo, hi, leave[c])
            gl, gh = _divide2(gl, gh, leave[c])
            wide = (last - first + 8) * 2.0**-52
            gl *= 1.0 - wide
            gh *= 1.0 + wide
            lo_best, hi_best = _pick2(lo, hi, lo_best, hi_best, minimise)
            gl_best, gh_best = _pick2(gl, gh, gl_best, gh_best, minimise)
        low, high, over = _set2(work, s, lo_best, hi_best, tol, precision, floor, over)
        if lower_on == 1.0:
            val = min(max(gl_best, 0.0), 1.0)
            if val < work[s, 2]:
                lower_fell = 1.0
            work[s, 2] = val
            if val > high:
                lower_on = 3.0
        if upper_on == 1.0:
            val = min(max(gh_best, 0.0), 1.0)
            if val > work[s, 3]:
                upper_rose = 1.0
            work[s, 3] = val
            if val < low:
                upper_on = 3.0
    track[OFF + 6] = lower_on
    track[OFF + 7] = upper_on
    track[OFF + 10] = lower_fell
    track[OFF + 11] = upper_rose
    return over
