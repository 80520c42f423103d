r"""The graph walks of :mod:`~mitld_lp.solvers.graph` compiled (numba): imported only
from there (:func:`~mitld_lp.solvers.graph.compiled_walks`), and only for a product
large enough to pay numba's load or once numba is loaded anyway; compiled once, cached
on disk.

Each kernel gives what its NumPy counterpart gives, not merely an equivalent answer:

* :func:`state_graph`: the state graph of a choice matrix, each state's successors
  sorted and without repeats, as :func:`~mitld_lp.solvers.graph.graph_view` builds it;
* :func:`strong_components`: Tarjan's algorithm with an explicit stack; the components
  are numbered in the order they are completed, by the same depth-first search as
  SciPy's ``csgraph`` (successors looked at from the last: ``descending``) or as
  :func:`mitld_lp.util.traversal.strong_components`'s own walk of a small graph (from
  the first), so the labels are those of the routine the NumPy path calls;
* :func:`components_and_levels`: the same, with each component's level and which seed
  sets it reaches, found as the component is completed (after every component it
  reaches, so its successors' are final);
* :func:`state_levels`: the three above on a choice matrix, in one call;
* :func:`backward`: the least fixed points of :func:`~mitld_lp.solvers.graph.attractor`
  and of :func:`~mitld_lp.solvers.graph.backward_reachable` by a work queue over the
  transposed pattern (a set: the order of the queue does not change it), and
  :func:`reaching_edges` the same reach along a list of edges;
* :func:`closed_among`: how many of some states lie outside the attractor of the
  others, on their own rows (whether an end component lies among them);
* :func:`end_components_among`: de Alfaro's rounds of
  :func:`~mitld_lp.solvers.graph.maximal_end_components` on the candidate states alone
  (no sub-MDP is built for them).
"""

from __future__ import annotations

import numpy as np

from mitld_lp.util import kernel_loader

# numba's cached machine code run without importing numba; numba itself on a miss
# (without PyYAML, the narrow load, the disk cache's lock: kernel_loader.numba_module)
numba = kernel_loader.lazy_numba(globals())


__all__ = ["INDEX_LIMIT", "backward", "closed_among", "components_and_levels",
           "end_components_among",
           "fits", "reaching_edges", "state_graph", "state_levels", "strong_components"]


@numba.njit(cache=True, nogil=True, inline="always")
def _sort_run(a, lo, hi):  # pragma: no cover - compiled
    """Sort ``a[lo:hi]`` in place: by insertion where short (a state's few successors),
    else numba's sort."""
    if hi - lo > 32:
        a[lo:hi].sort()
        return
    for i in range(lo + 1, hi):
        x = a[i]
        j = i - 1
        while j >= lo and a[j] > x:
            a[j + 1] = a[j]
            j -= 1
        a[j + 1] = x


def fits(n_nodes: int, n_entries: int) -> bool:
    """Whether a graph of ``n_nodes`` nodes and ``n_entries`` entries (or a choice
    matrix's: its states and stored entries) has every node id and every offset below
    :data:`INDEX_LIMIT`: the compiled components walk it in int32, as SciPy's
    ``csgraph`` walks every graph; the callers take NumPy's walks past it."""
    return max(n_nodes, n_entries) < INDEX_LIMIT


INDEX_LIMIT = 2**31 - 1
"""The int32 state graphs' bound (:func:`fits`)."""


@numba.njit(cache=True, nogil=True)
def state_graph(indptr, indices, row_groups, n):  # pragma: no cover - compiled
    """``(ptr, succ)``: the successors of each of the ``n`` states (the columns of its
    choices' rows ``row_groups[s]:row_groups[s+1]``), sorted, each once; in int32
    whatever the matrix's index types (the caller checked :func:`fits`): half the bytes
    Tarjan's search reads an edge (QVBS zeroconf 1000-4's quotient, 164,171 states:
    0.018 -> 0.010 s), and :func:`components_and_levels` compiled for one signature
    (an int32 state graph beside the int64 graphs of other callers compiled it twice in
    the whole test suite)."""
    ptr = np.zeros(n + 1, dtype=np.int32)
    succ = np.empty(indices.shape[0], dtype=np.int32)
    mark = np.full(n, -1, dtype=np.int64)
    pos = 0
    for s in range(n):
        start = pos
        for e in range(indptr[row_groups[s]], indptr[row_groups[s + 1]]):
            t = indices[e]
            if mark[t] != s:
                mark[t] = s
                succ[pos] = t
                pos += 1
        _sort_run(succ, start, pos)
        ptr[s + 1] = pos
    return ptr, succ[:pos].copy()


