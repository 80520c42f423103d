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
proven.

Where the order is the reversed range (``kernels.sweep_order``'s) the sweeps walk the
states ``n - 1 .. 0`` without reading it and read the exits only of the choices listed
once a block (``kernels.Prepared.exit_rows``: 2.6% of that block's choices), every
other sum started at 0.0 (its exits are +0.0); where no entry lies on the diagonal no
entry is compared with its state and no ``leave`` read.  Each public sweep runs one of
three loops with these flags constant: that block's 46 sweeps 861-874 -> 734-763 ms,
the same bits."""

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
def _seek(rows, stop, first, listed):  # pragma: no cover - compiled
    """The first place in ``rows[:stop]`` of a listed choice ``>= first`` (a state's
    first choice; ``stop`` the first place of the next state's), as the states are
    swept from the last to the first; ``stop`` unless ``listed``."""
    p = stop
    if listed:
        while p > 0 and rows[p - 1] >= first:
            p -= 1
    return p


@numba.njit(cache=True, nogil=True, inline="always")
def _state(order, i, n, listed):  # pragma: no cover - compiled
    """The ``i``-th state swept: ``order[i]``, or the reversed range's unread."""
    return n - 1 - i if listed else order[i]


@numba.njit(cache=True, nogil=True, inline="always")
def _best2(indptr, indices, data, starts, leave, exits, local, s, minimise, rows, p,
           stop, listed, loops):  # pragma: no cover - compiled
    """State ``s``'s best choice's sums over ``local``'s two columns (each choice's
    self-loop solved, ``x / 1.0`` left out: it is ``x``; a choice that never leaves
    worth 0); the two bests.  Without ``loops`` (no entry of the block on its
    diagonal, so every ``leave`` is 1.0) no entry is compared with ``s`` and no
    ``leave`` read: the same operations.  With ``listed`` (:func:`plain2`) each sum
    starts from its choice's exit rewards only where the choice is listed in
    ``rows[p:stop]`` (the listed choices of ``s``, ascending), else from 0.0: the
    unlisted exits are +0.0, so the same bits."""
    lo_best = np.inf if minimise else -np.inf
    hi_best = lo_best
    for c in range(starts[s], starts[s + 1]):
        lo = 0.0  # listed: a choice not in rows has exits +0.0 (the same bits)
        hi = 0.0
        if not listed or (p < stop and rows[p] == c):
            lo = exits[c, 0]
            hi = exits[c, 1]
            p += 1  # a cursor only where listed (a helper returning it: 4x slower)
        if loops:
            for e in range(indptr[c], indptr[c + 1]):
                t = indices[e]
                if t != s:
                    w = data[e]
                    lo += w * local[t, 0]
                    hi += w * local[t, 1]
            lo, hi = _divide2(lo, hi, leave[c])
        else:
            for e in range(indptr[c], indptr[c + 1]):
                t = indices[e]
                w = data[e]
                lo += w * local[t, 0]
                hi += w * local[t, 1]
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
           tol, precision, floor, rows, listed, loops):  # pragma: no cover - compiled
    """:func:`_plain2` by one of three loops, ``listed`` and ``loops`` constants in each
    (folded: the flags read at run time cost more than they save)."""
    if listed and not loops:
        return _plain2(indptr, indices, data, starts, leave, exits, local, order,
                       minimise, tol, precision, floor, rows, True, False)
    if listed:
        return _plain2(indptr, indices, data, starts, leave, exits, local, order,
                       minimise, tol, precision, floor, rows, True, True)
    return _plain2(indptr, indices, data, starts, leave, exits, local, order,
                   minimise, tol, precision, floor, rows, False, True)


@numba.njit(cache=True, nogil=True, inline="always")
def _plain2(indptr, indices, data, starts, leave, exits, local, order, minimise,
            tol, precision, floor, rows, listed, loops):  # pragma: no cover - compiled
    """One sweep of ``local``'s two columns through the states in ``order`` (with
    ``listed``: the reversed range, not read, and only the exits of the choices in
    ``rows`` read, the choices whose exit row is not +0.0, ascending; ``loops``:
    :func:`_best2`); the largest gap over its threshold among the states swept, as
    :func:`watched2`'s.  Each sweep runs one of three loops, its flags constants
    (:func:`plain2`'s)."""
    over = 0.0
    n = local.shape[0]
    stop = rows.shape[0]
    for i in range(n if listed else order.shape[0]):
        s = _state(order, i, n, listed)
        p = _seek(rows, stop, starts[s], listed)
        lo, hi = _best2(indptr, indices, data, starts, leave, exits, local, s, minimise,
                        rows, p, stop, listed, loops)
        stop = p
        _, _, over = _set2(local, s, lo, hi, tol, precision, floor, over)
    return over


@numba.njit(cache=True, nogil=True)
def watched2(indptr, indices, data, starts, leave, exits, local, order, minimise,
             guess, track, tol, precision, floor, rows, listed,
             loops):  # pragma: no cover - compiled
    """:func:`_watched2` by one of three loops, ``listed`` and ``loops`` constants in each
    (folded: the flags read at run time cost more than they save)."""
    if listed and not loops:
        return _watched2(indptr, indices, data, starts, leave, exits, local, order,
                         minimise, guess, track, tol, precision, floor, rows, True, False)
    if listed:
        return _watched2(indptr, indices, data, starts, leave, exits, local, order,
                         minimise, guess, track, tol, precision, floor, rows, True, True)
    return _watched2(indptr, indices, data, starts, leave, exits, local, order,
                     minimise, guess, track, tol, precision, floor, rows, False, True)


@numba.njit(cache=True, nogil=True, inline="always")
def _watched2(indptr, indices, data, starts, leave, exits, local, order, minimise,
              guess, track, tol, precision, floor, rows, listed,
              loops):  # pragma: no cover - compiled
    """:func:`plain2` (``rows``, ``listed``, ``loops`` as there), each bound's change
    written into ``guess`` and each column's largest change into ``track``; returns the
    largest gap over its threshold among the states swept (read as each is set: the
    caller uses it only when ``order`` holds every state once, then it is
    ``compiled_kernels._over``'s maximum)."""
    m0 = track[OFF + 8]  # OFF + 4 k + j, k = 2: this sweep's largest changes
    m1 = track[OFF + 9]
    over = 0.0
    n = local.shape[0]
    stop = rows.shape[0]
    for i in range(n if listed else order.shape[0]):
        s = _state(order, i, n, listed)
        a = local[s, 0]
        b = local[s, 1]
        p = _seek(rows, stop, starts[s], listed)
        lo, hi = _best2(indptr, indices, data, starts, leave, exits, local, s, minimise,
                        rows, p, stop, listed, loops)
        stop = p
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
               track, tol, precision, floor, rows, listed,
               loops):  # pragma: no cover - compiled
    """:func:`_verifying2` by one of three loops, ``listed`` and ``loops`` constants in each
    (folded: the flags read at run time cost more than they save)."""
    if listed and not loops:
        return _verifying2(indptr, indices, data, starts, leave, exits, work, order,
                           minimise, track, tol, precision, floor, rows, True, False)
    if listed:
        return _verifying2(indptr, indices, data, starts, leave, exits, work, order,
                           minimise, track, tol, precision, floor, rows, True, True)
    return _verifying2(indptr, indices, data, starts, leave, exits, work, order,
                       minimise, track, tol, precision, floor, rows, False, True)


@numba.njit(cache=True, nogil=True, inline="always")
def _verifying2(indptr, indices, data, starts, leave, exits, work, order, minimise,
                track, tol, precision, floor, rows, listed,
                loops):  # pragma: no cover - compiled
    """``compiled_kernels.checked`` for one model on the packed rows: ``work[t]`` holds
    ``t``'s lower and upper bound and its lower and upper guess side by side.  Each
    guess's sum is widened by a bound on its rounding error (a lower guess lowered, an
    upper one raised), a guess on trial replaced by its clipped update, flagged when
    that moved it the wrong way, out of the trial when it crossed the proven bound on
    its other side.  The trial and failure flags are held in locals for the sweep and
    written back at its end (a flag set mid-sweep stops its guess's updates from the
    next state on).  Returns the largest gap over its threshold of the bounds swept, as
    :func:`watched2` does.  ``rows``, ``listed``, ``loops``: :func:`plain2`."""
    lower_on = track[OFF + 6]  # the lower guess's trial (1: on trial, 3: crossed)
    upper_on = track[OFF + 7]
    lower_fell = track[OFF + 10]  # 1: a lower guess fell in this sweep
    upper_rose = track[OFF + 11]
    over = 0.0
    n = work.shape[0]
    stop = rows.shape[0]
    for i in range(n if listed else order.shape[0]):
        s = _state(order, i, n, listed)
        p = _seek(rows, stop, starts[s], listed)
        stop_s = stop
        stop = p
        lo_best = np.inf if minimise else -np.inf
        hi_best = lo_best
        gl_best = lo_best
        gh_best = lo_best
        for c in range(starts[s], starts[s + 1]):
            lo = 0.0
            hi = 0.0
            if not listed or (p < stop_s and rows[p] == c):
                lo = exits[c, 0]
                hi = exits[c, 1]
                p += 1
            gl = lo
            gh = hi
            first = indptr[c]
            last = indptr[c + 1]
            if loops:
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
            else:
                for e in range(first, last):
                    t = indices[e]
                    w = data[e]
                    lo += w * work[t, 0]
                    hi += w * work[t, 1]
                    gl += w * work[t, 2]
                    gh += w * work[t, 3]
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
