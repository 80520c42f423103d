"""The quotient's block order and the levels the certificate keeps, for
:func:`mitld_lp.solvers.analysis.analyse`.

The analysis finds the product's components and what they reach
(:func:`~mitld_lp.solvers.graph.state_components`); the levels of those components were
half of the analysis on QVBS products walked by SciPy (csma 4-2: 0.16 of 0.35 s CPU),
and every solver reads only the quotient's.  So where the product's levels are not
found at no cost (the compiled walk finds all three in one pass), the quotient's own
components and levels are found on the quotient alone (its maybe states after prob-one:
678 to 28,812 states on those products) and give the solvers' block order; the
certificate (:mod:`~mitld_lp.solvers.certify`) reads them lifted to the product's
components (``Quotient.layers``: a component whose states all stay in the quotient is
one of the quotient's, an end component collapsed inside it keeping it strongly
connected), -1 for the others, where it finds levels of its own if it reads one.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.analysis_gates import level_walks
from mitld_lp.solvers.graph import Blocks, blocks_from, state_levels
from mitld_lp.util.arrays import SLICE_STATES, index_dtype

__all__ = ["crowded", "may_split", "mixed", "order_of", "quotient_blocks", "split",
           "staying"]


def order_of(q_matrix: sp.csr_array, row_groups: np.ndarray, comp_of: np.ndarray,
             level_of: np.ndarray) -> Blocks:
    """The quotient's components (``comp_of``, per reduced state: ids of the product's
    components or of the quotient's own) and levels (``level_of`` per component), with
    each reduced choice's probability of staying where it is."""
    self_loop = staying(q_matrix, row_groups)
    return blocks_from(comp_of, level_of, self_loop)


def staying(q_matrix: sp.csr_array, row_groups: np.ndarray) -> np.ndarray:
    """``(n_choices,)`` float64: each choice's probability of staying in its own state
    (its row's entries in its state's column, summed in their order), read
    :data:`SLICE_STATES` states at a time: not each entry's row and each choice's state
    for the whole quotient (two index arrays, an entry's and a choice's, and a mask an
    entry, alive at QVBS zeroconf 1000-4's analysis peak: 2.6 bytes a transition), the
    same sums."""
    n = row_groups.shape[0] - 1
    n_choices = q_matrix.shape[0]
    ptr = q_matrix.indptr
    out = np.zeros(n_choices, dtype=np.float64)
    for lo in range(0, n, SLICE_STATES):
        hi = min(lo + SLICE_STATES, n)
        a, b = int(row_groups[lo]), int(row_groups[hi])
        if a == b:
            continue
        owner = np.repeat(np.arange(lo, hi, dtype=index_dtype(n)),
                          np.diff(row_groups[lo:hi + 1]))
        e, f = int(ptr[a]), int(ptr[b])
        row = np.repeat(np.arange(b - a, dtype=index_dtype(n_choices)), np.diff(ptr[a:b + 1]))
        hit = q_matrix.indices[e:f] == owner[row]
        out[a:b] = np.bincount(row[hit], weights=q_matrix.data[e:f][hit], minlength=b - a)
    return out


def crowded(component: np.ndarray) -> np.ndarray:
    """The states (ascending ids) whose component holds more than one state: the only
    ones :func:`mixed`, :func:`may_split` and :func:`split` need to look at (a component
    of one state holds no two states).  One count a component and one gather, once an
    analysis, in place of a scatter, a gather and a count over every state in each test
    (QVBS csma 4-2: 8,345 of 600,267 states; firewire_dl 3-600 and zeroconf_dl
    1000-1-30: none)."""
    if not component.size:
        return np.zeros(0, dtype=np.int64)
    size = np.bincount(component)
    if int(size.max()) < 2:  # every component one state
        return np.zeros(0, dtype=np.int64)
    return np.flatnonzero(size[component] > 1).astype(index_dtype(component.size),
                                                       copy=False)