@numba.njit(cache=True, nogil=True)
def state_levels(indptr, indices, row_groups, seeds, small):  # pragma: no cover
    """``(label, level, reach)`` of the state graph of a choice matrix
    (:func:`state_graph`): :func:`components_and_levels` with the successors looked at
    from the last where the graph has more than ``small`` nodes and entries (as
    SciPy's search does), from the first else (as the plain walk does).  One entry
    point: numba reads each from its cache at its first call (~0.03 s)."""
    n = row_groups.shape[0] - 1
    ptr, succ = state_graph(indptr, indices, row_groups, n)
    # np.bool_: a bool, not numba's Literal[bool](True), so that one signature serves
    # this call and the Python callers' (a literal argument is compiled for apart)
    _, label, level, reach = components_and_levels(ptr, succ, n + succ.shape[0] > small,
                                                   seeds, np.bool_(True))
    return label, level, reach


@numba.njit(cache=True, nogil=True)
def strong_components(ptr, succ, descending):  # pragma: no cover - compiled
    """``(n_components, label)`` of the graph ``ptr, succ`` (CSR, any index type, walked
    in int32 as :func:`state_graph`'s: :func:`fits`): Tarjan's algorithm, the roots
    taken in increasing order, each node's successors from the last when
    ``descending``; components numbered as completed."""
    n_comp, label, _, _ = components_and_levels(
        ptr.astype(np.int32), succ.astype(np.int32), descending,
        np.zeros((ptr.shape[0] - 1, 0), dtype=np.bool_), np.bool_(False))
    return n_comp, label


@numba.njit(cache=True, nogil=True)
def components_and_levels(ptr, succ, descending, seeds,
                          layered):  # pragma: no cover - compiled
    """``(n_components, label, level, reach)``: :func:`strong_components`, and with
    ``layered`` each component's level (0 without a successor component, else one more
    than its highest successor's) and ``reach[c, j]``: whether it reaches a state of
    ``seeds[:, j]``, found as it is completed (its successors are all complete then)."""
    n = ptr.shape[0] - 1
    k = seeds.shape[1]
    level = np.zeros(n if layered else 0, dtype=np.int64)
    reach = np.zeros((n if layered else 0, k), dtype=np.bool_)
    order = np.full(n, -1, dtype=np.int64)
    low = np.zeros(n, dtype=np.int64)
    label = np.full(n, -1, dtype=np.int32)
    on_stack = np.zeros(n, dtype=np.bool_)
    stack = np.empty(n, dtype=np.int64)
    work_v = np.empty(n, dtype=np.int64)
    work_at = np.empty(n, dtype=np.int64)  # the next successor's position
    top = 0
    counter = 0
    n_comp = 0
    for root in range(n):
        if order[root] >= 0:
            continue
        order[root] = counter
        low[root] = counter
        counter += 1
        stack[top] = root
        top += 1
        on_stack[root] = True
        work_v[0] = root
        work_at[0] = ptr[root + 1] - 1 if descending else ptr[root]
        depth = 1
        while depth:
            v = work_v[depth - 1]
            at = work_at[depth - 1]
            lo, hi = ptr[v], ptr[v + 1]
            descended = False
            while lo <= at < hi:
                w = succ[at]
                at = at - 1 if descending else at + 1
                if order[w] < 0:
                    work_at[depth - 1] = at
                    order[w] = counter
                    low[w] = counter
                    counter += 1
                    stack[top] = w
                    top += 1
                    on_stack[w] = True
                    work_v[depth] = w
                    work_at[depth] = ptr[w + 1] - 1 if descending else ptr[w]
                    depth += 1
                    descended = True
                    break
                if on_stack[w] and order[w] < low[v]:
                    low[v] = order[w]
            if descended:
                continue
            depth -= 1
            if depth:
                u = work_v[depth - 1]
                if low[v] < low[u]:
                    low[u] = low[v]
            if low[v] == order[v]:
                end = top
                while True:
                    top -= 1
                    w = stack[top]
                    on_stack[w] = False
                    label[w] = n_comp
                    if w == v:
                        break
                if layered:
                    _layer(ptr, succ, seeds, label, stack[top:end], n_comp, level, reach)
                n_comp += 1
    return n_comp, label, level[:n_comp], reach[:n_comp]


