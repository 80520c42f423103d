"""The numba kernels of :mod:`mitld_lp.solvers.kernels` (imported only from there, and
only for a product large enough to pay numba's import; compiled once, cached on disk).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["gauss_seidel"]


@numba.njit(cache=True, nogil=True, inline="always")
def update(indptr, indices, data, starts, leave, exits, local, s, best, acc,
           minimise):  # pragma: no cover - compiled
    k = local.shape[1]
    for j in range(k):
        best[j] = np.inf if minimise else -np.inf
    for c in range(starts[s], starts[s + 1]):
        for j in range(k):
            acc[j] = exits[c, j]
        for e in range(indptr[c], indptr[c + 1]):
            t = indices[e]
            if t != s:
                w = data[e]
                for j in range(k):
                    acc[j] += w * local[t, j]
        lv = leave[c]
        for j in range(k):
            val = acc[j] / lv if lv > 0.0 else 0.0
            if (val < best[j]) if minimise else (val > best[j]):
                best[j] = val
    for j in range(k):
        val = min(max(best[j], 0.0), 1.0)
        if j % 2 == 0:
            if val > local[s, j]:
                local[s, j] = val
        elif val < local[s, j]:
            local[s, j] = val

@numba.njit(cache=True, nogil=True, inline="always")
def update2(indptr, indices, data, starts, leave, exits, local, s,
            minimise):  # pragma: no cover - compiled
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
        lv = leave[c]
        if lv != 1.0:  # most choices have no self-loop: x / 1.0 is x, and no divide
            if lv > 0.0:
                lo /= lv
                hi /= lv
            else:
                lo = 0.0
                hi = 0.0
        if minimise:
            lo_best = min(lo_best, lo)
            hi_best = min(hi_best, hi)
        else:
            lo_best = max(lo_best, lo)
            hi_best = max(hi_best, hi)
    local[s, 0] = max(local[s, 0], min(max(lo_best, 0.0), 1.0))
    local[s, 1] = min(local[s, 1], min(max(hi_best, 0.0), 1.0))

@numba.njit(cache=True, nogil=True)
def gauss_seidel(indptr, indices, data, starts, leave, exits, local, order, max_sweeps,
                 tol, minimise, precision, floor):  # pragma: no cover - compiled
    """Sweeps through the states in ``order`` until every gap is below ``tol`` and,
    when ``precision >= 0``, below ``precision`` times its lower bound (never below
    ``floor``); returns the sweeps and the largest gap over its threshold."""
    n, k = local.shape
    best = np.empty(k)
    acc = np.empty(k)
    done = 0
    over = np.inf
    while done < max_sweeps:
        for i in range(n):
            s = order[i]
            if k == 2:
                update2(indptr, indices, data, starts, leave, exits, local, s, minimise)
            else:
                update(indptr, indices, data, starts, leave, exits, local, s, best, acc,
                       minimise)
        done += 1
        over = 0.0
        for s in range(n):
            for j in range(0, k, 2):
                d = local[s, j + 1] - local[s, j]
                if precision < 0.0:
                    r = d / tol
                else:
                    r = d / min(tol, max(precision * local[s, j], floor))
                if r > over:
                    over = r
        if over < 1.0:
            break
    return done, over
