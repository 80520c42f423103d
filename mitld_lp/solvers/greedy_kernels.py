r"""The greedy check's dual feasibility in one compiled pass (numba, through
:mod:`mitld_lp.util.kernel_loader`; imported only by
:func:`mitld_lp.solvers.greedy_block.certified_greedy`, and only once the compiled
kernels' load is paid).

:func:`~mitld_lp.solvers.greedy_block.certified_greedy` decides, for every choice ``c``
of a state ``s``, whether its score beats the policy's value there and, for the
policy's own choice, whether its residual is above the tie scale; the scores are summed
in long double (each row's products from 0 in their stored order), which numba cannot
do.  :func:`dual_check` sums them in float64 instead, with each sum's rounding bound:
the float64 slack and the long double one (rounded to float64) both lie within
:math:`(k + 2)\,u\,A + u\,|S| + (k + 1)\,2^{-1070}` of the exact slack :math:`S`
(``k`` products, :math:`u = 2^{-53}`, :math:`A` the sum of the magnitudes of the
reward, the products and the state's value; the last term covers products that
underflow), so where the float64 comparison clears twice that (:data:`_SAFETY` times
it) both routes decide the same, and the decision is taken here.  A state with a choice
that does not clear it is marked ``UNSURE`` and decided by the long double route as
before.  The decisions, hence the failing states and everything after, are the long
double route's to the bit.
"""

from __future__ import annotations

import numpy as np

from mitld_lp.util import kernel_loader

numba = kernel_loader.lazy_numba(globals())

__all__ = ["FAILED", "UNSURE", "dual_check", "greedy_choices"]

FAILED = 1
"""A state whose greedy choice some choice beats, or whose residual is above the scale."""

UNSURE = 2
"""A state with a choice too close to the scale for float64 to decide."""

_U = 2.0 ** -53
_TINY = 2.0 ** -1070
_SAFETY = 4.0


@numba.njit(cache=True, nogil=True)
def dual_check(indptr, indices, data, groups, reward, raw, tie, chosen,
               maximise):  # pragma: no cover - compiled
    """Per state: 0 (every choice passes), :data:`FAILED` or :data:`UNSURE` (module
    docs).  ``indptr``/``indices``/``data``: the block's rows (canonical), ``groups``
    each state's choices, ``reward`` each choice's exit reward, ``raw`` the policy's
    values (unclipped), ``tie`` each state's tie scale, ``chosen`` the policy's
    choices."""
    n = groups.shape[0] - 1
    flag = np.zeros(n, dtype=np.uint8)
    for s in range(n):
        v = raw[s]
        t = tie[s]
        own = chosen[s]
        for c in range(groups[s], groups[s + 1]):
            acc = 0.0
            mag = 0.0
            lo = indptr[c]
            hi = indptr[c + 1]
            for e in range(lo, hi):
                p = data[e] * raw[indices[e]]
                acc += p
                mag += abs(p)
            r = reward[c]
            score = r + acc
            slack = v - score if maximise else score - v
            k = hi - lo
            err = _SAFETY * ((k + 2) * _U * (abs(r) + mag + abs(v)) + 2.0 * _U * abs(slack)
                             + (k + 1) * _TINY)
            m = t + slack
            if not (abs(m) < np.inf and abs(slack) < np.inf):
                flag[s] = UNSURE
                continue
            if abs(m) <= 2.0 * err + 4.0 * _U * abs(m):
                flag[s] = UNSURE
                continue
            if m < 0.0:
                flag[s] = FAILED
                break
            if c == own:
                d = abs(slack) - t
                if abs(d) <= 2.0 * err + 4.0 * _U * (abs(slack) + t):
                    flag[s] = UNSURE
                    continue
                if d > 0.0:
                    flag[s] = FAILED
                    break
    return flag


@numba.njit(cache=True, nogil=True)
def greedy_choices(indptr, indices, data, groups, reward, bound,
                   maximise):  # pragma: no cover - compiled
    """Per state, its first choice of best score ``reward + rows @ bound`` (each row's
    products summed from 0 in their stored order, then added to its reward: the sums
    of SciPy's product), as :func:`~mitld_lp.solvers.graph.segmented_argmax` picks it
    (the lowest index among the scores equal to the best; a state whose best is NaN
    or infinite gets the largest int64, as there)."""
    n = groups.shape[0] - 1
    out = np.empty(n, dtype=np.int64)
    for s in range(n):
        lo = groups[s]
        hi = groups[s + 1]
        best = 0.0
        pick = -1
        nan = False
        for c in range(lo, hi):
            acc = 0.0
            for e in range(indptr[c], indptr[c + 1]):
                acc += data[e] * bound[indices[e]]
            score = reward[c] + acc
            if score != score:
                nan = True
                break
            if pick < 0 or (score > best if maximise else score < best):
                best = score
                pick = c
        # no score equal to an infinite or NaN best, there
        out[s] = np.iinfo(np.int64).max if nan or pick < 0 or abs(best) == np.inf else pick
    return out
