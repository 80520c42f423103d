"""Rows of integers grouped, spread and summed without a Python loop per row: the
array operations of the frontier-at-a-time construction
(:mod:`mitld_lp.sensing.frontier`).

Each runs as NumPy lines or, once :func:`load_kernels` has loaded them (the build does
at its first chunk of :data:`COMPILED_MIN_STATES` states), as the numba kernels of
:mod:`mitld_lp.sensing.kernels`, which give the same arrays to the bit."""

from __future__ import annotations

import math
from collections.abc import Hashable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

__all__ = ["groups", "lex_order", "ordered_groups", "spread", "fsum_by", "mix64",
           "pack_words", "Table", "Lookup", "INT", "DENSE", "COMPILED_MIN_STATES",
           "COMPILED_MIN_ESTIMATE", "load_kernels", "running_kernels", "compiled_on",
           "scatter", "small_pages", "narrow", "join_parts", "grown", "merged_entries",
           "MERGE_ENTRIES"]

INT = np.int64
_I = INT
DENSE = 1 << 22
"""The most keys a :class:`Lookup` keeps as a dense array (32 MiB)."""
COMPILED_MIN_STATES = 2_048
"""The states of a chunk from which the build loads the compiled kernels.  Their load
costs some 0.6 s CPU (numba's import 0.2 s, the kernels from numba's disk cache 0.4 s;
their first compile, once per machine, some 8 s) and they save about a third of the
build (0.45 s -> 0.28 s on tests/test_sensing_kernels.py's false-alarm case once
loaded): they pay from a build of some 1.5 s, some 25,000 states.  A level of 2,048
states comes some levels before the largest on the bus cases, whose products hold ten
times that or more; the smaller cases of experiments/bench_sensed.py never load them
(experiments/results/bench_sensed_kernel.md)."""
COMPILED_MIN_ESTIMATE = 8_192
"""The size estimate (:mod:`mitld_lp.sensing.growth`, made at a level's end from the
clock's half-way step on, meant to err low) from which the build loads the kernels
before any chunk reaches :data:`COMPILED_MIN_STATES`: the bus case's camera on bus 2
at epsilon 0.01 estimates 8,918 states at level 7 (1,909 found; 52,498 built), whose
next three levels (4,321 states) take 0.20 s CPU by the NumPy lines and some 0.07 s by
the kernels.  The smaller cases of experiments/bench_sensed.py estimate none this large
and still never load them."""
_K: Any = None  # mitld_lp.sensing.kernels once loaded, False if numba is not installed


def load_kernels() -> bool:
    """Load the compiled kernels (numba imported the first time): whether they run."""
    global _K
    if _K is None:
        try:
            from mitld_lp.sensing import kernels
        except ImportError:
            _K = False
        else:
            _K = kernels
    return bool(_K)


def compiled_on() -> Any:
    """The compiled kernels' module where they run (:func:`load_kernels`), else None."""
    return _K or None


@contextmanager
def running_kernels(on: bool) -> Iterator[bool]:
    """Within it, the compiled kernels run (``on``, numba installed) or the NumPy lines
    (the build's own choice, :data:`COMPILED_MIN_STATES`, suspended); yields whether the
    kernels run."""
    global _K
    before = _K
    _K = None if on else False
    if on:
        load_kernels()
    try:
        yield bool(_K)
    finally:
        _K = before


@contextmanager
def small_pages() -> Iterator[None]:
    """Within it, NumPy does not ask the system for huge pages for its large arrays
    (its default, restored after): a build allocates and drops its levels' rows by the
    hundred megabytes, and each huge page the system zeroes or compacts for them cost
    more system time than the pages save (0.4-1.0 s of the false-alarm case's 8 s,
    measured by ``NUMPY_MADVISE_HUGEPAGE=0``).  The memory's contents, hence every
    result, are the same.  A NumPy without the (private) switch runs as it is."""
    try:
        from numpy._core.multiarray import _set_madvise_hugepage
    except ImportError:  # pragma: no cover - another NumPy
        yield
        return
    before = _set_madvise_hugepage(False)
    try:
        yield
    finally:
        _set_madvise_hugepage(before)


def narrow(x: np.ndarray, copy: bool = False) -> np.ndarray:
    """``x`` (integers) in the narrowest of int8, int16, int32 and int64 that holds
    every value (a copy where narrower; ``copy``: always a copy, never a view of a
    buffer the caller drops): for arrays kept until the build's end or after it."""
    if x.size == 0:
        return x.copy() if copy else x
    lo, hi = int(x.min()), int(x.max())
    for dtype in (np.int8, np.int16, np.int32):
        info = np.iinfo(dtype)
        if info.min <= lo and hi <= info.max:
            return x.astype(dtype)
    return x.copy() if copy else x