@numba.njit(cache=True, nogil=True, inline="always")
def _layer(ptr, succ, seeds, label, members, c, level, reach):  # pragma: no cover
    """Component ``c``'s level and reach from its ``members``' successors (complete)."""
    k = seeds.shape[1]
    lv = 0
    for s in members:
        for j in range(k):
            if seeds[s, j]:
                reach[c, j] = True
        for e in range(ptr[s], ptr[s + 1]):
            d = label[succ[e]]
            if d == c:
                continue
            if level[d] + 1 > lv:
                lv = level[d] + 1
            for j in range(k):
                if reach[d, j]:
                    reach[c, j] = True
    level[c] = lv


@numba.njit(cache=True, nogil=True)
def _transpose(indptr, indices, n_cols):  # pragma: no cover - compiled
    """The rows of each column of the pattern ``indptr, indices`` (a counting sort)."""
    n_rows = indptr.shape[0] - 1
    col_ptr = np.zeros(n_cols + 1, dtype=indptr.dtype)  # up to the entries: their type
    for e in range(indptr[n_rows]):
        col_ptr[indices[e] + 1] += 1
    for t in range(n_cols):
        col_ptr[t + 1] += col_ptr[t]
    fill = col_ptr[:-1].copy()
    rows = np.empty(indptr[n_rows], dtype=indices.dtype)  # 4 bytes an entry where int32
    for r in range(n_rows):
        for e in range(indptr[r], indptr[r + 1]):
            t = indices[e]
            rows[fill[t]] = r
            fill[t] += 1
    return col_ptr, rows


def backward(indptr: np.ndarray, indices: np.ndarray, row_groups: np.ndarray,
             seeds: np.ndarray, hit: np.ndarray, every: bool) -> np.ndarray:
    """:func:`_backward` (the docs there) with ``row_groups`` passed read-only: a view,
    not a copy.  The suite's callers pass read-only row groups and writable ones, and
    numba compiles one machine code for each (1 s of CPU on a cold cache); the kernel
    only reads them."""
    row_groups = np.asarray(row_groups)
    if indptr.shape[0] - 1 > np.iinfo(indices.dtype).max:  # a choice's id past the type
        indices = indices.astype(np.int64)
    if row_groups.flags.writeable:
        row_groups = row_groups.view()
        row_groups.flags.writeable = False
    return _backward(indptr, indices, row_groups, seeds, hit, bool(every))


@numba.njit(cache=True, nogil=True)
def _backward(indptr, indices, row_groups, seeds, hit, every):  # pragma: no cover
    """The least set holding ``seeds`` and each state with a choice hit (``every``: all
    its choices, at least one), a choice being hit if it is in ``hit`` (a copy the
    kernel may write) or has an entry into the set: with ``every`` the attractor of
    :func:`mitld_lp.solvers.graph.attractor`, else the states with a path to the
    seeds.  A work queue over the transposed pattern."""
    n = row_groups.shape[0] - 1
    col_ptr, col_rows = _transpose(indptr, indices, n)
    owner = np.empty(row_groups[n], dtype=indices.dtype)  # a state: a column's type
    # the choices still to hit before joining (fewer than the rows: the indices' type)
    remaining = np.zeros(n, dtype=indices.dtype)
    for s in range(n):
        for c in range(row_groups[s], row_groups[s + 1]):
            owner[c] = s
            if not hit[c]:
                remaining[s] += 1
        if not every and remaining[s] > 0:
            remaining[s] = 1
    inside = seeds.copy()
    for s in range(n):
        if remaining[s] == 0 and row_groups[s + 1] > row_groups[s]:
            inside[s] = True
    return _joined(col_ptr, col_rows, owner, remaining, inside, hit)


