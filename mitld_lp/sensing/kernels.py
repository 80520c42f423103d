"""The numba kernels of :mod:`mitld_lp.sensing.rows` (imported only from there, and only
for a build whose rows are many enough to pay numba's load; compiled once, cached on
disk).  Each does what the NumPy lines it replaces do, with the same floating-point
operations in the same order, so a product is the same to the bit either way
(tests/test_sensing_kernels.py)."""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["pack", "sorted_groups", "dense_groups", "dd_sums", "spread", "scatter_max",
           "scatter_min", "scatter_add", "gather2"]

_LIMIT = 1 << 62


@numba.njit(cache=True, nogil=True)
def pack(cols):  # pragma: no cover - compiled
    """:func:`mitld_lp.sensing.rows.pack_words` on a tuple of int64 columns: the words
    as the rows of an array, and the last word's span."""
    k = len(cols)
    n = len(cols[0])
    lo = np.empty(k, np.int64)
    hi = np.empty(k, np.int64)
    for j in range(k):
        c = cols[j]
        a = c[0]
        b = c[0]
        for i in range(1, n):
            v = c[i]
            if v < a:
                a = v
            elif v > b:
                b = v
        lo[j] = a
        hi[j] = b
    words = np.empty((k, n), np.int64)
    m = 0  # the words begun
    open_ = False  # whether the last one takes more columns
    span = 1
    for j in range(k):
        c = cols[j]
        # hi - lo + 1 >= 1 << 62, the difference exact in unsigned arithmetic
        if np.uint64(hi[j]) - np.uint64(lo[j]) >= np.uint64(_LIMIT - 1):
            for i in range(n):
                words[m, i] = c[i]
            m += 1
            open_ = False
            span = 0
            continue
        size = hi[j] - lo[j] + 1
        base = lo[j]
        if open_ and size <= (_LIMIT - 1) // span:
            for i in range(n):
                words[m - 1, i] = words[m - 1, i] * size + (c[i] - base)
            span = span * size
        else:
            for i in range(n):
                words[m, i] = c[i] - base
            m += 1
            open_ = True
            span = size
    return words[:m], span


@numba.njit(cache=True, nogil=True)
def sorted_groups(words, order):  # pragma: no cover - compiled
    """The groups of rows whose words are equal, ``order`` sorting them: each row's
    group and the first row (in ``order``) of each."""
    k, n = words.shape
    inverse = np.empty(n, np.int64)
    first = np.empty(n, np.int64)
    g = -1
    for r in range(n):
        i = order[r]
        change = r == 0
        if not change:
            p = order[r - 1]
            for j in range(k):
                if words[j, i] != words[j, p]:
                    change = True
                    break
        if change:
            g += 1
            first[g] = i
        inverse[i] = g
    return inverse, first[:g + 1]


@numba.njit(cache=True, nogil=True)
def dense_groups(word, span):  # pragma: no cover - compiled
    """The groups of a word below ``span`` by a dense count: each row's group (in the
    word's order) and the last row of each."""
    n = len(word)
    first = np.full(span, -1, np.int64)
    for i in range(n):
        first[word[i]] = i
    rank = np.empty(span, np.int64)
    g = 0
    for v in range(span):
        rank[v] = g - 1 if first[v] < 0 else g
        if first[v] >= 0:
            first[g] = first[v]
            g += 1
    inverse = np.empty(n, np.int64)
    for i in range(n):
        inverse[i] = rank[word[i]]
    return inverse, first[:g].copy()


@numba.njit(cache=True, nogil=True)
def dd_sums(starts, count, values):  # pragma: no cover - compiled
    """The double-double sums of :func:`mitld_lp.sensing.rows.fsum_by`: per group its
    running sum, the carried errors and their magnitudes."""
    n = len(starts)
    high = np.empty(n)
    low = np.zeros(n)
    size = np.zeros(n)
    for g in range(n):
        s = starts[g]
        a = values[s]
        lo = 0.0
        sz = 0.0
        for k in range(1, count[g]):
            x = values[s + k]
            t = a + x
            back = t - a
            error = (a - (t - back)) + (x - back)
            a = t
            lo += error
            sz += abs(error)
        high[g] = a
        low[g] = lo
        size[g] = sz
    return high, low, size


@numba.njit(cache=True, nogil=True)
def spread(counts):  # pragma: no cover - compiled
    """For parents with ``counts`` children each: every child's parent and its rank."""
    n = 0
    for c in counts:
        n += c
    parent = np.empty(n, np.int64)
    rank = np.empty(n, np.int64)
    at = 0
    for p in range(len(counts)):
        for r in range(counts[p]):
            parent[at] = p
            rank[at] = r
            at += 1
    return parent, rank


@numba.njit(cache=True, nogil=True)
def scatter_max(out, idx, vals):  # pragma: no cover - compiled
    """``np.maximum.at(out, idx, vals)``."""
    for i in range(len(idx)):
        if vals[i] > out[idx[i]]:
            out[idx[i]] = vals[i]


@numba.njit(cache=True, nogil=True)
def scatter_min(out, idx, vals):  # pragma: no cover - compiled
    """``np.minimum.at(out, idx, vals)``."""
    for i in range(len(idx)):
        if vals[i] < out[idx[i]]:
            out[idx[i]] = vals[i]


@numba.njit(cache=True, nogil=True)
def scatter_add(out, idx, vals):  # pragma: no cover - compiled
    """``np.add.at(out, idx, vals)`` (unsigned: wrapping, as a hash sums)."""
    for i in range(len(idx)):
        out[idx[i]] += vals[i]


@numba.njit(cache=True, nogil=True)
def gather2(table, a, b):  # pragma: no cover - compiled
    """``table[a, b]`` and how many of them are -2 (not made yet)."""
    out = np.empty(len(a), np.int64)
    miss = 0
    for i in range(len(a)):
        v = table[a[i], b[i]]
        out[i] = v
        if v == -2:
            miss += 1
    return out, miss
