"""A sum of floats in a numba kernel rounded as :func:`math.fsum` rounds it, for the sensed
build's level kernels (:func:`mitld_lp.sensing.group_kernels.level_hypotheses`): the
double-double sum where it is surely the correctly rounded sum (as
:func:`mitld_lp.sensing.rows.fsum_by` decides), else CPython's own algorithm step for
step (Shewchuk's exact partials), so a hypothesis's total is the same to the bit as the
one-state-at-a-time build's.  Imported only where the compiled kernels run."""

from __future__ import annotations

import math

from mitld_lp.util import kernel_loader

# numba's cached machine code run without importing numba; numba itself on a miss
# (without PyYAML, the narrow load, the disk cache's lock: kernel_loader.numba_module)
numba = kernel_loader.lazy_numba(globals())


@numba.njit(cache=True, nogil=True)
def fsum(values, start, count, partials):  # pragma: no cover - compiled
    """:func:`math.fsum` of ``values[start:start + count]`` (finite values), CPython's
    algorithm step for step: Shewchuk's exact partials (``partials``: room for them),
    then their sum rounded once, half-way cases to even."""
    n = 0
    for k in range(start, start + count):
        x = values[k]
        i = 0
        for j in range(n):
            y = partials[j]
            if abs(x) < abs(y):
                x, y = y, x
            hi = x + y
            lo = y - (hi - x)
            if lo != 0.0:
                partials[i] = lo
                i += 1
            x = hi
        partials[i] = x
        n = i + 1
    hi = 0.0
    if n > 0:
        n -= 1
        hi = partials[n]
        lo = 0.0
        while n > 0:
            x = hi
            n -= 1
            y = partials[n]
            hi = x + y
            yr = hi - x
            lo = y - yr
            if lo != 0.0:
                break
        if n > 0 and ((lo < 0.0 and partials[n - 1] < 0.0)
                      or (lo > 0.0 and partials[n - 1] > 0.0)):
            y = lo * 2.0
            x = hi + y
            yr = x - hi
            if y == yr:
                hi = x
    return hi


@numba.njit(cache=True, nogil=True)
def sum_of(values, start, count, partials):  # pragma: no cover - compiled
    """:func:`mitld_lp.sensing.rows.fsum_by`'s sum of ``values[start:start + count]``
    (positive values), decided as it decides: the double-double sum rounded once,
    or, where that may not be the correctly rounded sum, :func:`fsum`."""
    high = values[start]
    low = 0.0
    size = 0.0
    for k in range(start + 1, start + count):
        x = values[k]
        t = high + x
        back = t - high
        error = (high - (t - back)) + (x - back)
        high = t
        low += error
        size += abs(error)
    out = high + low
    back = out - high
    rest = (high - (out - back)) + (low - back)
    m, e = math.frexp(out)
    if out == 0.0 or abs(out) < 2.2250738585072014e-308:
        half = 5e-324 / 2
    else:
        half = math.ldexp(1.0, e - 53) / 2
    if rest < 0.0 and m == 0.5:
        half /= 2
    if count > 2 and abs(rest) + 4.0 * count * 2.0**-52 * size >= half:
        return fsum(values, start, count, partials)
    return out