@numba.njit(cache=True, nogil=True)
def reaching_edges(n, source, succ, seeds):  # pragma: no cover - compiled
    """The states of ``n`` with a path along the edges ``source -> succ`` to a
    ``seeds`` state, the seeds included (:func:`mitld_lp.solvers.graph.
    backward_reachable`): :func:`_backward` with each edge a choice of its source.
    The edges' pointers in ``succ``'s type (int32 where the caller could): the pattern
    handed to :func:`_transpose` then has the types of a product's matrix, and
    :func:`_transpose` is compiled for one signature with :func:`_backward`'s."""
    m = succ.shape[0]
    ptr = np.empty(m + 1, dtype=succ.dtype)
    for e in range(m + 1):
        ptr[e] = e
    col_ptr, col_rows = _transpose(ptr, succ, n)
    remaining = np.ones(n, dtype=np.int64)  # one edge into the set is enough
    return _joined(col_ptr, col_rows, source, remaining, seeds.copy(),
                   np.zeros(m, dtype=np.bool_))


@numba.njit(cache=True, nogil=True, inline="always")
def _joined(col_ptr, col_rows, owner, remaining, inside, hit):  # pragma: no cover
    """The work queue of :func:`backward` from the states ``inside``: a choice (a row
    of the transposed pattern ``col_ptr, col_rows``, owned by ``owner``) not yet
    ``hit`` is hit by an entry into the set, and its owner joins when its
    ``remaining`` count of choices to hit reaches 0."""
    n = inside.shape[0]
    queue = np.empty(n, dtype=col_rows.dtype)  # states: within the rows' type
    tail = 0
    for s in range(n):
        if inside[s]:
            queue[tail] = s
            tail += 1
    head = 0
    while head < tail:
        t = queue[head]
        head += 1
        for e in range(col_ptr[t], col_ptr[t + 1]):
            c = col_rows[e]
            if hit[c]:
                continue
            hit[c] = True
            o = owner[c]
            remaining[o] -= 1
            if remaining[o] == 0 and not inside[o]:
                inside[o] = True
                queue[tail] = o
                tail += 1
    return inside


@numba.njit(cache=True, nogil=True)
def closed_among(indptr, indices, row_groups, states, among):  # pragma: no cover
    """How many of ``states`` (ascending ids; ``among`` their ``(n,)`` mask) are outside
    the attractor of the other states: :func:`_backward` with ``every``, seeded by the
    states not among them, found on the rows of ``states`` alone (their entries, not the
    whole pattern's).  A choice is hit once an entry of it leaves the set or enters the
    attractor (a choice without an entry never is); a state with no choice is in the
    attractor at once.  The states counted keep a choice whose entries all stay among
    them, so 0 iff no end component lies among ``states`` (a non-empty such set holds
    one: a bottom component of those choices' graph)."""
    k = states.shape[0]
    local = np.full(among.shape[0], -1, dtype=np.int32)
    cptr = np.zeros(k + 1, dtype=np.int64)
    for i in range(k):
        local[states[i]] = i
        cptr[i + 1] = cptr[i] + row_groups[states[i] + 1] - row_groups[states[i]]
    owner = np.empty(cptr[k], dtype=np.int32)
    hit = np.zeros(cptr[k], dtype=np.bool_)
    remaining = np.zeros(k, dtype=np.int32)
    count = np.zeros(k + 1, dtype=np.int64)  # the entries into each state, kept choices
    for i in range(k):
        first = row_groups[states[i]]
        for lc in range(cptr[i], cptr[i + 1]):
            owner[lc] = i
            c = first + lc - cptr[i]
            for e in range(indptr[c], indptr[c + 1]):
                if local[indices[e]] < 0:
                    hit[lc] = True
                    break
            if not hit[lc]:
                remaining[i] += 1
                for e in range(indptr[c], indptr[c + 1]):
                    count[local[indices[e]] + 1] += 1
    for i in range(k):
        count[i + 1] += count[i]
    fill = count[:-1].copy()
    rows = np.empty(count[k], dtype=np.int32)
    for i in range(k):
        first = row_groups[states[i]]
        for lc in range(cptr[i], cptr[i + 1]):
            if hit[lc]:
                continue
            c = first + lc - cptr[i]
            for e in range(indptr[c], indptr[c + 1]):
                t = local[indices[e]]
                rows[fill[t]] = lc
                fill[t] += 1
    inside = remaining == 0  # every choice leaves, or none
    return k - np.count_nonzero(_joined(count, rows, owner, remaining, inside, hit))


