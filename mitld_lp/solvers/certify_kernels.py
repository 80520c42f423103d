"""The numba kernel of the certificates' Bellman check (:mod:`mitld_lp.solvers.
certify`), run through :mod:`mitld_lp.util.kernel_loader` and only where a compiled
kernel's load is paid already (:func:`~mitld_lp.util.kernel_loader.compiled_paid`).

:func:`bellman_rows` decides, row by row, what :func:`~mitld_lp.solvers.certify.
_rows_pass` decides with NumPy: a row passes when its float sum, bounded by the
rounding's factors (``(s + slack) * high`` above, ``max((s - slack) * low, 0)``
below, :func:`~mitld_lp.solvers.rounding.above` / ``below``), is on the right side of
the state's own value, or else when the extreme of ``x`` over the row's stored entries
is (the convex rule).  The sum is SciPy's product's: from 0, in the entries' order, one
product and one addition a term, so the same bits; the extreme is exact in any order.
NumPy's rule settles some rows by ``x``'s own extremes first (:func:`~mitld_lp.solvers.
certify._rule_values`): each of those shortcuts is the support's extreme compared with
the own value, which the kernel reads directly, so every row gets the same verdict.
"""

from __future__ import annotations

import numpy as np

from mitld_lp.util import kernel_loader

# numba's cached machine code run without importing numba; numba itself on a miss
numba = kernel_loader.lazy_numba(globals())

__all__ = ["bellman_rows", "chain_blocks", "chain_parts", "chain_sets", "cycling"]


@numba.njit(cache=True, nogil=True)
def bellman_rows(states, groups, nature, indptr, indices, data, x, count, slack_of,
                 factor_of, free, upper, ok):  # pragma: no cover - compiled
    """Per row of the ``states``' choices (their rows one after the other, in the
    states' order: the order of :meth:`~mitld_lp.solvers.certify_repair.Rows.rows_of`),
    whether it passes the pre- (``upper``) or sub-fixed point check of the state's
    value ``x[s]`` (module docs); every row of a ``free`` state passes.  ``groups``:
    each state's first choice; ``nature``: each choice's first row (empty: a row a
    choice).  Written into ``ok``; returns the rows written."""
    has_nature = nature.shape[0] > 0
    pos = 0
    for i in range(states.shape[0]):
        s = states[i]
        lo = groups[s]
        hi = groups[s + 1]
        if has_nature:
            lo = nature[lo]
            hi = nature[hi]
        own = x[s]
        if free[s]:
            for _r in range(lo, hi):
                ok[pos] = True
                pos += 1
            continue
        for r in range(lo, hi):
            acc = 0.0
            for e in range(indptr[r], indptr[r + 1]):
                acc += data[e] * x[indices[e]]
            k = count[r]
            if upper:
                bound = (acc + slack_of[k]) * factor_of[k]
                good = bound <= own
            else:
                bound = (acc - slack_of[k]) * factor_of[k]
                if bound < 0.0:
                    bound = 0.0
                good = bound >= own
            if not good:
                if upper:
                    ext = -np.inf
                    for e in range(indptr[r], indptr[r + 1]):
                        v = x[indices[e]]
                        if v > ext:
                            ext = v
                    good = ext <= own
                else:
                    ext = np.inf
                    for e in range(indptr[r], indptr[r + 1]):
                        v = x[indices[e]]
                        if v < ext:
                            ext = v
                    good = ext >= own
            ok[pos] = good
            pos += 1
    return pos


