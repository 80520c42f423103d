"""The two groupings of a level's undecided hypotheses (:mod:`mitld_lp.sensing.frontier`)
by numba kernels that use the rows' order: the rows come choice by choice (the
hypothesis kernel spreads each choice's outcomes, hypotheses, branches and successors
in turn), so grouping them by observation ``(choice, world, unsensed events, reports)``
sorts each choice's few rows, not the level's millions, and grouping them by
``(observation, hypothesis)`` sorts each observation's handful.

Both give the numbering :func:`mitld_lp.sensing.rows.groups` gives (the groups in the
columns' lexicographic order) and one row of each group (which one is no matter: every
caller reads only the grouped columns from it), so the product is the same to the bit
(tests/test_sensed_level.py).  Imported only where the compiled kernels run
(:func:`mitld_lp.sensing.rows.compiled_on`)."""

from __future__ import annotations

import numpy as np

from mitld_lp.sensing.fsum_kernels import sum_of
from mitld_lp.util import kernel_loader

# numba's cached machine code run without importing numba; numba itself on a miss
# (without PyYAML, the narrow load, the disk cache's lock: kernel_loader.numba_module)
numba = kernel_loader.lazy_numba(globals())

INT = np.int64  # rows.INT (not imported: rows imports this module)
_MAX = 9_223_372_036_854_775_807
"""The largest int64, written out: ``np.iinfo`` in a kernel makes loading it from the
cache import ``numba.np.arraymath``, which imports ``scipy.linalg`` (some 0.2 s of CPU in
a build that has not imported it)."""

__all__ = ["by_observation", "by_observation_bits", "by_hypothesis", "decided_alone",
           "least_counts", "hash_add", "level_hypotheses", "group_shifts"]


@numba.njit(cache=True, nogil=True)
def _runs(c):  # pragma: no cover - compiled
    """Whether ``c`` never decreases."""
    for i in range(1, len(c)):
        if c[i] < c[i - 1]:
            return False
    return True


_SMALL = 24  # up to this many rows sorted by insertion, in place (no allocation)


@numba.njit(cache=True, nogil=True, inline="always")
def _reorder(vals, idx, m, order):  # pragma: no cover - compiled
    """``vals[:m]`` and ``idx[:m]`` taken in ``order``."""
    v = vals[:m][order]
    x = idx[:m][order]
    vals[:m] = v
    idx[:m] = x


@numba.njit(cache=True, nogil=True, inline="always")
def _insertion(vals, idx, m, by_row):  # pragma: no cover - compiled
    """``idx[:m]`` and ``vals[:m]`` sorted together by insertion, by ``vals`` (and
    ``idx`` on ties where ``by_row``)."""
    for r in range(1, m):
        v = vals[r]
        x = idx[r]
        k = r - 1
        while k >= 0 and (vals[k] > v or (by_row and vals[k] == v and idx[k] > x)):
            vals[k + 1] = vals[k]
            idx[k + 1] = idx[k]
            k -= 1
        vals[k + 1] = v
        idx[k + 1] = x


@numba.njit(cache=True, nogil=True)
def _sort(vals, idx, m):  # pragma: no cover - compiled
    """``idx[:m]`` and ``vals[:m]`` sorted together by ``vals``."""
    if m > _SMALL:
        _reorder(vals, idx, m, np.argsort(vals[:m]))
    else:
        _insertion(vals, idx, m, False)


@numba.njit(cache=True, nogil=True)
def _number(vals, idx, m, g, inverse, first):  # pragma: no cover - compiled
    """Number the sorted rows ``idx[:m]`` (values ``vals[:m]``) from group ``g`` on;
    the next group's number."""
    for r in range(m):
        if r == 0 or vals[r] != vals[r - 1]:
            first[g] = idx[r]
            g += 1
        inverse[idx[r]] = g - 1
    return g


