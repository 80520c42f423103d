r"""The product's components and reach in one compiled pass (numba), for
:func:`~mitld_lp.solvers.graph.components_reaching`'s SciPy route: the same labels and
the same reached states, without SciPy's state graph (its duplicates merged), its
strong components and a search of the graph reversed for each seed set (three passes
over the product's entries and a reversal of them: QVBS csma 4-2, 1.1 million entries,
0.035 s of CPU).

:func:`components_reach` walks the state graph of a choice matrix (a state's successors
the columns of its choices' rows, each once) by Tarjan's algorithm with an explicit
stack, the roots in increasing order and each state's successors from the largest
down: the order of SciPy's ``csgraph.connected_components(connection='strong')`` on the
sorted graph :func:`~mitld_lp.solvers.graph.graph_view` builds, so the components are
numbered as SciPy numbers them (in the order they are completed).  That sorted graph
is built in the same call, a state at a time (no SciPy matrix, no duplicate merge of
the whole pattern), and returned for the condensation a caller may walk later.  Which
seed sets a component reaches is found as it is completed, every
component it reaches being complete then: a bit a seed set, OR-ed from the members'
seeds and from each edge into a completed component, as the edge is crossed (no second
pass over the entries).  The seed masks are read, and each state's reach written, as
bool columns in the same call, and each component's size, known as it completes, marks
the states of components of more than one state (no NumPy pass over the states for the
bits, their unpacking or :func:`~mitld_lp.solvers.quotient_order.crowded`'s count).
Imported only where the compiled walks are (the kernel loader's
cache, else numba)."""

from __future__ import annotations

import numpy as np

from mitld_lp.util import kernel_loader

numba = kernel_loader.lazy_numba(globals())

__all__ = ["MAX_SEEDS", "component_levels", "components_reach", "seed_columns", "warm_up"]

MAX_SEEDS = 8
"""The most seed sets one call reads (a bit each of a byte)."""