@numba.njit(cache=True, nogil=True)
def end_components_among(indptr, indices, positive, row_groups,
                         cand):  # pragma: no cover - compiled
    """De Alfaro's rounds (:func:`mitld_lp.solvers.graph.maximal_end_components`) on the
    states ``cand`` (sorted ids) alone: keep the choices whose positive entries
    (``positive`` per entry) stay among the states left, drop the states left with
    none, split into strongly connected components and drop the choices that leave
    theirs, until nothing changes.  Returns ``(alive, allowed, label)`` per candidate
    (``alive``), per choice of the candidates in their order (``allowed``) and the last
    round's component of each candidate (``label``: no edge leaves one then, so which
    order the components are found in does not matter)."""
    n = row_groups.shape[0] - 1
    k = cand.shape[0]
    local = np.full(n, -1, dtype=np.int64)
    cptr = np.zeros(k + 1, dtype=np.int64)
    for i in range(k):
        local[cand[i]] = i
        cptr[i + 1] = cptr[i] + row_groups[cand[i] + 1] - row_groups[cand[i]]
    alive = np.ones(k, dtype=np.bool_)
    allowed = np.ones(cptr[k], dtype=np.bool_)
    still = np.zeros(k, dtype=np.bool_)
    # the candidates' graph in int32, as state_graph's (the caller checked fits):
    # components_and_levels compiled for one signature
    ptr = np.zeros(k + 1, dtype=np.int32)
    held = 0  # the candidates' entries, not the product's: the most succ holds
    for i in range(k):
        held += indptr[row_groups[cand[i] + 1]] - indptr[row_groups[cand[i]]]
    succ = np.empty(held, dtype=np.int32)
    mark = np.full(k, -1, dtype=np.int64)
    no_seeds = np.zeros((k, 0), dtype=np.bool_)
    while True:
        pos = 0
        for i in range(k):
            still[i] = False
            mark_id = i
            first = row_groups[cand[i]]
            for lc in range(cptr[i], cptr[i + 1]):
                if not allowed[lc]:
                    continue
                if not alive[i]:
                    allowed[lc] = False
                    continue
                c = first + lc - cptr[i]
                for e in range(indptr[c], indptr[c + 1]):
                    if positive[e]:
                        t = local[indices[e]]
                        if t < 0 or not alive[t]:
                            allowed[lc] = False
                            break
                if allowed[lc]:
                    still[i] = True
                    for e in range(indptr[c], indptr[c + 1]):
                        t = local[indices[e]]
                        if positive[e] and mark[t] != mark_id:
                            mark[t] = mark_id
                            succ[pos] = t
                            pos += 1
            ptr[i + 1] = pos
        mark[:] = -1
        _, label, _, _ = components_and_levels(ptr, succ[:pos], np.bool_(False), no_seeds,
                                               np.bool_(False))
        any_cross = False
        for i in range(k):
            first = row_groups[cand[i]]
            for lc in range(cptr[i], cptr[i + 1]):
                if not allowed[lc]:
                    continue
                c = first + lc - cptr[i]
                for e in range(indptr[c], indptr[c + 1]):
                    if positive[e] and label[local[indices[e]]] != label[i]:
                        allowed[lc] = False
                        any_cross = True
                        break
        changed = False
        for i in range(k):
            if still[i] != alive[i]:
                changed = True
                alive[i] = still[i]
        if not any_cross and not changed:
            return alive, allowed, label