@numba.njit(cache=True, nogil=True)
def _block_groups(c, word):  # pragma: no cover - compiled
    """Rows grouped by ``(c, word)``, ``c`` non-decreasing: each row's group, one row of
    each, and the rows in the groups' order (a permutation), a run of one ``c`` at a
    time (:func:`group_run`)."""
    n = len(c)
    inverse = np.empty(n, np.int64)
    first = np.empty(n, np.int64)
    perm = np.empty(n, np.int64)
    vals = np.empty(64, np.int64)
    local = np.empty(64, np.int64)
    seen = np.empty(_SMALL, np.int64)
    where = np.empty(_SMALL, np.int64)
    g = 0
    i = 0
    while i < n:
        j = _run_end(c, i)
        g, vals, local = group_run(word, i, j, g, inverse, first, perm, vals, local, seen,
                                   where)
        i = j
    return inverse, first[:g].copy(), perm


@numba.njit(cache=True, nogil=True, inline="always")
def group_run(word, i, j, g, inverse, first, perm, vals, local, seen,
              where):  # pragma: no cover - compiled
    """The rows ``i .. j - 1`` (one choice's) grouped by ``word``, their groups
    numbered from ``g`` in ascending order of their words: each row's group
    (``inverse``), one row of each (``first``), the rows in the groups' order (``perm``,
    stable).  A choice's few distinct words are found by a scan of those met (a sort
    where they are many), sorted, and its rows placed by a counting sort.  Returns the
    next group's number and the scratch arrays ``vals``, ``local`` (grown if needed;
    ``seen``, ``where``: :data:`_SMALL` long)."""
    m = j - i
    if len(vals) < m:
        vals = np.empty(2 * m, np.int64)
        local = np.empty(2 * m, np.int64)
    # seen: a choice's distinct words as met; where: their rank once sorted, then
    # their next slot
    k = 0  # distinct words met
    many = False
    for r in range(m):
        v = word[i + r]
        s = 0
        while s < k and seen[s] != v:
            s += 1
        if s == k:
            if k == _SMALL:
                many = True
                break
            seen[k] = v
            first[g + k] = i + r
            k += 1
        local[r] = s
    if many:
        for r in range(m):
            vals[r] = word[i + r]
            perm[i + r] = i + r
        _sort(vals, perm[i:j], m)
        return _number(vals, perm[i:j], m, np.int64(g), inverse, first), vals, local
    # the distinct words in order: each one's rank among them
    for a in range(k):
        rank = 0
        for b in range(k):
            if seen[b] < seen[a]:
                rank += 1
        where[a] = rank
        vals[rank] = first[g + a]
    for a in range(k):
        first[g + a] = vals[a]
    count = np.zeros(k + 1, np.int64)
    for r in range(m):
        count[where[local[r]] + 1] += 1
    for a in range(k):
        count[a + 1] += count[a]
    for r in range(m):
        rk = where[local[r]]
        perm[i + count[rk]] = i + r
        count[rk] += 1
        inverse[i + r] = g + rk
    return g + k, vals, local


@numba.njit(cache=True, nogil=True)
def _nested_groups(perm, outer, key):  # pragma: no cover - compiled
    """Rows grouped by ``(outer, key)``, ``perm`` the rows ordered by ``outer`` (its
    groups numbered in that order): each row's group and one row of each."""
    n = len(perm)
    inverse = np.empty(n, np.int64)
    first = np.empty(n, np.int64)
    vals = np.empty(64, np.int64)
    idx = np.empty(64, np.int64)
    g = 0
    i = 0
    while i < n:
        o = outer[perm[i]]
        j = i + 1
        while j < n and outer[perm[j]] == o:
            j += 1
        m = j - i
        if len(vals) < m:
            vals = np.empty(2 * m, np.int64)
            idx = np.empty(2 * m, np.int64)
        for r in range(m):
            idx[r] = perm[i + r]
            vals[r] = key[idx[r]]
        _sort(vals, idx, m)
        g = _number(vals, idx, m, np.int64(g), inverse, first)  # one signature
        i = j
    return inverse, first[:g].copy()