def join_parts(parts: list[list[Any]], k: int, dtype: Any) -> np.ndarray:
    """The ``k``-th arrays of ``parts`` joined in order as ``dtype``, each dropped from
    its part once copied (a build's transitions are not held twice over)."""
    out = np.empty(sum(len(p[k]) for p in parts), dtype)
    at = 0
    for p in parts:
        out[at:at + len(p[k])] = p[k]
        at += len(p[k])
        p[k] = None
    return out


def grown(x: np.ndarray, used: int, size: int) -> np.ndarray:
    """``x``'s first ``used`` values in a new array of ``size`` (at least ``used``) of
    its dtype, the rest never written: where NumPy maps a large array, the system gives
    the tail's pages only when first written (``np.resize`` writes them all)."""
    out = np.empty(size, x.dtype)
    out[:used] = x[:used]
    return out


def scatter(op: str, out: np.ndarray, idx: np.ndarray, vals: np.ndarray) -> None:
    """``np.maximum.at``, ``np.minimum.at`` or ``np.add.at`` (``op``: ``max``, ``min``,
    ``add``) of ``vals`` into ``out`` at ``idx``."""
    if _K:
        getattr(_K, "scatter_" + op)(out, idx, vals)
    else:
        {"max": np.maximum, "min": np.minimum, "add": np.add}[op].at(out, idx, vals)


def pack_words(cols: tuple[np.ndarray, ...]) -> tuple[list[np.ndarray], int]:
    """The columns packed into as few int64 words as keep their lexicographic order
    (each column shifted to start at 0, in mixed radix while the product fits), and the
    last word's span (0 for a hash, kept as it is in a word of its own)."""
    words: list[np.ndarray] = []
    word, span = None, 1
    for c in cols:
        lo, hi = int(c.min()), int(c.max())
        size = hi - lo + 1
        if size >= 1 << 62:
            if word is not None:
                words.append(word)
            words.append(c.astype(_I, copy=False))
            word, span = None, 0
            continue
        v = c.astype(_I) - lo
        if word is not None and span * size < 1 << 62:
            word, span = word * size + v, span * size
        else:
            if word is not None:
                words.append(word)
            word, span = v, size
    if word is not None:
        words.append(word)
    return words, span


def lex_order(*cols: np.ndarray) -> np.ndarray:
    """``np.lexsort(cols[::-1])``: the rows' stable order by the first column, then the
    second, and so on; the columns packed into one word where they fit
    (:func:`pack_words`) and that word sorted stably, which is the same order (a
    level's columns come in sorted runs, which the stable sort merges in a pass, where
    ``np.lexsort`` sorts each column in turn)."""
    if len(cols[0]) == 0:
        return np.zeros(0, np.intp)
    words, _ = pack_words(cols)
    if len(words) == 1:
        return np.argsort(words[0], kind="stable")
    return np.lexsort(words[::-1])


def groups(*cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows grouped by equal values in every column: each row's group (numbered in the
    columns' lexicographic order) and one row of each group (every caller reads only
    the grouped columns from it, equal across the group)."""
    n = len(cols[0])
    if n == 0:
        return np.zeros(0, _I), np.zeros(0, _I)
    if _K:
        return _compiled_groups(cols, n)
    words, span = pack_words(cols)
    if len(words) == 1 and 0 < span <= max(4 * n, 1 << 16):  # a dense count, no sort
        word = words[0]
        first = np.full(span, -1, _I)
        first[word] = np.arange(n, dtype=_I)  # a row of each group (any one will do)
        present = first >= 0
        rank = np.cumsum(present) - 1
        return rank[word], first[present]
    order = (np.argsort(words[0], kind="stable") if len(words) == 1
             else np.lexsort(words[::-1]))
    change = np.zeros(n, dtype=bool)
    change[0] = True
    for c in words:
        s = c[order]
        change[1:] |= s[1:] != s[:-1]
    inverse = np.empty(n, _I)
    inverse[order] = np.cumsum(change) - 1
    return inverse, order[change]


def ordered_groups(*cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`groups` of rows that come in the order of their first column (a level's
    rows come choice by choice): by the kernels, each run of one first value sorted
    apart (:func:`mitld_lp.sensing.group_kernels.by_observation`), else as
    :func:`groups`."""
    if _K:
        from mitld_lp.sensing.group_kernels import by_observation

        found = by_observation(_K, cols[0], *cols[1:])
        if found is not None:
            return found[0], found[1]
    return groups(*cols)