@numba.njit(cache=True, nogil=True)
def components_reach(indptr, indices, row_groups, seeds):  # pragma: no cover - compiled
    """``(n_components, label, reach, crowd, ptr, succ)`` of the state graph of the choice
    matrix ``indptr, indices`` (state ``s``'s choices are rows
    ``row_groups[s]:row_groups[s+1]``; its states and entries below 2**31 - 1), for the
    seed sets ``seeds`` (``(n, k)`` bool, C order, ``k`` at most :data:`MAX_SEEDS`, each
    column a bit of a byte here): ``label`` (int32) each state's component, numbered as
    completed (module docs); ``reach`` (``(n, k)`` bool) whether each state reaches a
    state of each seed set (itself included); ``crowd`` (int32, ascending) the states
    whose component holds more than one state (:func:`~mitld_lp.solvers.quotient_order.
    crowded`'s, each component's size known as it completes: no count over the labels);
    ``ptr, succ`` the state graph (int32 CSR, each row sorted, without repeats: SciPy's
    route's, :func:`~mitld_lp.solvers.graph.graph_view`), built first, a state at a time
    in order (the rows read in stored order: 0.03 s against 0.035 entering each state's
    as the search reaches it, on QVBS csma 4-2).  Pearce's one-array form
    of Tarjan's search (as SciPy's): ``rindex`` holds a state's index, then its low
    link, then, completed, ``n -`` its component, so an edge reads one number of
    its head.  A plain search in the same order comes first (:func:`_acyclic`): where
    the graph has no cycle but self-loops it gives the same numbering and bits, else it
    stops at its first cycle and Tarjan's search runs."""
    n = row_groups.shape[0] - 1
    ptr = np.empty(n + 1, dtype=np.int32)
    succ = np.empty(indptr[row_groups[n]] - indptr[row_groups[0]], dtype=np.int32)
    pos = 0
    ptr[0] = 0
    for v in range(n):  # each state's distinct successors, sorted
        start = pos
        for e in range(indptr[row_groups[v]], indptr[row_groups[v + 1]]):
            x = indices[e]
            i = pos
            while i > start and succ[i - 1] > x:  # insertion, a short run
                succ[i] = succ[i - 1]
                i -= 1
            if i > start and succ[i - 1] == x:  # a repeat: undo the shift
                for r in range(i, pos):
                    succ[r] = succ[r + 1]
                continue
            succ[i] = x
            pos += 1
        ptr[v + 1] = pos
    rindex = np.zeros(n, dtype=np.int32)  # 0: not entered
    k = seeds.shape[1]
    # a state's own bits, and those of the components its edges enter
    acc = np.zeros(n, dtype=np.uint8)
    for s in range(n):
        own = 0
        for j in range(k):
            if seeds[s, j]:
                own |= 1 << j
        acc[s] = own
    comp_bits = np.zeros(n, dtype=np.uint8)
    many = np.zeros(n, dtype=np.bool_)  # a completed component holds more than one state
    stack = np.empty(n, dtype=np.int32)  # entered states whose root is not finished
    work_v = np.empty(n, dtype=np.int32)
    work_at = np.empty(n, dtype=np.int32)  # the next successor's position, descending
    work_root = np.empty(n, dtype=np.bool_)
    top = 0
    index = 1
    # the next completed component's rindex (its label n - c): above every entered
    # state's index (at most the states entered and not completed, n - n_components)
    c = _acyclic(ptr, succ, acc, rindex, comp_bits, stack, work_v, work_at, n)
    if c < 0:  # a cycle: Tarjan's search, from nothing
        rindex[:] = 0
        comp_bits[:] = 0
        c = n
    for root in range(n):  # nothing left to enter where the graph is acyclic
        if rindex[root]:
            continue
        v = root
        depth = 0
        entering = True
        while True:
            if entering:
                rindex[v] = index
                index += 1
                work_v[depth] = v
                work_at[depth] = ptr[v + 1] - 1
                work_root[depth] = True
                depth += 1
            v = work_v[depth - 1]
            at = work_at[depth - 1]
            lo = ptr[v]
            rv = rindex[v]
            is_root = work_root[depth - 1]
            entering = False
            while at >= lo:
                w = succ[at]
                at -= 1
                rw = rindex[w]
                if rw == 0:
                    entering = True
                    break
                if rw > c:  # a completed component: its bits are final
                    acc[v] |= comp_bits[n - rw]
                elif rw < rv:  # on the stack: in v's component, below v's root
                    rv = rw
                    is_root = False
            rindex[v] = rv
            work_root[depth - 1] = is_root
            if entering:
                work_at[depth - 1] = at
                v = w
                continue
            depth -= 1
            if is_root:  # v's component: v and the states above it on the stack
                index -= 1
                b = acc[v]
                members = 1
                while top > 0 and rv <= rindex[stack[top - 1]]:
                    top -= 1
                    w = stack[top]
                    rindex[w] = c
                    index -= 1
                    b |= acc[w]
                    members += 1
                rindex[v] = c
                comp_bits[n - c] = b
                many[n - c] = members > 1
                c -= 1
            else:
                stack[top] = v
                top += 1
            if depth == 0:
                break
            u = work_v[depth - 1]
            rv = rindex[v]
            if rv > c:  # v's component completed below u
                acc[u] |= comp_bits[n - rv]
            elif rv < rindex[u]:
                rindex[u] = rv
                work_root[depth - 1] = False
    n_comp = n - c
    label = np.empty(n, dtype=np.int32)
    reach = np.empty((n, k), dtype=np.bool_)
    crowd = np.empty(n, dtype=np.int32)
    n_crowd = 0
    for s in range(n):
        comp = n - rindex[s]
        label[s] = comp
        b = comp_bits[comp]
        for j in range(k):
            reach[s, j] = ((b >> j) & 1) != 0
        if many[comp]:
            crowd[n_crowd] = s
            n_crowd += 1
    return n_comp, label, reach, crowd[:n_crowd], ptr, succ[:pos]


