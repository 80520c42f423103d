"""The numba kernels of :mod:`mitld_lp.solvers.kernels` (imported only from there, and
only for a product large enough to pay numba's import; compiled once, cached on disk).

A verification (the guesses swept beside the proven bounds) runs on packed rows: at its
start each state's bounds and guesses are copied side by side into one row of a work
array (:func:`_pack`), swept there, and copied back when it ends or the call returns, so
an entry reads one row (32 bytes for one model) where the two arrays cost two reads far
apart in memory.  The arithmetic is the same, and so are the bounds, to the bit.
"""

from __future__ import annotations

import numpy as np

from mitld_lp.solvers.sweep_four import plain4, verifying4, watched4
from mitld_lp.solvers.sweep_two import plain2, verifying2, watched2
from mitld_lp.util import kernel_loader

# numba's cached machine code run without importing numba; numba itself on a miss
# (without PyYAML, the narrow load, the disk cache's lock: kernel_loader.numba_module)
numba = kernel_loader.lazy_numba(globals())


__all__ = ["OFF", "VERIFY_SWEEPS", "WATCH_SWEEPS", "gauss_seidel"]

OFF = 8
"""``track``'s header: [0] the phase (-1: plain sweeps, 0: watching the changes, 1:
verifying guesses), [1] sweeps of the verification, [2] guesses made, [3] columns
verified, [4] sweeps watched since the last verification, [5] the guesses' margin (a
share of the extrapolated correction), [6] verifying sweeps in all.  Then six slots
per column: the largest change of the last sweep and of the one before, the ratio of
the two, the column's trial (1: on trial, 2: verified, 3: crossed the other bound, 0:
none), this sweep's largest change, and whether its guess failed to move one way (an
upper rose, a lower fell) in this sweep."""
WATCH_SWEEPS = 8
"""Sweeps watched before a guess (and after a verification ends)."""
VERIFY_SWEEPS = 16
"""Sweeps a guess has to become monotone (verified) before it is given up.  Measured and
not done: 8.  On QVBS ``consensus`` 6-2 ``c2``'s block of 139,566 states swept alone it
took 361 -> 336 sweeps (172 -> 136 of them verifying), but in the solve stage the
iteration took 1,380 sweeps where it took 1,217 with 16."""
STEADY = 0.05
"""A column's changes are steady when the ratio of two successive sweeps' largest
changes moved by at most this share of ``1 - ratio`` since the last sweep."""


@numba.njit(cache=True, nogil=True, inline="always")
def sums(indptr, indices, data, exits, x, c, s, acc, off, k):  # pragma: no cover
    """``acc[off + j]``: choice ``c``'s exit reward plus its entries' sum over ``x``'s
    column ``j`` (all but ``s``'s self-loop, which the caller solves)."""
    for j in range(k):
        acc[off + j] = exits[c, j]
    for e in range(indptr[c], indptr[c + 1]):
        t = indices[e]
        if t != s:
            w = data[e]
            for j in range(k):
                acc[off + j] += w * x[t, j]


@numba.njit(cache=True, nogil=True, inline="always")
def keep(local, s, best, k):  # pragma: no cover - compiled
    """``best`` (clipped to [0, 1]) kept where it improves ``s``'s bounds: a lower bound
    (even column) only raised, an upper one only lowered."""
    for j in range(k):
        val = min(max(best[j], 0.0), 1.0)
        if j % 2 == 0:
            if val > local[s, j]:
                local[s, j] = val
        elif val < local[s, j]:
            local[s, j] = val


@numba.njit(cache=True, nogil=True, inline="always")
def update(indptr, indices, data, starts, leave, exits, local, s, best, acc,
           minimise):  # pragma: no cover - compiled
    k = local.shape[1]
    for j in range(k):
        best[j] = np.inf if minimise else -np.inf
    for c in range(starts[s], starts[s + 1]):
        sums(indptr, indices, data, exits, local, c, s, acc, 0, k)
        lv = leave[c]
        for j in range(k):
            val = acc[j] / lv if lv > 0.0 else 0.0
            if (val < best[j]) if minimise else (val > best[j]):
                best[j] = val
    keep(local, s, best, k)