def _compiled_groups(cols: tuple[np.ndarray, ...], n: int) -> tuple[np.ndarray,
                                                                       np.ndarray]:
    """:func:`groups` by the kernels: the same packing, sort and numbering."""
    words, span = _K.pack(tuple(np.ascontiguousarray(c, dtype=_I) for c in cols))
    if len(words) == 1 and 0 < span <= max(4 * n, 1 << 16):
        return _K.dense_groups(words[0], span)
    order = (np.argsort(words[0], kind="stable") if len(words) == 1
             else np.lexsort(words[::-1]))
    return _K.sorted_groups(words, order)


def fsum_by(ids: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """The sum of ``values`` per id (``ids`` sorted, every id in ``0 .. n - 1`` present),
    correctly rounded as :func:`math.fsum`.  Summed term by term in double-double
    (each addition's rounding error found by Knuth's two-sum and carried), then
    rounded once: that is the correctly rounded sum unless the exact sum may lie within
    the carried errors' own rounding of a point halfway between two floats, and those
    few sums are redone by :func:`math.fsum`."""
    count = np.bincount(ids, minlength=n)
    starts = np.cumsum(count) - count
    if _K:
        high, low, size = _K.dd_sums(starts, count, values)
    else:
        high, low, size = _dd_sums(starts, count, values)
    out = high + low
    back = out - high
    rest = (high - (out - back)) + (low - back)  # high + low - out, exactly
    # half the gap to the next float on the rest's side (below a power of two, the gap
    # is half the one above)
    half = np.spacing(out) / 2
    half[(rest < 0) & (np.frexp(out)[0] == 0.5)] /= 2
    unsure = np.abs(rest) + 4.0 * count * 2.0**-52 * size >= half
    redo = np.flatnonzero(unsure & (count > 2))
    if len(redo):
        out[redo] = [math.fsum(values[a:a + k].tolist()) for a, k in zip(
            starts[redo].tolist(), count[redo].tolist(), strict=True)]
    return out


def _dd_sums(starts: np.ndarray, count: np.ndarray, values: np.ndarray) -> tuple[
        np.ndarray, np.ndarray, np.ndarray]:
    """Each group's running sum, carried errors and their magnitudes, a term at a time
    over all groups (:func:`fsum_by`)."""
    n = len(starts)
    high = values[starts].copy()
    low = np.zeros(n)
    size = np.zeros(n)  # the errors' magnitudes, for the bound on low's own rounding
    live = np.arange(n, dtype=_I)
    for k in range(1, int(count.max(initial=0))):
        live = live[count[live] > k]
        a, x = high[live], values[starts[live] + k]
        t = a + x
        back = t - a
        error = (a - (t - back)) + (x - back)
        high[live] = t
        low[live] += error
        size[live] += np.abs(error)
    return high, low, size


MERGE_ENTRIES = True
"""Whether :func:`merged_entries` merges (tests/test_sensed_merged_entries.py builds
without it to compare)."""


def merged_entries(c: np.ndarray, first: np.ndarray, target: np.ndarray,
                   total: np.ndarray) -> tuple[np.ndarray, ...]:
    """A level's entries into information states, one per observation: choice ``c``,
    the observation's first row ``first``, its state ``target`` and mass ``total``, with
    the entries of one choice into one state made one, at the place of the first and
    with their masses summed left to right in the order of their places, as one state at
    a time sums them into its row (tests/test_sensing_build.py), and the other entries
    as they are.  Several observations lead to one state where they differ only in what
    the state does not keep: with false alarms a report is not kept as reported (each
    hypothesis's count of reports is, made canonical by merge.py's ``Counts``), so a
    step with a report and one without meet wherever the counts come out the same: 41%
    of the transitions of experiments/bench_sensed.py's camera with false alarms (5.31
    -> 3.13 million), which every sweep of the solve read."""
    if not MERGE_ENTRIES or len(c) < 2:
        return c, first, target, total
    order = lex_order(c, target, first)
    cs, ts = c[order], target[order]
    head = np.ones(len(c), dtype=bool)
    head[1:] = (cs[1:] != cs[:-1]) | (ts[1:] != ts[:-1])
    if head.all():
        return c, first, target, total
    # bincount adds in the array's order: each sum left to right, from 0.0 (exact)
    sums = np.bincount(np.cumsum(head) - 1, weights=total[order])
    keep = order[head]
    return c[keep], first[keep], target[keep], sums


def spread(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For parents with ``counts`` children each: every child's parent and its rank."""
    if _K:
        return _K.spread(np.ascontiguousarray(counts, dtype=_I))
    parent = np.repeat(np.arange(len(counts), dtype=_I), counts)
    starts = np.cumsum(counts) - counts
    return parent, np.arange(len(parent), dtype=_I) - starts[parent]


def mix64(x: np.ndarray) -> np.ndarray:
    """A 64-bit mix of each value (splitmix64's finaliser), summed into a set's hash."""
    z = x.astype(np.uint64) + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


class Table:
    """Entries of variable number per key, each key's entries computed once (a Python
    call) and kept as flat numpy columns: :meth:`rows` gives, for an array of keys'
    indices, each entry's parent and the entry columns."""

    def __init__(self, width: int, dtypes: tuple[Any, ...]) -> None:
        self.dtypes = dtypes
        self.width = width
        self.clear()

    def clear(self) -> None:
        """Every key and entry dropped (a build's end: nothing looks them up after)."""
        self.index: dict[Hashable, int] = {}
        self.entries: list[tuple[np.ndarray, ...]] = []
        self.flat_cols: tuple[np.ndarray, ...] = tuple(np.zeros(0, d) for d in self.dtypes)
        self.flat_start = np.zeros(0, _I)
        self.flat_len = np.zeros(0, _I)

    def flat(self) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, ...]]:
        """Every key's entries as flat columns: each key's first entry's place in them,
        its number of entries, and the columns (grown as keys come)."""
        done = len(self.flat_start)
        if done < len(self.entries):
            new = self.entries[done:]
            counts = np.array([len(e[0]) for e in new], _I)
            at = len(self.flat_cols[0])
            self.flat_start = np.concatenate([self.flat_start,
                                              at + np.cumsum(counts) - counts])
            self.flat_len = np.concatenate([self.flat_len, counts])
            self.flat_cols = tuple(np.concatenate([self.flat_cols[c]] + [e[c] for e in new])
                                   for c in range(self.width))
        return self.flat_start, self.flat_len, self.flat_cols

    def find(self, cols: tuple[np.ndarray, ...], make: Any) -> np.ndarray:
        """The table index of each row's key (the row's values in ``cols``), ``make``
        called once for each key not met before."""
        ids, first = groups(*cols)
        out = np.empty(len(first), _I)
        for n, key in enumerate(zip(*(c[first].tolist() for c in cols), strict=True)):
            i = self.index.get(key)
            if i is None:
                rows = make(key)
                i = self.index[key] = len(self.entries)
                self.entries.append(tuple(np.asarray([r[c] for r in rows], dtype=d)
                                          for c, d in enumerate(self.dtypes)))
            out[n] = i
        return out[ids]

    def rows(self, which: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        """``which``: a table index per parent row; the children's parents and columns
        (read from the flat columns: no Python loop over the keys used)."""
        starts, lengths, cols = self.flat()
        which = np.asarray(which, _I)
        parent, rank = spread(lengths[which])
        at = starts[which][parent] + rank
        return parent, [c[at] for c in cols]


class Lookup:
    """Small integers (``>= -1``) by pairs of small integers ``(a, b)``, each pair's
    value made once by ``make(a, b)`` (a Python call) and kept in a dict, and also as a
    dense array while the pairs' box stays within :data:`DENSE` keys (grown by doubling
    as larger keys come): :meth:`__call__` looks up a row of pairs at a time."""

    def __init__(self, make: Any) -> None:
        self.make = make
        self.table: dict[tuple[int, int], int] = {}
        self.dense: np.ndarray | None = None

    def __call__(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """The value of each row's pair ``(a, b)``."""
        if len(a) == 0:
            return np.zeros(0, _I)
        shape = (int(a.max()) + 1, int(b.max()) + 1)
        dense = self.dense
        if dense is None or dense.shape[0] < shape[0] or dense.shape[1] < shape[1]:
            old = (0, 0) if dense is None else dense.shape
            if max(shape[0], old[0]) * max(shape[1], old[1]) > DENSE:
                return self.sparse(a, b)
            size = tuple(max(s, 2 * o if s > o else o) for s, o in zip(shape, old,
                                                                         strict=True))
            if size[0] * size[1] > DENSE:
                size = (max(shape[0], old[0]), max(shape[1], old[1]))
            grown = np.full(size, -2, _I)  # -2: not asked yet
            if dense is not None:
                grown[:old[0], :old[1]] = dense
            dense = self.dense = grown
        if _K:
            values, n_miss = _K.gather2(dense, a, b)
            miss = np.flatnonzero(values == -2) if n_miss else ()
        else:
            values = dense[a, b]
            miss = np.flatnonzero(values == -2)
        if len(miss):
            found = self.sparse(a[miss], b[miss])
            dense[a[miss], b[miss]] = found
            values[miss] = found
        return values

    def sparse(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """:meth:`__call__` through the dict alone."""
        ids, first = groups(a, b)
        values = np.empty(len(first), _I)
        table, make = self.table, self.make
        for n, (x, y) in enumerate(zip(a[first].tolist(), b[first].tolist(), strict=True)):
            v = table.get((x, y))
            if v is None:
                v = table[(x, y)] = make(x, y)
            values[n] = v
        return values[ids]