@numba.njit(cache=True, nogil=True)
def component_levels(indptr, indices, row_groups, label, n_comp):  # pragma: no cover
    """``(level, ok)``: each component's level in the state graph of the choice matrix
    ``indptr, indices`` (state ``s``'s choices are rows ``row_groups[s]:row_groups[s+1]``)
    whose states lie in the components ``label`` (int32, ``n_comp`` of them): 0 for a
    component without an edge to another, else one more than the highest level of those
    it has an edge to, :func:`~mitld_lp.solvers.graph.levels`' longest path to a sink.
    The components numbered as Tarjan's search completes them (:func:`components_reach`:
    every edge between two runs from a higher id to a lower), each is final when the
    components below it are: one pass over the components in increasing order, their
    states grouped by a counting sort, each state's entries read once (no state graph,
    no condensation, no round a level).  ``ok`` False where an edge runs up (not such a
    numbering): the levels are then not read."""
    n = row_groups.shape[0] - 1
    start = np.zeros(n_comp + 1, dtype=np.int64)
    for s in range(n):
        start[label[s] + 1] += 1
    for c in range(n_comp):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    members = np.empty(n, dtype=np.int32)
    for s in range(n):
        c = label[s]
        members[fill[c]] = s
        fill[c] += 1
    level = np.zeros(n_comp, dtype=np.int64)
    for c in range(n_comp):
        lv = 0
        for i in range(start[c], start[c + 1]):
            s = members[i]
            for e in range(indptr[row_groups[s]], indptr[row_groups[s + 1]]):
                d = label[indices[e]]
                if d == c:
                    continue
                if d > c:  # not final yet: not Tarjan's numbering
                    return level, False
                if level[d] >= lv:
                    lv = level[d] + 1
        level[c] = lv
    return level, True


@numba.njit(cache=True, nogil=True, inline="always")
def _acyclic(ptr, succ, acc, rindex, comp_bits, bits, work_v, work_at,
             n):  # pragma: no cover - compiled
    """:func:`components_reach`'s search where the state graph has no cycle but
    self-loops (a deadline's clock: QVBS firewire_dl 3-600, zeroconf_dl 1000-1-30): each
    state is a component of its own, completed as the search leaves it, so a plain
    depth-first search in the same order (roots increasing, successors from the last)
    numbers them as Tarjan's does and ORs the same bits, without the low links or the
    stack of entered states.  Writes ``rindex`` and ``comp_bits`` as Tarjan's search
    leaves them (a completed state ``v``: ``rindex[v] = c``, its bits at ``n - c``;
    ``-1`` marks a state on the path) and returns the last ``c``; ``-1`` as soon as an
    edge enters a state on the path (a cycle), the arrays then to be cleared.  ``bits``
    holds the bits found so far at each depth (scratch of ``n``)."""
    c = n
    for root in range(n):
        if rindex[root]:
            continue
        rindex[root] = -1
        work_v[0] = root
        work_at[0] = ptr[root + 1] - 1
        bits[0] = acc[root]
        depth = 1
        while depth:
            v = work_v[depth - 1]
            b = bits[depth - 1]
            w = -1  # the next state to enter, if any
            for at in range(work_at[depth - 1], ptr[v] - 1, -1):
                x = succ[at]
                rx = rindex[x]
                if rx > 0:  # completed: its bits are final
                    b |= comp_bits[n - rx]
                elif rx == 0:
                    w = x
                    work_at[depth - 1] = at - 1
                    break
                elif x != v:  # on the path: a cycle
                    return -1
            if w >= 0:
                bits[depth - 1] = b
                rindex[w] = -1
                work_v[depth] = w
                work_at[depth] = ptr[w + 1] - 1
                bits[depth] = acc[w]
                depth += 1
                continue
            rindex[v] = c
            comp_bits[n - c] = b
            c -= 1
            depth -= 1
            if depth:
                bits[depth - 1] |= b
    return c


def seed_columns(seeds: np.ndarray) -> np.ndarray:
    """``seeds`` as :func:`components_reach` reads them: ``(n, k)`` bool in C order, ``k``
    at most :data:`MAX_SEEDS` (a bit each of a byte); a bad shape named."""
    seeds = np.asarray(seeds)
    if seeds.ndim != 2 or seeds.shape[1] > MAX_SEEDS:
        raise ValueError(f"seeds: expected an (n, k) mask with k <= {MAX_SEEDS}, "
                         f"got shape {seeds.shape}")
    return np.ascontiguousarray(seeds, dtype=bool)


def warm_up() -> None:
    """Compile (or link) :func:`components_reach` for the signature a solve passes
    (:mod:`~mitld_lp.solvers.analysis_reach`: an int32 pattern, read-only row groups)."""
    groups = np.array([0, 1, 2], dtype=np.int64)
    groups.flags.writeable = False
    components_reach(np.array([0, 1, 2], dtype=np.int32), np.array([1, 0], dtype=np.int32),
                     groups, np.zeros((2, 1), dtype=bool))