@numba.njit(cache=True, nogil=True, inline="always")
def checked(indptr, indices, data, starts, leave, exits, local, guess, s, best, acc,
            minimise, track, k):  # pragma: no cover - compiled
    """:func:`update` of ``local`` in a verifying sweep, and in the same pass over the
    entries the update of the guesses on trial (``guess``), each choice's value widened
    by a bound on its rounding error (every term is non-negative: a sum of ``m`` of them
    is within ``m`` units of its last place, the self-loop's ``1 - p`` and the division
    add two), a lower guess lowered and an upper one raised, so they lie beyond the
    exact update.  A guess is replaced by its update; one whose update moved it the
    wrong way (a lower down, an upper up) is flagged, one that crossed the proven
    bound on its other side is out of the trial."""
    for j in range(2 * k):
        best[j] = np.inf if minimise else -np.inf
    for c in range(starts[s], starts[s + 1]):
        sums(indptr, indices, data, exits, local, c, s, acc, 0, k)
        sums(indptr, indices, data, exits, guess, c, s, acc, k, k)
        lv = leave[c]
        wide = (indptr[c + 1] - indptr[c] + 8) * 2.0**-52
        for j in range(2 * k):
            val = acc[j] / lv if lv > 0.0 else 0.0
            if j >= k:
                val = val * (1.0 - wide) if j % 2 == 0 else val * (1.0 + wide)
            if (val < best[j]) if minimise else (val > best[j]):
                best[j] = val
    keep(local, s, best, k)
    for j in range(k):
        if track[OFF + 3 * k + j] != 1.0:
            continue
        val = min(max(best[k + j], 0.0), 1.0)
        if (val < guess[s, j]) if j % 2 == 0 else (val > guess[s, j]):
            track[OFF + 5 * k + j] = 1.0
        guess[s, j] = val
        if (val > local[s, j + 1]) if j % 2 == 0 else (val < local[s, j - 1]):
            track[OFF + 3 * k + j] = 3.0  # beyond the other side's proven bound


@numba.njit(cache=True, nogil=True, inline="always")
def threshold(low, tol, precision, floor):  # pragma: no cover - compiled
    """The gap below which a state of lower bound ``low`` is known (kernels.thresholds)."""
    return tol if precision < 0.0 else min(tol, max(precision * low, floor))


@numba.njit(cache=True, nogil=True)
def _over(local, k, tol, precision, floor):  # pragma: no cover - compiled
    """The largest gap over its threshold among the bounds in ``local``'s first ``k``
    columns (all of them, or a verification's packed rows: one C-contiguous layout,
    so compiled once)."""
    n = local.shape[0]
    over = 0.0
    for s in range(n):
        for j in range(0, k, 2):
            r = (local[s, j + 1] - local[s, j]) / threshold(local[s, j], tol, precision,
                                                            floor)
            if r > over:
                over = r
    return over


@numba.njit(cache=True, nogil=True)
def _plain(indptr, indices, data, starts, leave, exits, local, order, best,
           acc, minimise, tol, precision, floor, rows, listed, loops):  # pragma: no cover
    """One sweep of ``local`` through the states in ``order``; for one model the
    largest gap over its threshold read as each state is set (:func:`_watched`), -1 for
    more."""
    n, k = local.shape
    if k == 2:  # one model: its sums in scalars (sweep_two)
        return plain2(indptr, indices, data, starts, leave, exits, local, order,
                      minimise, tol, precision, floor, rows, listed, loops)
    if k == 4:  # two models: their sums in scalars (sweep_four)
        plain4(indptr, indices, data, starts, leave, exits, local, order, minimise)
        return -1.0
    for i in range(n):
        update(indptr, indices, data, starts, leave, exits, local, order[i], best, acc,
               minimise)
    return -1.0


@numba.njit(cache=True, nogil=True)
def _watched(indptr, indices, data, starts, leave, exits, local, order, best,
             acc, minimise, guess, track, tol, precision, floor, rows, listed,
             loops):  # pragma: no cover - compiled
    """:func:`_plain`, each bound's change written into ``guess`` and each column's
    largest change into ``track``; returns the largest gap over its threshold after the
    sweep (:func:`_over`) for one or two models, -1 for more (the caller reads it then).

    One model (two columns) runs on scalars (sweep_two): a state's old bounds held in
    registers, not written into ``guess`` and read back, its gap read as it is set (a
    state is updated once a sweep and nothing after the sweep moves a bound while
    watching, so the largest of those is :func:`_over`'s, the same maximum of the same
    ratios): QVBS ``zeroconf`` 1000-4's block of 213,268 states, whose 39 sweeps all
    watch, 13.4 -> 10.0 ms a sweep, the bounds the same to the bit."""
    n, k = local.shape
    if k == 2:
        return watched2(indptr, indices, data, starts, leave, exits, local, order,
                        minimise, guess, track, tol, precision, floor, rows, listed,
                        loops)
    if k == 4:
        return watched4(indptr, indices, data, starts, leave, exits, local, order,
                        minimise, guess, track, tol, precision, floor)
    for i in range(n):
        s = order[i]
        for j in range(k):
            guess[s, j] = local[s, j]
        update(indptr, indices, data, starts, leave, exits, local, s, best, acc,
               minimise)
        for j in range(k):
            d = abs(local[s, j] - guess[s, j])
            guess[s, j] = d
            if d > track[OFF + 4 * k + j]:
                track[OFF + 4 * k + j] = d
    return -1.0