def split(component: np.ndarray, maybe: np.ndarray, sure: np.ndarray,
          crowd: np.ndarray | None = None) -> bool:
    """Whether a component of the product holds both a state left in the quotient
    (``maybe``) and one removed with value 1 (``sure``); ``crowd``: :func:`crowded`'s
    states of ``component``, where the caller has them (a component of one state holds
    both only where its state is in both)."""
    if not sure.any():
        return False
    if bool(np.any(maybe & sure)):  # a state in both: its component holds both
        return True
    at = crowded(component) if crowd is None else crowd
    comp = component[at]
    kept = np.zeros(int(comp.max(initial=-1)) + 1, dtype=bool)
    kept[comp[maybe[at]]] = True
    return bool(kept[comp[sure[at]]].any())


def mixed(comp: np.ndarray, maybe: np.ndarray, crowd: np.ndarray | None = None) -> bool:
    """Whether a component of the product holds both a state of the quotient
    (``maybe``) and one out of it (then the quotient's levels are not the product's
    lifted, and the product's are walked: QVBS zeroconf 1000-4's large component);
    ``crowd``: :func:`crowded`'s states of ``comp`` (only those can be in such a
    component), where the caller has them."""
    # one state's mark written for each component (any one: a component all in or all
    # out gets its own mark), then any state whose mark differs from its component's:
    # bools a component, not two int64 counts (csma 4-2: 9.5 MB at the analysis's peak)
    at = crowded(comp) if crowd is None else crowd
    own, inside = comp[at], maybe[at]
    mark = np.zeros(int(own.max(initial=-1)) + 1, dtype=bool)
    mark[own] = inside
    return bool(np.any(mark[own] != inside))


def may_split(comp: np.ndarray, maybe: np.ndarray, crowd: np.ndarray | None = None) -> bool:
    """Whether prob-one may split a component of the product (:func:`split`): some
    ``maybe`` state lies in a component of more than one state (``crowd``:
    :func:`crowded`'s states of ``comp``, where the caller has them).  If not, the
    caller needs the product's levels in no case and frees what would walk them."""
    at = crowded(comp) if crowd is None else crowd
    return bool(np.any(maybe[at]))


def quotient_blocks(found: Any, matrix: sp.csr_array, row_groups: np.ndarray,
                    maybe: np.ndarray, sure_state: np.ndarray, state_map: np.ndarray,
                    product_levels: Callable[[], Any], crowd: np.ndarray | None = None,
                    ) -> tuple[Blocks, np.ndarray]:
    """The quotient's block order and a level per component of the product for the
    certificate (``Quotient.layers``).  With the product's levels (``found.level``:
    from the compiled walk, or walked by the caller where a component of the product
    holds states in and out of the quotient, :func:`mixed`) the order and layers are
    those of the product, as before.  Else the quotient's own levels, found on the
    quotient alone (its maybe states after prob-one), lifted to the components of the
    product that hold its states (each is one of its components); -1 for the others,
    where the certificate finds levels of its own if it reads one
    (:mod:`~mitld_lp.solvers.certify`).  Where prob-one's removal split a component
    (:func:`split`), the product's levels are walked (``found.later()``, kept by the
    caller where :func:`may_split`; else ``product_levels()``, the same components)
    for the layers, as before.  ``crowd``: :func:`crowded`'s states of the product's
    components, where the caller has them."""
    comp = found.component
    level = found.level
    cut = split(comp, maybe, sure_state, crowd)
    if level is not None and not cut:
        comp_of = np.zeros(row_groups.shape[0] - 1, dtype=np.int64)
        comp_of[state_map[maybe]] = comp[maybe]
        return order_of(matrix, row_groups, comp_of, level), level
    # a component of the product that lost states to prob-one may be several of the
    # quotient: the quotient's own are found (a block is one component: a single
    # state is solved apart)
    # compiled where a kernel's load is paid and its cache warm (analysis_gates), in
    # place of SciPy's components and Dijkstra's search of thin levels: the same numbers
    own = state_levels(matrix, row_groups, walks=level_walks(matrix.nnz))
    order = order_of(matrix, row_groups, own.component, own.level)
    if cut:  # the product's levels for the layers, as before
        if level is None:
            level = found.later() if found.later is not None else product_levels().level
        return order, level
    level = np.full(int(comp.max(initial=-1)) + 1, -1, dtype=np.int64)
    at = np.flatnonzero(maybe)
    level[comp[at]] = own.level[own.component[state_map[at]]]
    return order, level