@numba.njit(cache=True, nogil=True)
def chain_sets(states, rows, indptr, indices, data, target, never, sure):  # pragma: no cover
    """The sets of a policy's chain that its graph decides
    (:func:`~mitld_lp.solvers.certify_chain.chain`): the chain's edges are the positive
    stored entries of row ``rows[i]`` out of state ``states[i]`` (the other states have
    none); ``never``: the states with no path to a ``target`` state, ``sure``: those
    with no path to a ``never`` state.  The edges reversed once by a counting sort,
    then two breadth-first searches from the seeds: which edges exist is all that is
    read, so the sets are those of the NumPy searches.  Written into ``never`` and
    ``sure`` (bool, a state each)."""
    n = target.shape[0]
    # each head's count of edges, then the end of its sources; filled from the ends
    # down, so that the pointers become each head's start (the caller checks that
    # the edges and states fit an int32)
    ptr = np.zeros(n + 1, dtype=np.int32)
    for i in range(states.shape[0]):
        r = rows[i]
        for e in range(indptr[r], indptr[r + 1]):
            if data[e] > 0.0:
                ptr[indices[e] + 1] += 1
    for j in range(n):
        ptr[j + 1] += ptr[j]
    src = np.empty(ptr[n], dtype=np.int32)
    for i in range(states.shape[0]):
        r = rows[i]
        s = states[i]
        for e in range(indptr[r], indptr[r + 1]):
            if data[e] > 0.0:
                c = indices[e] + 1
                ptr[c] -= 1
                src[ptr[c]] = s
    # (now ptr[j + 1] is head j's start and ptr[j + 2] its end: shifted by one)
    queue = np.empty(n, dtype=np.int32)
    for side in range(2):
        seen = np.zeros(n, dtype=np.bool_)
        head = 0
        tail = 0
        for j in range(n):
            if (target[j] if side == 0 else never[j]):
                seen[j] = True
                queue[tail] = j
                tail += 1
        while head < tail:
            j = queue[head]
            head += 1
            for e in range(ptr[j + 1], ptr[j + 2] if j + 2 <= n else src.shape[0]):
                s = src[e]
                if not seen[s]:
                    seen[s] = True
                    queue[tail] = s
                    tail += 1
        for j in range(n):
            if side == 0:
                never[j] = not seen[j]
            else:
                sure[j] = not seen[j]


@numba.njit(cache=True, nogil=True)
def chain_parts(states, rows, indptr, indices, data, target, never,
                sure):  # pragma: no cover - compiled
    """:func:`chain_sets`, then in the same call what
    :func:`~mitld_lp.solvers.certify_chain.chain` gathers with NumPy for the solve: the
    ``solved`` states (acting, neither ``never`` nor ``sure``; ``states`` increasing, so
    in increasing order), each one's mass into ``sure`` (``b``: its positive entries
    there summed from 0 in the row's order, as ``np.bincount`` adds its weights) and its
    positive entries into solved states (their values, and their columns as positions
    among the solved states, in the row's order: the chain ``sub`` as CSR).  Returns
    ``(idx, b, vals, cols, ptr)``, the indices int32 (the caller checks that states and
    entries fit)."""
    chain_sets(states, rows, indptr, indices, data, target, never, sure)
    n = target.shape[0]
    at = np.full(n, -1, dtype=np.int32)
    k = 0
    entries = 0
    for i in range(states.shape[0]):
        s = states[i]
        if not never[s] and not sure[s]:
            at[s] = k
            k += 1
    for i in range(states.shape[0]):
        if at[states[i]] < 0:
            continue
        r = rows[i]
        for e in range(indptr[r], indptr[r + 1]):
            if data[e] > 0.0 and at[indices[e]] >= 0:
                entries += 1
    idx = np.empty(k, dtype=np.int32)
    b = np.empty(k, dtype=np.float64)
    vals = np.empty(entries, dtype=np.float64)
    cols = np.empty(entries, dtype=np.int32)
    ptr = np.zeros(k + 1, dtype=np.int32)
    j = 0
    pos = 0
    for i in range(states.shape[0]):
        s = states[i]
        if at[s] < 0:
            continue
        r = rows[i]
        acc = 0.0
        for e in range(indptr[r], indptr[r + 1]):
            p = data[e]
            if p > 0.0:
                c = indices[e]
                if sure[c]:
                    acc += p
                elif at[c] >= 0:
                    cols[pos] = at[c]
                    vals[pos] = p
                    pos += 1
        idx[j] = s
        b[j] = acc
        j += 1
        ptr[j] = pos
    return idx, b, vals, cols, ptr