def by_observation(kernels, c: np.ndarray, *cols: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """:func:`~mitld_lp.sensing.rows.groups` of ``(c, *cols)`` with the rows in their
    groups' order (``kernels``: :mod:`mitld_lp.sensing.kernels`), or None where ``c``
    is not in order or ``cols`` do not pack into one word (the caller groups them
    itself)."""
    if len(c) == 0 or not _runs(c):
        return None
    words, span = kernels.pack(tuple(np.ascontiguousarray(x, dtype=INT) for x in cols))
    if len(words) != 1:
        return None
    return _block_groups(np.ascontiguousarray(c, dtype=INT), words[0])


@numba.njit(cache=True, nogil=True)
def _observation_word(c, w2, occ, new, nu, ns):  # pragma: no cover - compiled
    """Whether ``c`` never decreases, and each row's observation ``(w2, occ, new)`` as
    one word ``(w2 << nu | occ) << ns | new`` (the same order)."""
    n = len(c)
    word = np.empty(n, np.int64)
    runs = True
    for i in range(n):
        if i and c[i] < c[i - 1]:
            runs = False
        word[i] = ((w2[i] << nu) | occ[i]) << ns | new[i]
    return runs, word


def by_observation_bits(c: np.ndarray, w2: np.ndarray, occ: np.ndarray, new: np.ndarray,
                        nu: int, ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """:func:`by_observation` of ``(c, w2, occ, new)`` with ``occ`` below ``2**nu``,
    ``new`` below ``2**ns`` and ``w2`` non-negative below ``2**(62 - nu - ns)``: the
    word made in one pass from the known widths, not packed from the columns' bounds
    (the same order, so the same groups)."""
    if len(c) == 0:
        return None
    runs, word = _observation_word(c, w2, occ, new, np.int64(nu), np.int64(ns))
    return _block_groups(c, word) if runs else None


def by_hypothesis(perm: np.ndarray, outer: np.ndarray, key: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~mitld_lp.sensing.rows.groups` of ``(outer, key)``, ``perm`` the rows in
    ``outer``'s groups' order (:func:`by_observation`)."""
    return _nested_groups(perm, outer, np.ascontiguousarray(key, dtype=INT))


@numba.njit(cache=True, nogil=True)
def least_counts(counts, tid, group, n_groups):  # pragma: no cover - compiled
    """The rows whose group's least report counts are not all zero and those least
    counts (:meth:`mitld_lp.sensing.merge.Counts.canonical`): ``counts`` each times
    index's counts, ``tid`` each row's, ``group`` each row's group."""
    n, k = len(tid), counts.shape[1]
    least = np.full((n_groups, k), _MAX, np.int64)
    for r in range(n):
        g = group[r]
        t = tid[r]
        for j in range(k):
            v = counts[t, j]
            if v < least[g, j]:
                least[g, j] = v
    moved = np.zeros(n_groups, np.bool_)
    for g in range(n_groups):
        for j in range(k):
            if least[g, j] != 0:
                moved[g] = True
    m = 0
    for r in range(n):
        if moved[group[r]]:
            m += 1
    rows = np.empty(m, np.int64)
    by = np.empty((m, k), np.int64)
    at = 0
    for r in range(n):
        g = group[r]
        if moved[g]:
            rows[at] = r
            for j in range(k):
                by[at, j] = least[g, j]
            at += 1
    return rows, by


@numba.njit(cache=True, nogil=True)
def hash_add(out, idx, codes):  # pragma: no cover - compiled
    """``out[idx] +=`` :func:`mitld_lp.sensing.rows.mix64` of ``codes`` (wrapping, as
    ``np.add.at`` on unsigned words): each group's hash of its hypotheses."""
    for i in range(len(idx)):
        z = np.uint64(codes[i]) + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        out[idx[i]] += z ^ (z >> np.uint64(31))


@numba.njit(cache=True, nogil=True)
def group_shifts(times, tid, group, n_groups, c, c_state, reported, new, clock, events,
                 starts, delays):  # pragma: no cover - compiled
    """Each group's shift of each shiftable sensed event's times
    (:meth:`mitld_lp.sensing.merge.Shifts.canonical`): ``times`` each times index's
    steps, ``tid`` each row's, ``c_state[c]`` its parent state, whose ``reported`` and
    ``clock`` it reads (with the row's ``new`` reports), read here row by row rather
    than gathered into arrays of the level's length first; ``events`` the shiftable
    events, ``starts`` their least places, ``delays`` every sensed event's delay."""
    n, k = len(tid), len(events)
    good = np.ones((n_groups, k), np.bool_)
    least = np.full((n_groups, k), _MAX, np.int64)
    for r in range(n):
        g = group[r]
        t = tid[r]
        st = c_state[c[r]]
        said = reported[st] | new[r]
        for e in range(k):
            i = events[e]
            ki = times[t, i]
            if not (ki > 0 and ((said >> i) & 1 == 1 or ki + delays[i] <= clock[st] + 1)):
                good[g, e] = False
            if ki < least[g, e]:
                least[g, e] = ki
    shift = np.zeros((n_groups, times.shape[1]), np.int64)
    for g in range(n_groups):
        for e in range(k):
            if good[g, e] and least[g, e] > starts[e]:
                shift[g, events[e]] = least[g, e] - starts[e]
    return shift


@numba.njit(cache=True, nogil=True)
def _sort_rows(vals, idx, m):  # pragma: no cover - compiled
    """``idx[:m]`` and ``vals[:m]`` sorted together by ``(vals, idx)``: the rows of one
    key come in their own order."""
    if m <= _SMALL:
        _insertion(vals, idx, m, True)
        return
    for r in range(1, m):  # the rows in their order first (any order before)
        if idx[r] < idx[r - 1]:
            _reorder(vals, idx, m, np.argsort(idx[:m]))
            break
    _reorder(vals, idx, m, np.argsort(vals[:m], kind="mergesort"))  # ties in row order


@numba.njit(cache=True, nogil=True)
def level_hypotheses(perm, obs, n_obs, tid, q, mass, s_seq, rank, nq, need, rep
                     ):  # pragma: no cover - compiled
    """A level's undecided rows (``perm``: the rows in their observation groups' order,
    :func:`by_observation`; ``obs`` each row's group of ``n_obs``) made into the new
    states' hypotheses in one pass over each observation's rows: grouped by
    ``rank[tid] * nq + q`` (:func:`mitld_lp.sensing.rows.groups`' numbering of
    ``(observation, key)``: the hypotheses in InfoState order within each observation),
    each hypothesis's mass summed in the rows' order (as ``np.bincount``), each
    observation's total correctly rounded (as :func:`mitld_lp.sensing.rows.fsum_by`),
    the weights, and per observation its number of hypotheses, the hash of its set (the
    sum of :func:`mitld_lp.sensing.rows.mix64` of the codes ``tid * nq + q``, wrapping)
    and its first row's place ``s_seq``; and per observation ``o`` the largest
    ``need[tid, rep[o]]`` of its hypotheses' times ``tid`` (-1 if none: the clock the
    new state keeps, :meth:`~mitld_lp.sensing.frontier.FrontierBuilder.expand`), read
    from the dense table of :class:`~mitld_lp.sensing.rows.Lookup` (``-2``, or a pair
    outside it: not made yet, left out of ``most``; the caller looks those hypotheses
    up itself, ``missing``).  Returns ``(hfirst, hobs, hcode, hmass, weight, total,
    count, hash, first, most, missing)``."""
    n = len(perm)
    hfirst = np.empty(n, np.int64)
    hobs = np.empty(n, np.int64)
    hcode = np.empty(n, np.int64)
    hmass = np.empty(n)
    weight = np.empty(n)
    total = np.empty(n_obs)
    count = np.zeros(n_obs, np.int64)
    hash_ = np.zeros(n_obs, np.uint64)
    first = np.full(n_obs, _MAX, np.int64)
    most = np.full(n_obs, -1, np.int64)
    missing = 0
    lost = np.empty(n, np.int64)  # the hypotheses whose need is not in the table
    n_tid, n_rep = need.shape
    vals = np.empty(n, np.int64)  # each observation's keys, sorted with their rows
    idx = np.empty(n, np.int64)
    partials = np.empty(64)
    g = 0
    i = 0
    last = -1
    while i < n:
        o = obs[perm[i]]
        if o <= last:
            raise ValueError("level_hypotheses: the rows are not in their groups' order")
        last = o
        j = i + 1
        while j < n and obs[perm[j]] == o:
            j += 1
        m = j - i
        least = _MAX
        for r in range(m):
            x = perm[i + r]
            idx[r] = x
            vals[r] = rank[tid[x]] * nq + q[x]
            if s_seq[x] < least:
                least = s_seq[x]
        first[o] = least
        _sort_rows(vals, idx, m)
        g0 = g
        h = 0
        b = rep[o]
        top = -1
        for r in range(m):
            x = idx[r]
            if r == 0 or vals[r] != vals[r - 1]:
                a = tid[x]
                v = need[a, b] if a < n_tid and b < n_rep else -2
                if v == -2:
                    lost[missing] = g
                    missing += 1
                elif v > top:
                    top = v
                code = a * nq + q[x]
                hfirst[g] = x
                hobs[g] = o
                hcode[g] = code
                hmass[g] = 0.0 + mass[x]  # as np.bincount: from 0.0, in the rows' order
                z = np.uint64(code) + np.uint64(0x9E3779B97F4A7C15)
                z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
                z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
                hash_[o] += z ^ (z >> np.uint64(31))
                g += 1
                h += 1
            else:
                hmass[g - 1] += mass[x]
        count[o] = h
        most[o] = top
        if len(partials) < h + 1:
            partials = np.empty(2 * h + 2)
        t = sum_of(hmass, g0, h, partials)
        total[o] = t
        for e in range(g0, g):
            weight[e] = hmass[e] / t
        i = j
    # no copies: every row is a hypothesis of its own in the bus cases (g = n)
    return (hfirst[:g], hobs[:g], hcode[:g], hmass[:g], weight[:g], total, count, hash_,
            first, most, lost[:missing])


@numba.njit(cache=True, nogil=True, inline="always")
def _run_end(c, i):  # pragma: no cover - compiled
    """The end of the run of rows from ``i`` with ``c[i]``'s value."""
    j = i + 1
    while j < len(c) and c[j] == c[i]:
        j += 1
    return j


@numba.njit(cache=True, nogil=True)
def decided_alone(c, w2, occ, new, end, gc, gw, go, gn, nu, ns):  # pragma: no cover
    """The observations of a level's decided rows (``c, w2, occ, new``, ``c``
    non-decreasing; ``end`` each row's record) that no undecided group has (``gc, gw,
    go, gn``: the groups in lexicographic order), in lexicographic order: each one's
    row of ``c``, ``w2``, ``occ``, ``new``, and its record where every row of it ended
    in one, else -1 (:meth:`mitld_lp.sensing.frontier.FrontierBuilder.record_moves`).
    Returns None where ``c`` decreases (the caller groups the rows itself)."""
    n = len(c)
    for i in range(1, n):
        if c[i] < c[i - 1]:
            return None
    out = np.empty(n, np.int64)  # a row of each observation kept
    rec = np.empty(n, np.int64)
    k = 0
    vals = np.empty(n, np.int64)  # each choice's words, sorted with their rows
    idx = np.empty(n, np.int64)
    u = 0  # the undecided groups met so far
    m_u = len(gc)
    i = 0
    while i < n:
        j = _run_end(c, i)
        m = j - i
        for r in range(m):
            vals[r] = ((w2[i + r] << nu) | occ[i + r]) << ns | new[i + r]
            idx[r] = i + r
        _sort(vals, idx, m)
        while u < m_u and gc[u] < c[i]:
            u += 1
        r = 0
        while r < m:
            s = r + 1
            one = end[idx[r]]
            while s < m and vals[s] == vals[r]:
                if end[idx[s]] != one:
                    one = -1
                s += 1
            v = vals[r]
            while u < m_u and gc[u] == c[i] and (((gw[u] << nu) | go[u]) << ns | gn[u]) < v:
                u += 1
            if not (u < m_u and gc[u] == c[i]
                    and (((gw[u] << nu) | go[u]) << ns | gn[u]) == v):
                out[k] = idx[r]
                rec[k] = one
                k += 1
            r = s
        i = j
    return out[:k].copy(), rec[:k].copy()


@numba.njit(cache=True, nogil=True, inline="always")
def _before(c, o, b, s, i, j):  # pragma: no cover - compiled
    """Whether row ``i`` comes strictly before row ``j`` by ``(c, o, b, s)``."""
    if c[i] != c[j]:
        return c[i] < c[j]
    if o[i] != o[j]:
        return o[i] < o[j]
    if b[i] != b[j]:
        return b[i] < b[j]
    return s[i] < s[j]


@numba.njit(cache=True, nogil=True)
def end_sums(c, o, b, s, r, m, starts):  # pragma: no cover - compiled
    """A level's rows that end in a record (``starts``: the bounds of the lists they
    were concatenated from, each in the loops' order ``(c, o, b, s)``), merged into the
    loops' order (a stable ``np.lexsort`` of the concatenation, ties to the earlier list)
    and grouped by ``(c, r)`` in that lexicographic order: each group's choice, record,
    mass (summed in the loops' order, as ``np.bincount``) and place of its first row
    in the loops' order.  Returns ``ok`` False (and nothing) where a list is not in
    the loops' order (the caller sorts the rows itself)."""
    k = len(starts) - 1
    n = starts[k]
    for t in range(k):
        for i in range(starts[t] + 1, starts[t + 1]):
            if _before(c, o, b, s, i, i - 1):
                z = np.zeros(0, np.int64)
                return False, z, z, np.zeros(0), z
    head = starts[:k].copy()
    g_c = np.empty(n, np.int64)
    g_r = np.empty(n, np.int64)
    g_m = np.empty(n)
    g_p = np.empty(n, np.int64)
    n_rec = 1
    for i in range(n):
        if r[i] + 1 > n_rec:
            n_rec = r[i] + 1
    slot = np.full(n_rec, -1, np.int64)  # each record's place in the current choice
    met = np.empty(n_rec, np.int64)  # the records met in the current choice, as met
    tm = np.empty(n_rec)  # their sums
    tp = np.empty(n_rec, np.int64)  # their first rows' places
    n_met = 0
    g = 0  # groups of the choices done
    cur = -1
    pick = 0
    for p in range(n + 1):
        i = -1
        if p < n:
            for t in range(k):  # the next row: the least head, the earlier list on ties
                if head[t] < starts[t + 1] and (i < 0 or _before(c, o, b, s, head[t], i)):
                    i = head[t]
                    pick = t
            head[pick] += 1
        if p == n or c[i] != cur:  # the choice done: its records in ascending order
            for x in range(n_met):
                e = met[x]
                rank = 0
                for y in range(n_met):
                    if met[y] < e:
                        rank += 1
                g_c[g + rank] = cur
                g_r[g + rank] = e
                g_m[g + rank] = tm[x]
                g_p[g + rank] = tp[x]
                slot[e] = -1
            g += n_met
            n_met = 0
            if p == n:
                break
            cur = c[i]
        e = r[i]
        x = slot[e]
        if x < 0:
            x = slot[e] = n_met
            met[x] = e
            tm[x] = 0.0
            tp[x] = p
            n_met += 1
        tm[x] += m[i]
    return True, g_c[:g].copy(), g_r[:g].copy(), g_m[:g].copy(), g_p[:g].copy()
