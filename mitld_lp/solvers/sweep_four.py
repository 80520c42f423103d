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
def _add4(a0, a1, a2, a3, w, x, t, col):  # pragma: no cover - compiled
    """Four sums each plus ``w`` times ``x[t, col:col + 4]``'s entry."""
    return (a0 + w * x[t, col], a1 + w * x[t, col + 1], a2 + w * x[t, col + 2],
            a3 + w * x[t, col + 3])


@numba.njit(cache=True, nogil=True, inline="always")
def _divide4(a0, a1, a2, a3, lv):  # pragma: no cover - compiled
    """Four sums over a choice's ``leave`` (``x / 1.0`` left out: it is ``x``; 0 where the
    choice never leaves)."""
    if lv == 1.0:
        return a0, a1, a2, a3
    if lv > 0.0:
        return a0 / lv, a1 / lv, a2 / lv, a3 / lv
    return 0.0, 0.0, 0.0, 0.0


@numba.njit(cache=True, nogil=True, inline="always")
def _pick(v, b, minimise):  # pragma: no cover - compiled
    """``v`` where it is strictly better than the best ``b`` so far, else ``b``."""
    return v if ((v < b) if minimise else (v > b)) else b


@numba.njit(cache=True, nogil=True, inline="always")
def _pick4(v0, v1, v2, v3, b0, b1, b2, b3, minimise):  # pragma: no cover - compiled
    return (_pick(v0, b0, minimise), _pick(v1, b1, minimise), _pick(v2, b2, minimise),
            _pick(v3, b3, minimise))


@numba.njit(cache=True, nogil=True, inline="always")
def _trial(work, s, j, g, on, bad):  # pragma: no cover - compiled
    """Guess column ``j`` (0-3; even a lower, odd an upper guess) of ``s`` replaced by its
    clipped update ``g`` while on trial (``on``): ``bad`` set where it moved the wrong
    way, ``on`` 3 where it crossed the proven bound on its pair's other side."""
    if on != 1.0:
        return on, bad
    v = min(max(g, 0.0), 1.0)
    lower = j % 2 == 0
    if (v < work[s, 4 + j]) if lower else (v > work[s, 4 + j]):
        bad = 1.0
    work[s, 4 + j] = v
    if (v > work[s, j + 1]) if lower else (v < work[s, j - 1]):
        on = 3.0  # beyond the other side's proven bound
    return on, bad


@numba.njit(cache=True, nogil=True, inline="always")
def _update4(indptr, indices, data, starts, leave, exits, local, s,
             minimise):  # pragma: no cover - compiled
    """``s``'s four bounds updated (``compiled_kernels.update`` for ``k == 4``)."""
    b0 = b1 = b2 = b3 = np.inf if minimise else -np.inf
    for c in range(starts[s], starts[s + 1]):
        v0, v1, v2, v3 = exits[c, 0], exits[c, 1], exits[c, 2], exits[c, 3]
        for e in range(indptr[c], indptr[c + 1]):
            t = indices[e]
            if t != s:
                v0, v1, v2, v3 = _add4(v0, v1, v2, v3, data[e], local, t, 0)
        v0, v1, v2, v3 = _divide4(v0, v1, v2, v3, leave[c])
        b0, b1, b2, b3 = _pick4(v0, v1, v2, v3, b0, b1, b2, b3, minimise)
    _keep4(local, s, b0, b1, b2, b3)


@numba.njit(cache=True, nogil=True, inline="always")
def _keep4(local, s, b0, b1, b2, b3):  # pragma: no cover - compiled
    """``compiled_kernels.keep``: each best clipped to [0, 1], a lower bound only raised,
    an upper one only lowered."""
    _kept(local, s, 0, b0)
    _kept(local, s, 1, b1)
    _kept(local, s, 2, b2)
    _kept(local, s, 3, b3)


@numba.njit(cache=True, nogil=True, inline="always")
def _kept(local, s, j, best):  # pragma: no cover - compiled
    v = min(max(best, 0.0), 1.0)
    if (v > local[s, j]) if j % 2 == 0 else (v < local[s, j]):
        local[s, j] = v


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


@numba.njit(cache=True, nogil=True, inline="always")
def _moved(guess, s, j, new, old, most):  # pragma: no cover - compiled
    """A bound's change written into ``guess[s, j]``; the largest change so far."""
    d = abs(new - old)
    guess[s, j] = d
    return d if d > most else most


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
        m0 = _moved(guess, s, 0, lo0, a0, m0)
        m1 = _moved(guess, s, 1, hi0, a1, m1)
        m2 = _moved(guess, s, 2, lo1, a2, m2)
        m3 = _moved(guess, s, 3, hi1, a3, m3)
        over = max(over, _gap(lo0, hi0, tol, precision, floor),
                   _gap(lo1, hi1, tol, precision, floor))
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
        b0 = b1 = b2 = b3 = g0 = g1 = g2 = g3 = np.inf if minimise else -np.inf
        for c in range(starts[s], starts[s + 1]):
            v0, v1, v2, v3 = exits[c, 0], exits[c, 1], exits[c, 2], exits[c, 3]
            u0, u1, u2, u3 = v0, v1, v2, v3
            for e in range(indptr[c], indptr[c + 1]):
                if indices[e] != s:
                    v0, v1, v2, v3 = _add4(v0, v1, v2, v3, data[e], work, indices[e], 0)
                    u0, u1, u2, u3 = _add4(u0, u1, u2, u3, data[e], work, indices[e], 4)
            lv = leave[c]
            v0, v1, v2, v3 = _divide4(v0, v1, v2, v3, lv)
            u0, u1, u2, u3 = _divide4(u0, u1, u2, u3, lv)
            wide = (indptr[c + 1] - indptr[c] + 8) * 2.0**-52
            u0, u2 = u0 * (1.0 - wide), u2 * (1.0 - wide)  # lower guesses lowered
            u1, u3 = u1 * (1.0 + wide), u3 * (1.0 + wide)  # upper ones raised
            b0, b1, b2, b3 = _pick4(v0, v1, v2, v3, b0, b1, b2, b3, minimise)
            g0, g1, g2, g3 = _pick4(u0, u1, u2, u3, g0, g1, g2, g3, minimise)
        _keep4(work, s, b0, b1, b2, b3)
        on0, bad0 = _trial(work, s, 0, g0, on0, bad0)
        on1, bad1 = _trial(work, s, 1, g1, on1, bad1)
        on2, bad2 = _trial(work, s, 2, g2, on2, bad2)
        on3, bad3 = _trial(work, s, 3, g3, on3, bad3)
    track[OFF + 3 * K] = on0
    track[OFF + 3 * K + 1] = on1
    track[OFF + 3 * K + 2] = on2
    track[OFF + 3 * K + 3] = on3
    track[OFF + 5 * K] = bad0
    track[OFF + 5 * K + 1] = bad1
    track[OFF + 5 * K + 2] = bad2
    track[OFF + 5 * K + 3] = bad3