@numba.njit(cache=True, nogil=True)
def chain_blocks(comp, level):  # pragma: no cover - compiled
    """What :func:`~mitld_lp.solvers.graph.blocks_from` makes with NumPy for a chain's
    states whose components ``comp`` (ids of a larger graph's, non-negative) and their
    levels ``level[comp]`` (non-negative) are known: the components and their levels
    renumbered densely in increasing order (a table of the ids present, as its
    ``_renumbered``), each component's size, the states ordered by level keeping ties
    in their order (a counting sort: the one permutation of a stable sort) and each
    level's first position.  Returns ``(component, level, size, by_level,
    level_starts)``, int64 as NumPy's; a pass or two over the states and one over the
    ids' table, not two tables, a gather and a sort of NumPy calls."""
    n = comp.shape[0]
    top = 0
    for i in range(n):
        if comp[i] + 1 > top:
            top = comp[i] + 1
    rank = np.zeros(top, dtype=np.int32)  # 1 where present, then each id's rank
    k = 0
    for i in range(n):
        if not rank[comp[i]]:
            rank[comp[i]] = 1
            k += 1
    # the ids in increasing order: each its rank and its level, the levels' top
    dlevel = np.empty(k, dtype=np.int64)
    j = 0
    ltop = 0
    for c in range(top):
        if rank[c]:
            rank[c] = j
            lv = level[c]
            dlevel[j] = lv
            if lv + 1 > ltop:
                ltop = lv + 1
            j += 1
    lrank = np.zeros(ltop, dtype=np.int64)
    for j in range(k):
        lrank[dlevel[j]] = 1
    n_levels = 0
    for lv in range(ltop):
        if lrank[lv]:
            lrank[lv] = n_levels
            n_levels += 1
    for j in range(k):
        dlevel[j] = lrank[dlevel[j]]
    dense = np.empty(n, dtype=np.int64)
    size = np.zeros(k, dtype=np.int64)
    starts = np.zeros(n_levels + 1, dtype=np.int64)
    for i in range(n):
        d = rank[comp[i]]
        dense[i] = d
        size[d] += 1
        starts[dlevel[d] + 1] += 1
    for lv in range(n_levels):
        starts[lv + 1] += starts[lv]
    at = starts[:n_levels].copy()
    order = np.empty(n, dtype=np.int64)
    for i in range(n):
        lv = dlevel[dense[i]]
        order[at[lv]] = i
        at[lv] += 1
    return dense, dlevel, size, order, starts


@numba.njit(cache=True, nogil=True)
def cycling(groups, indptr, indices, comp, left, out):  # pragma: no cover - compiled
    """What :func:`~mitld_lp.solvers.certify_chain.cycling_among` sets in ``out`` (a
    bool a state, False on entry): a ``left`` state of a strongly connected component
    ``comp`` of more than one state, or one with a choice (row ``c`` of
    ``groups[s]:groups[s + 1]``) whose stored entries, at least one, all lie in its own
    column.  Which entries exist and where is all that is read: the same set.  Returns
    False, ``out`` untouched, where a component number is negative or not below the
    count of states (the caller's NumPy path then runs)."""
    n = left.shape[0]
    size = np.zeros(n, dtype=np.int32)  # (a component number is below the states')
    for s in range(n):
        c = comp[s]
        if c < 0 or c >= n:
            return False
        size[c] += 1
    for s in range(n):
        if not left[s]:
            continue
        if size[comp[s]] > 1:
            out[s] = True
            continue
        for c in range(groups[s], groups[s + 1]):
            a = indptr[c]
            z = indptr[c + 1]
            if z == a:
                continue
            pure = True
            for e in range(a, z):
                if indices[e] != s:
                    pure = False
                    break
            if pure:
                out[s] = True
                break
    return True