@numba.njit(cache=True, nogil=True)
def _verifying(indptr, indices, data, starts, leave, exits, work, order, best,
               acc, minimise, track, tol, precision, floor, rows, listed,
               loops):  # pragma: no cover - compiled
    """One sweep of the proven bounds and of the guesses on trial (:func:`checked`),
    both packed into ``work``'s rows (the bounds in its first ``k`` columns, the
    guesses in the next ``k``): an entry reads one row where two arrays cost two reads
    far apart in memory, the verifying sweep's price 2.4 plain ones before.  For one
    model the largest gap over its threshold of the bounds as swept (sweep_two), -1
    for more."""
    n, kk = work.shape
    k = kk // 2
    if k == 2:
        return verifying2(indptr, indices, data, starts, leave, exits, work, order,
                          minimise, track, tol, precision, floor, rows, listed, loops)
    if k == 4:
        verifying4(indptr, indices, data, starts, leave, exits, work, order, minimise,
                   track)
        return -1.0
    for i in range(n):
        checked(indptr, indices, data, starts, leave, exits, work[:, :k], work[:, k:],
                order[i], best, acc, minimise, track, k)
    return -1.0


@numba.njit(cache=True, nogil=True)
def _pack(local, guess, work, back):  # pragma: no cover - compiled
    """``local`` and ``guess`` side by side in ``work``'s rows, or (``back``) back."""
    n, k = local.shape
    for s in range(n):
        for j in range(k):
            if back:
                local[s, j] = work[s, j]
                guess[s, j] = work[s, k + j]
            else:
                work[s, j] = local[s, j]
                work[s, k + j] = guess[s, j]


@numba.njit(cache=True, nogil=True)
def gauss_seidel(indptr, indices, data, starts, leave, exits, local, order, max_sweeps,
                 tol, minimise, precision, floor, guess, track, rows, listed,
                 loops):  # pragma: no cover - compiled
    """Sweeps through the states in ``order`` (each state once: a permutation, as
    :func:`~mitld_lp.solvers.kernels.sweep_order` gives; a watched sweep reads the gaps
    as it sets them only when ``order`` has one place a state) until every gap is below
    ``tol`` and, when ``precision >= 0``, below ``precision`` times its lower bound
    (never below ``floor``); returns the sweeps and the largest gap over its threshold.

    With ``track[0] >= 0`` the sweeps also guess and verify bounds (kernels.py's module
    docs), ``track`` keeping their state between calls (:data:`OFF`): while watching,
    ``guess`` holds each bound's change in the last sweep, while verifying the guesses
    on trial; ``local`` holds proven bounds only, a guess written into it once proven.
    Each kind of sweep is its own function: one loop with all three branches in it
    compiled to much slower plain sweeps.

    One model (two columns; more ignore these three): ``listed`` says ``order`` is the
    reversed range (then not read) and ``rows`` the choices whose row of ``exits`` is
    not +0.0, ascending (every other sum starts at 0.0: the same bits); ``loops`` that
    some entry lies on the diagonal (else no entry is compared with its state and no
    ``leave`` read, each 1.0).  QVBS ``zeroconf`` 1000-6 ``correct_min``'s block: 2.6%
    of its choices listed, no self-loop."""
    n, k = local.shape
    best = np.empty(2 * k)
    acc = np.empty(2 * k)
    done = 0
    over = np.inf
    optimistic = track[0] >= 0.0
    work = np.empty((0, 2 * k))  # the packed rows of a verification, made at its start
    packed = False
    # every state once a sweep: a watched sweep reads the gap
    whole = listed or order.shape[0] == n
    while done < max_sweeps:
        for j in range(k):
            track[OFF + 4 * k + j] = 0.0
            track[OFF + 5 * k + j] = 0.0
        proven = track[3]
        if not optimistic:
            swept = _plain(indptr, indices, data, starts, leave, exits, local, order,
                           best, acc, minimise, tol, precision, floor, rows, listed, loops)
        elif track[0] == 1.0:
            if not packed:
                if work.shape[0] != n:
                    work = np.empty((n, 2 * k))
                _pack(local, guess, work, np.bool_(False))  # bool_: not a literal type
                packed = True
            swept = _verifying(indptr, indices, data, starts, leave, exits, work, order,
                               best, acc, minimise, track, tol, precision, floor, rows,
                               listed, loops)
        else:
            swept = _watched(indptr, indices, data, starts, leave, exits, local, order,
                             best, acc, minimise, guess, track, tol, precision, floor,
                             rows, listed, loops)
        # the gap over its threshold read by the sweep (-1: not), good when every state
        # was swept once: each is set once a sweep, and nothing after it moves a bound
        # but a guess proven (then read again)
        watched = swept if whole else -1.0
        done += 1
        # one layout and no literal for the helpers below, so each is compiled once (a
        # slice work[:, :k] is typed apart from a C array, a constant 0 or True apart
        # from an int64 or bool): the packed rows are passed whole, the guesses at k
        if packed:
            _after_sweep(work, work, k, track, k, tol, precision, floor)
            over = (watched if watched >= 0.0 and track[3] == proven
                    else _over(work, k, tol, precision, floor))
            if track[0] != 1.0:  # the verification is over: watched sweeps next
                _pack(local, guess, work, np.bool_(True))
                packed = False
        else:
            if optimistic:  # watching: moves guess and track only, never local
                _after_sweep(local, guess, np.int64(0), track, k, tol, precision, floor)
            over = watched if watched >= 0.0 else _over(local, k, tol, precision, floor)
        if over < 1.0:
            break
    if packed:
        _pack(local, guess, work, np.bool_(True))
    return done, over


