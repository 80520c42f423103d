"""The numba kernels of :mod:`mitld_lp.sensing.rows` (imported only from there, and only
for a build whose rows are many enough to pay numba's load; compiled once, cached on
disk).  Each does what the NumPy lines it replaces do, with the same floating-point
operations in the same order, so a product is the same to the bit either way
(tests/test_sensing_kernels.py)."""

from __future__ import annotations

import numpy as np

from mitld_lp.sensing.group_kernels import _SMALL, group_run
from mitld_lp.util import kernel_loader

# numba's cached machine code run without importing numba; numba itself on a miss
# (without PyYAML, the narrow load, the disk cache's lock: kernel_loader.numba_module)
numba = kernel_loader.lazy_numba(globals())

__all__ = ["pack", "sorted_groups", "dense_groups", "dd_sums", "spread", "scatter_max",
           "scatter_min", "scatter_add", "gather2", "key_match", "key_rehash", "verify"]

_LIMIT = 1 << 62


def pack(cols: tuple[np.ndarray, ...]) -> tuple[np.ndarray, int]:
    """:func:`mitld_lp.sensing.rows.pack_words` on a tuple of int64 columns (contiguous):
    the words as the rows of an array, and the last word's span.  A column at a time,
    by kernels of one signature each: a kernel taking the tuple was compiled once for
    each number of columns (five in the test suite, 4.7 s of CPU on a cold cache).  The
    same integer arithmetic, column by column, so the same words."""
    k = len(cols)
    n = len(cols[0])
    words = np.empty((k, n), np.int64)
    m = 0  # the words begun
    open_ = False  # whether the last one takes more columns
    span = 1
    for c in cols:
        lo, hi = _bounds(c) if n else (0, 0)
        lo, hi = int(lo), int(hi)
        if hi - lo >= _LIMIT - 1:  # hi - lo + 1 >= 1 << 62: kept as it is
            words[m] = c
            m += 1
            open_ = False
            span = 0
            continue
        size = hi - lo + 1
        if open_ and size <= (_LIMIT - 1) // span:
            _fold(words[m - 1], c, size, lo)
            span = span * size
        else:
            _shift(words[m], c, lo)
            m += 1
            open_ = True
            span = size
    return words[:m], span


@numba.njit(cache=True, nogil=True)
def _bounds(c):  # pragma: no cover - compiled
    """The least and the largest value of ``c`` (not empty)."""
    a = c[0]
    b = c[0]
    for i in range(1, len(c)):
        v = c[i]
        if v < a:
            a = v
        elif v > b:
            b = v
    return a, b


@numba.njit(cache=True, nogil=True)
def _fold(word, c, size, base):  # pragma: no cover - compiled
    """``word`` times ``size`` plus ``c - base``, in place (the next digit of a word)."""
    for i in range(len(c)):
        word[i] = word[i] * size + (c[i] - base)


@numba.njit(cache=True, nogil=True)
def _shift(word, c, base):  # pragma: no cover - compiled
    """``word = c - base`` (a word's first digit)."""
    for i in range(len(c)):
        word[i] = c[i] - base


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