@numba.njit(cache=True, nogil=True)
def _after_sweep(local, guess, g, track, k, tol, precision, floor):  # pragma: no cover
    """The bookkeeping of :func:`gauss_seidel`'s guesses after a sweep (the phases of
    ``track``, :data:`OFF`): while watching, once every moving column's changes shrink
    at a steady ratio, extrapolate into ``guess``; while verifying, a guess whose sweep
    was monotone is proven (module docs) and written into ``local``, one that crossed
    or ran out of sweeps is dropped.  The bounds are ``local``'s first ``k`` columns,
    the guesses ``guess``'s ``k`` columns from ``g`` (the packed rows: both ``work``,
    ``g = k``)."""
    n = local.shape[0]
    if track[0] == 0.0:
        track[4] += 1.0
        steady = True
        moving = False
        for j in range(k):
            d = track[OFF + 4 * k + j]
            d1 = track[OFF + j]
            track[OFF + k + j] = d1
            track[OFF + j] = d
            if d <= 0.0:
                continue
            moving = True
            ratio = d / d1 if d1 > 0.0 else 2.0
            last = track[OFF + 2 * k + j]
            track[OFF + 2 * k + j] = ratio
            if not (ratio < 1.0 and abs(ratio - last) <= STEADY * (1.0 - ratio)):
                steady = False
        if not (steady and moving and track[4] >= WATCH_SWEEPS):
            return
        eta = track[5]
        for p in range(0, k, 2):
            if track[OFF + p] <= 0.0 or track[OFF + p + 1] <= 0.0:
                continue  # a pair that no longer moves: nothing to extrapolate
            ql = track[OFF + 2 * k + p]
            qh = track[OFF + 2 * k + p + 1]
            rl = ql / (1.0 - ql)
            rh = qh / (1.0 - qh)
            for s in range(n):
                low = local[s, p]
                high = local[s, p + 1]
                cl = low + guess[s, g + p] * rl
                ch = high - guess[s, g + p + 1] * rh
                lo_c = min(cl, ch)
                hi_c = max(cl, ch)
                margin = eta * max(cl - low, high - ch) \
                    + threshold(low, tol, precision, floor) / 16.0
                guess[s, g + p] = min(high, max(low, lo_c - margin))
                guess[s, g + p + 1] = max(guess[s, g + p], min(high, hi_c + margin))
            track[OFF + 3 * k + p] = 1.0
            track[OFF + 3 * k + p + 1] = 1.0
        track[0] = 1.0
        track[1] = 0.0
        track[2] += 1.0
        return
    track[1] += 1.0
    track[6] += 1.0
    left = False
    for j in range(k):
        trial = track[OFF + 3 * k + j]
        if trial == 1.0 and track[OFF + 5 * k + j] == 0.0:
            track[OFF + 3 * k + j] = 2.0  # monotone: an inductive bound (module docs)
            track[3] += 1.0
            for s in range(n):
                if j % 2 == 1:
                    local[s, j] = min(local[s, j], guess[s, g + j])
                else:
                    local[s, j] = max(local[s, j], guess[s, g + j])
        elif trial == 1.0:
            left = True
    if left and track[1] < VERIFY_SWEEPS:
        return
    failed = False
    for j in range(k):
        if track[OFF + 3 * k + j] == 1.0 or track[OFF + 3 * k + j] == 3.0:
            failed = True
        track[OFF + 3 * k + j] = 0.0
        track[OFF + j] = 0.0
        track[OFF + k + j] = 0.0
        track[OFF + 2 * k + j] = 0.0
    track[5] = min(track[5] * 2.0, 1.0) if failed else max(track[5] / 2.0, 1.0 / 256.0)
    track[0] = 0.0
    track[4] = 0.0