def dd_sums(starts: np.ndarray, count: np.ndarray, values: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_dd_sums` on float64 values, integer ones cast to float64 where every sum
    of them is exact in float64 (the largest magnitude times their number below
    2**53): each addition is then exact, its error 0, and the sums are the integer
    ones rounded once, as on int64 values, to the bit.  The kernel is so compiled for
    one type of values (it was for int64 and float64 in the test suite)."""
    if values.dtype.kind in "iu" and (
            values.size == 0
            or max(abs(int(values.min())), abs(int(values.max()))) * values.size < 2**53):
        values = values.astype(np.float64)
    return _dd_sums(starts, count, values)


@numba.njit(cache=True, nogil=True)
def _dd_sums(starts, count, values):  # pragma: no cover - compiled
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


@numba.njit(cache=True, nogil=True)
def hypothesis_rows(o_c, o_st, o_occ, o_pu, o_seq, o_succ, hstart, hcount, hyp_code,
                    hyp_weight, nq, h0, h_branch, b_start, b_len, b_tid, b_new, b_pc, b_cut,
                    b_now, b_wait, s_start, s_len, s_w2, s_pg, world_label, u_atoms,
                    s_atoms, pending, nu, step, ends, ns, work, work_m
                    ):  # pragma: no cover - compiled
    """The loops of :meth:`mitld_lp.sensing.frontier.FrontierBuilder.hypothesis_rows`
    (its rows in its order, the same products): per outcome row (``o_*``; ``o_succ``
    its key in the successors' table), its state's hypotheses (``h_branch[h - h0]``:
    each one's key in the branches' table), their branches (``b_*``), the world's
    successors (``s_*``); ``step``, ``ends``: the automaton's step and where a
    hypothesis ends as dense tables (-2, or a key outside them: not made yet).
    Returns the cut rows, the decided rows, the undecided rows, and the keys not made
    yet: of ``step`` (automaton state, label) and, where every step was found, of
    ``ends`` (automaton state, events left); with any, the rows are not to be read.
    ``work`` (19 rows) and ``work_m`` (2 rows) hold the decided and undecided rows
    where they are long enough (else new ones, twice as long, are made and returned
    last): a level's rows land in pages the previous level's already touched, not in
    fresh ones the system must zero (half a million page faults, some 0.8 s of system
    time, on the false-alarm case's 29 million rows).  With ``ns >= 0`` (an
    observation fits one word, :func:`mitld_lp.sensing.compiled.observations`) and
    ``o_c`` non-decreasing, each choice's undecided rows are also grouped by
    observation as soon as they are made (:func:`~mitld_lp.sensing.group_kernels.
    group_run`: each row's group, one row of each, the rows in the groups' order, as
    :func:`~mitld_lp.sensing.group_kernels.by_observation_bits` gives them), while
    they are in the cache; the number of groups is -1 where they were not."""
    n3 = 0
    n4 = 0
    for r in range(len(o_c)):
        st = o_st[r]
        for h in range(hstart[st], hstart[st] + hcount[st]):
            k = h_branch[h - h0]
            for e in range(b_start[k], b_start[k] + b_len[k]):
                n3 += 1
                if not b_cut[e]:
                    n4 += s_len[o_succ[r]]
    cut_c = np.empty(n3, np.int64)
    cut_o = np.empty(n3, np.int64)
    cut_b = np.empty(n3, np.int64)
    cut_m = np.empty(n3)
    if work.shape[1] < n4:
        work = np.empty((19, 2 * n4), np.int64)
        work_m = np.empty((2, 2 * n4))
    d_i = work[:7]  # c, o, b, s, end, world, occurred
    d_new = work[7]
    d_m = work_m[0]
    u_i = work[8:15]  # c, occurred, world, reported, times, q, place
    u_m = work_m[1]
    inverse, first, perm, word = work[15], work[16], work[17], work[18]
    vals = np.empty(64, np.int64)  # group_run's scratch
    local = np.empty(64, np.int64)
    seen = np.empty(_SMALL, np.int64)
    where = np.empty(_SMALL, np.int64)
    grouping = ns >= 0
    for r in range(1, len(o_c)):
        if o_c[r] < o_c[r - 1]:
            grouping = False
    g = 0
    u0 = 0
    miss_a = np.empty(n4, np.int64)
    miss_b = np.empty(n4, np.int64)
    n_cut = 0
    n_done = 0
    n_und = 0
    n_step = 0
    n_end = 0
    b = -1
    s = -1
    for r in range(len(o_c)):
        st = o_st[r]
        c = o_c[r]
        occ = o_occ[r]
        pu = o_pu[r]
        if r == 0 or c != o_c[r - 1]:
            u0 = n_und  # the choice's first undecided row
        left0 = pending[st] & ~occ
        hu = u_atoms[occ]
        sw = o_succ[r]
        for h in range(hstart[st], hstart[st] + hcount[st]):
            q = hyp_code[h] % nq
            w = hyp_weight[h]
            k = h_branch[h - h0]
            for e in range(b_start[k], b_start[k] + b_len[k]):
                b += 1
                base = w * pu * b_pc[e]
                if b_cut[e]:
                    cut_c[n_cut] = c
                    cut_o[n_cut] = o_seq[r]
                    cut_b[n_cut] = b
                    cut_m[n_cut] = base
                    n_cut += 1
                    continue
                happened = hu | s_atoms[b_now[e]]
                left = left0 | (b_wait[e] << nu)
                for f in range(s_start[sw], s_start[sw] + s_len[sw]):
                    s += 1
                    w2 = s_w2[f]
                    label = world_label[w2] | happened
                    q2 = -2
                    if q < step.shape[0] and label < step.shape[1]:
                        q2 = step[q, label]
                    if q2 == -2:
                        miss_a[n_step] = q
                        miss_b[n_step] = label
                        n_step += 1
                        continue
                    if n_step:
                        continue
                    end = -2
                    if q2 < ends.shape[0] and left < ends.shape[1]:
                        end = ends[q2, left]
                    if end == -2:
                        miss_a[n_end] = q2
                        miss_b[n_end] = left
                        n_end += 1
                        continue
                    if n_end:
                        continue
                    mass = base * s_pg[f]
                    if end >= 0:
                        d_i[0, n_done] = c
                        d_i[1, n_done] = o_seq[r]
                        d_i[2, n_done] = b
                        d_i[3, n_done] = s
                        d_i[4, n_done] = end
                        d_i[5, n_done] = w2
                        d_i[6, n_done] = occ
                        d_new[n_done] = b_new[e]
                        d_m[n_done] = mass
                        n_done += 1
                    else:
                        u_i[0, n_und] = c
                        u_i[1, n_und] = occ
                        u_i[2, n_und] = w2
                        u_i[3, n_und] = b_new[e]
                        u_i[4, n_und] = b_tid[e]
                        u_i[5, n_und] = q2
                        u_i[6, n_und] = s
                        u_m[n_und] = mass
                        n_und += 1
        if (grouping and n_step == 0 and n_end == 0 and n_und > u0
                and (r + 1 == len(o_c) or o_c[r + 1] != c)):  # the choice's rows made
            for x in range(u0, n_und):
                word[x] = ((u_i[2, x] << nu) | u_i[1, x]) << ns | u_i[3, x]
            g, vals, local = group_run(word, u0, n_und, g, inverse, first, perm, vals,
                                       local, seen, where)
    n_miss = n_step if n_step else n_end
    if not grouping or n_und == 0:
        g = -1
    return (cut_c[:n_cut], cut_o[:n_cut], cut_b[:n_cut], cut_m[:n_cut],
            d_i[:, :n_done], d_new[:n_done], d_m[:n_done], u_i[:, :n_und], u_m[:n_und],
            n_step > 0, miss_a[:n_miss], miss_b[:n_miss], g, inverse[:n_und],
            first[:max(g, 0)], perm[:n_und], work, work_m)


@numba.njit(cache=True, nogil=True, inline="always")
def _key_hash(keys, i):  # pragma: no cover - compiled
    """The hash of key ``i``, the column ``keys[:, i]`` (the keys stored a column of
    each, as the columns they come from: stacked without a strided copy)."""
    h = np.uint64(0x9E3779B97F4A7C15)
    for j in range(keys.shape[0]):
        z = h ^ np.uint64(keys[j, i])
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        h = z ^ (z >> np.uint64(31))
    return h


@numba.njit(cache=True, nogil=True)
def key_rehash(slots, keys, n):  # pragma: no cover - compiled
    """The first ``n`` keys (columns of ``keys``) entered into the empty ``slots`` (a
    power of two of them, -1 each; linear probing)."""
    mask = np.uint64(len(slots) - 1)
    for e in range(n):
        s = _key_hash(keys, e) & mask
        while slots[s] >= 0:
            s = (s + np.uint64(1)) & mask
        slots[s] = e


@numba.njit(cache=True, nogil=True)
def key_match(slots, keys, state, n, rows):  # pragma: no cover - compiled
    """:meth:`mitld_lp.sensing.keys.Keys.match` on the table of ``n`` keys (``keys``,
    a column each, their ``state``, ``slots`` their places by hash, room made for every
    row): each row (a column of ``rows``)'s state, ``-1 - k`` for the ``k``-th key new
    (entered with it), the first row of each new key, and the keys now held."""
    width, m = rows.shape
    mask = np.uint64(len(slots) - 1)
    out = np.empty(m, np.int64)
    reps = np.empty(m, np.int64)
    fresh = 0
    for i in range(m):
        s = _key_hash(rows, i) & mask
        while True:
            e = slots[s]
            if e < 0:
                slots[s] = n
                for j in range(width):
                    keys[j, n] = rows[j, i]
                state[n] = -1 - fresh
                out[i] = -1 - fresh
                reps[fresh] = i
                fresh += 1
                n += 1
                break
            same = True
            for j in range(width):
                if keys[j, e] != rows[j, i]:
                    same = False
                    break
            if same:
                out[i] = state[e]
                break
            s = (s + np.uint64(1)) & mask
    return out, reps[:fresh], n


@numba.njit(cache=True, nogil=True)
def verify(starts, count, hobs, hcode, weight, hyp_code, hyp_weight):  # pragma: no cover
    """:meth:`mitld_lp.sensing.frontier.FrontierBuilder.verify`'s comparisons in one
    pass: whether a group's hypotheses differ from its state's (the ``k``-th row of
    group ``hobs`` against hypothesis ``starts[g] + k``), the largest weight gap and
    its first row."""
    at = np.empty(len(count), np.int64)  # each group's first row
    s = 0
    for g in range(len(count)):
        at[g] = s
        s += count[g]
    worst = 0.0
    worst_row = -1
    for i in range(len(hobs)):
        g = hobs[i]
        h = starts[g] + i - at[g]
        if hyp_code[h] != hcode[i]:
            return True, worst, worst_row
        gap = abs(hyp_weight[h] - weight[i])
        if gap > worst or worst_row < 0:
            worst = gap
            worst_row = i
    return False, worst, worst_row
